"""Each planar contact state's equations, batched over many states (thesis eq.
linear_system): with the state fixed, equilibrium is linear in the motion ``r`` restricted
to the slip face plus the free friction of the rolling contacts, a 3 x 3 system
``M z = -h - w0 - s d`` factorised once per state (:func:`prepared_states`, cached on the
grasp); its solution is affine in ``s``, and the state's inequalities give the interval
of ``s`` where it holds (:func:`intervals`). Singular systems and states with more than
three unknowns get the thesis' LP (:func:`lp_state`, HiGHS). Every "stable" answer is
checked against the model itself (:func:`certified`).

Tolerances are relative (``EPS`` = 1e-9) in units where the grasp has size 1.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._lp import INF, solve_lp
from ..grasp import Grasp
from ..solution import model_residuals
from .enumeration import STATE_NAMES, motion_planes, state_chunks

__all__ = [
    "CACHE_PRELOADS",
    "EPS",
    "Context",
    "Prepared",
    "batch_solutions",
    "certified",
    "contact_forces",
    "equilibrium_terms",
    "intervals",
    "lp_state",
    "prepared_states",
    "singular_screen",
    "state_names",
]

EPS = 1e-9  # relative tolerance of the state checks (geometry normalised to size 1)


@dataclass
class Context:
    """What every state's equations share for one grasp, preload ``p`` and wrench
    ``w0 + s d``: the motion planes ``T``, ``N``, the wrenches of unit contact forces, and
    the absolute slack ``tol`` of the checks at ``s = 0``."""

    grasp: Grasp
    T: NDArray[np.float64]
    N: NDArray[np.float64]
    p: NDArray[np.float64]
    mu: NDArray[np.float64]
    Gn: NDArray[np.float64]  # (m, 3) wrench of a unit normal force
    Gt: NDArray[np.float64]  # (m, 3) wrench of a unit tangential force
    GnN: NDArray[np.float64]  # (m, 9) Gn_i N_i^T flattened
    GtN: NDArray[np.float64]
    That: NDArray[np.float64]  # (m, 3) unit rows of T
    Tperp: NDArray[np.float64]  # (m, 3, 2) orthonormal basis of {r: T_i r = 0}
    w0: NDArray[np.float64]  # wrench at s = 0
    d: NDArray[np.float64]  # wrench per unit s
    tol: float  # slack at s = 0 without motion: eps (|w0| + max p)

    @classmethod
    def make(cls, grasp: Grasp, p, w0, d) -> Context:
        T, N = motion_planes(grasp)
        G = grasp.G
        Gn, Gt = G[:, 0::2].T.copy(), G[:, 1::2].T.copy()
        GnN = np.einsum("ia,ib->iab", Gn, N).reshape(-1, 9)
        GtN = np.einsum("ia,ib->iab", Gt, N).reshape(-1, 9)
        # the model is homogeneous in the force scale (unit springs): no absolute floor
        scale = np.abs(w0).max() + p.max(initial=0.0) + 1e-300
        That = T / np.linalg.norm(T, axis=1, keepdims=True)
        Tperp = np.linalg.svd(That[:, None, :])[2][:, 1:, :].transpose(0, 2, 1)
        return cls(grasp, T, N, p, grasp.mu, Gn, Gt, GnN, GtN, That, Tperp, w0, d, EPS * scale)


def _first_true(mask: NDArray[np.bool_], k: int) -> NDArray[np.intp]:
    """Column indices of the first ``k`` True entries per row (0 where there are fewer)."""
    out = np.zeros((len(mask), k), dtype=np.intp)
    rows = np.flatnonzero(mask.any(axis=1))
    rest = mask[rows]
    sub = np.arange(len(rows))
    for j in range(min(k, mask.shape[1])):
        idx = np.argmax(rest, axis=1)
        out[rows, j] = idx
        rest[sub, idx] = False
    return out


def _null_bases(ctx: Context, S: NDArray[np.int8]) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Basis ``B`` (K, 3, 3) of ``{r : T_i r = 0 for rolling i}`` in its first ``nmot`` columns.

    Regions, facets and lines (<= 2 rolling contacts) are closed-form; faces
    with more rolling contacts (the origin, degenerate grasps) use an SVD.
    """
    K = len(S)
    roll = S == 0
    nroll = roll.sum(axis=1)
    ridx = _first_true(roll, 2)
    B = np.zeros((K, 3, 3))
    nmot = np.zeros(K, dtype=np.intp)
    sel = nroll == 0
    B[sel] = np.eye(3)
    nmot[sel] = 3
    sel = np.flatnonzero(nroll == 1)
    B[sel, :, :2] = ctx.Tperp[ridx[sel, 0]]
    nmot[sel] = 2
    sel = np.flatnonzero(nroll == 2)
    if len(sel):
        i, j = ridx[sel, 0], ridx[sel, 1]
        c = np.cross(ctx.That[i], ctx.That[j])
        nc = np.linalg.norm(c, axis=1)
        line = nc > 1e-9
        B[sel[line], :, 0] = c[line] / nc[line, None]
        nmot[sel[line]] = 1
        same = sel[~line]  # two contacts on one tangential plane
        B[same, :, :2] = ctx.Tperp[i[~line]]
        nmot[same] = 2
    sel = np.flatnonzero(nroll > 2)
    if len(sel):
        TZ = ctx.That[None, :, :] * roll[sel][:, :, None]
        _, sv, Vt = np.linalg.svd(TZ, full_matrices=True)
        k = (sv > 1e-9).sum(axis=1)
        for kk in range(3):
            sk = k == kk
            B[sel[sk], :, : 3 - kk] = Vt[sk, kk:, :].transpose(0, 2, 1)
        nmot[sel] = 3 - k
    return B, nmot


def _complete(M: NDArray[np.float64], nu: NDArray[np.intp]) -> None:
    """Fill the unused columns (``j >= nu``) of each 3 x 3 system with an orthonormal
    basis of the complement of its used columns, in place.

    The system then stays square; the extra unknowns are the equilibrium
    residual off the range of the real columns, which the equilibrium check
    rejects unless it vanishes. With full column rank the result is nonsingular.
    """
    two = np.flatnonzero(nu == 2)
    if len(two):
        c = np.cross(M[two, :, 0], M[two, :, 1])
        M[two, :, 2] = c / np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-300)
    one = np.flatnonzero(nu == 1)
    if len(one):
        a = M[one, :, 0]
        e = np.eye(3)[np.argmin(np.abs(a), axis=1)]
        u = np.cross(a, e)
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
        v = np.cross(a, u)
        M[one, :, 1] = u
        M[one, :, 2] = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
    M[nu == 0] = np.eye(3)


@dataclass
class Prepared:
    """Wrench-independent part of a chunk of states: systems factorised once."""

    S: NDArray[np.int8]
    P: NDArray[np.bool_]
    B: NDArray[np.float64]  # (K, 3, 3) motion basis, first nmot columns
    nmot: NDArray[np.intp]
    nrp: NDArray[np.intp]  # rolling, persisting contacts (free friction unknowns)
    ridx: NDArray[np.intp]  # their indices (first 3)
    h: NDArray[np.float64]  # (K, 3) wrench of the preload forces
    many: NDArray[np.bool_]  # more than 3 unknowns: LP
    square: NDArray[np.bool_]  # nonsingular 3 x 3 system
    inv: NDArray[np.float64]  # (K_square, 3, 3) its inverse
    rest: NDArray[np.intp]  # singular systems
    U_perp: NDArray[np.float64]  # (K_rest, 3, 3) left singular vectors, masked off the range
    M_rest: NDArray[np.float64]  # (K_rest, 3, 3) the singular systems themselves

    def __len__(self) -> int:
        return len(self.S)


def equilibrium_terms(ctx: Context, S, P) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(Q, h)`` per state (K, 3, 3) and (K, 3): the wrench of the normal and slip forces
    is ``sum_persist (Gn_i - mu_i s_i Gt_i)(p_i - N_i r) = h - Q r``."""
    Pf = P.astype(float)
    PS = Pf * S * ctx.mu
    Q = (Pf @ ctx.GnN - PS @ ctx.GtN).reshape(-1, 3, 3)
    h = Pf @ (ctx.p[:, None] * ctx.Gn) - PS @ (ctx.p[:, None] * ctx.Gt)
    return Q, h


def _prepare(ctx: Context, S: NDArray[np.int8], P: NDArray[np.bool_]) -> Prepared:
    """Build and factorise each state's system ``M z = -h - w0 - s d`` (eq. linear_system).

    Unknowns ``z``: motion coordinates in the slip face (``r = B z``) and the
    friction of rolling, persisting contacts; equations: equilibrium
    ``sum_persist (Gn_i - mu_i s_i Gt_i)(p_i - N_i r) + sum_roll Gt_i c_t,i + w = 0``.
    """
    K, m = S.shape
    Pf = P.astype(float)
    Q, h = equilibrium_terms(ctx, S, P)
    B, nmot = _null_bases(ctx, S)
    roll_p = (S == 0) & P
    nrp = roll_p.sum(axis=1)
    nu = nmot + nrp
    M = -(Q @ B)
    # motion columns that vanish relative to what they are built from are exactly zero:
    # round-off must not pose as a direction (it would "solve" singular systems)
    qscale = Pf @ (np.linalg.norm(ctx.Gn, axis=1) * np.linalg.norm(ctx.N, axis=1)) + (
        Pf * ctx.mu
    ) @ (np.linalg.norm(ctx.Gt, axis=1) * np.linalg.norm(ctx.N, axis=1))
    tiny = np.linalg.norm(M, axis=1) <= 1e-12 * qscale[:, None]
    M[np.repeat(tiny[:, None, :], 3, axis=1)] = 0.0
    ridx = _first_true(roll_p, min(3, m))
    rows = np.arange(K)
    for j in range(ridx.shape[1]):
        col = nmot + j
        sel = (j < nrp) & (col < 3)
        M[rows[sel], :, col[sel]] = ctx.Gt[ridx[sel, j]]
    many = nu > 3
    _complete(M, nu)
    a, b, c = M[:, :, 0], M[:, :, 1], M[:, :, 2]
    bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
    det = np.einsum("ki,ki->k", a, bc)
    norms = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1)
    square = (~many) & (np.abs(det) > 1e-12 * norms)
    # Cramer's rule, batched: rows of M^-1 are (b x c, c x a, a x b) / det
    inv = np.stack([bc[square], ca[square], ab[square]], axis=1) / det[square, None, None]
    rest = np.flatnonzero((~many) & (~square))
    U_perp = np.zeros((len(rest), 3, 3))
    if len(rest):
        # rank 2 (the usual singular case): the normal of the column plane is the
        # largest of the three column cross products; lower ranks use an SVD
        cr = np.stack([bc[rest], ca[rest], ab[rest]], axis=1)
        cn = np.linalg.norm(cr, axis=2)
        k = np.argmax(cn, axis=1)
        big = cn[np.arange(len(rest)), k]
        ln = np.linalg.norm(M[rest], axis=1)  # column norms
        pair = np.max(ln * np.roll(ln, 1, axis=1), axis=1)  # largest product of two
        rank2 = big > 1e-10 * pair
        r2 = np.flatnonzero(rank2)
        U_perp[r2, :, 2] = cr[r2, k[r2]] / big[r2, None]
        # rank 1 or 0: the complement of the largest column, or everything
        low = np.flatnonzero(~rank2)
        if len(low):
            Ml = M[rest[low]]
            coln = np.linalg.norm(Ml, axis=1)
            j = np.argmax(coln, axis=1)
            big = coln[np.arange(len(low)), j]
            one = big > 1e-12
            col = Ml[np.arange(len(low)), :, j] / np.maximum(big, 1e-300)[:, None]
            e = np.eye(3)[np.argmin(np.abs(col), axis=1)]
            u = np.cross(col, e)
            u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
            v = np.cross(col, u)
            U_perp[low[one], :, 1] = u[one]
            U_perp[low[one], :, 2] = v[one]
            U_perp[low[~one]] = np.eye(3)
    return Prepared(S, P, B, nmot, nrp, ridx, h, many, square, inv, rest, U_perp, M[rest])


def singular_screen(e0, e1, rhs0_max, d_max, s_max: float):
    """Range test of singular systems: ``(solvable, s_ub)``, elementwise over leading axes.

    ``e0 + s e1`` (last axis) are the components of the right-hand side off the range
    of ``M``; equilibrium is solvable for some ``s`` in ``[0, s_max]`` iff they vanish
    (to ``eps`` of the right-hand side) at the least-squares ``s``, which bounds the
    state's stable ``s`` (``s_max`` when ``e1 = 0``, any ``s``).
    """
    etol = EPS * (rhs0_max + (1.0 + s_max) * d_max)
    n1 = _last(np.add, e1**2)
    s_star = np.clip(-_last(np.add, e0 * e1) / np.maximum(n1, 1e-300), 0.0, s_max)
    resid = np.where(
        n1 > 0,
        _last(np.maximum, np.abs(e0 + s_star[..., None] * e1)),
        _last(np.maximum, np.abs(e0)),
    )
    return resid <= etol, np.where(n1 > 0, s_star, s_max)


def batch_solutions(ctx: Context, pr: Prepared, s_max: float = 0.0):
    """Affine-in-s candidate solutions of each state's system.

    Returns ``(r0, r1, ct0, ct1, lp, skip, s_ub)`` where ``r(s) = r0 + s r1``
    and the rolling friction ``ct(s) = ct0 + s ct1`` ((K, m), zero elsewhere);
    ``lp`` masks states needing the LP (singular with solvable equilibrium
    for some ``s`` in ``[0, s_max]``, or more than 3 unknowns), ``skip`` the
    singular states whose equilibrium has no solution at all, and ``s_ub`` an
    upper bound on the stable ``s`` of each LP state.
    """
    K, m = pr.S.shape
    lp = pr.many.copy()
    skip = np.zeros(K, dtype=bool)
    s_ub = np.full(K, s_max)
    rhs0 = -(pr.h + ctx.w0)
    rhs1 = np.broadcast_to(-ctx.d, (K, 3))
    Z0 = np.zeros((K, 3))
    Z1 = np.zeros((K, 3))
    sq = pr.square
    Z = pr.inv @ np.stack([rhs0[sq], rhs1[sq]], axis=2)
    Z0[sq], Z1[sq] = Z[..., 0], Z[..., 1]
    rest = pr.rest
    if len(rest):
        solvable, s_ub[rest] = singular_screen(
            np.einsum("kai,ka->ki", pr.U_perp, rhs0[rest]),
            np.einsum("kai,ka->ki", pr.U_perp, rhs1[rest]),
            np.abs(rhs0[rest]).max(axis=1),
            np.abs(ctx.d).max(),
            s_max,
        )
        lp[rest[solvable]] = True
        skip[rest[~solvable]] = True
    r0 = (pr.B @ Z0[:, :, None])[..., 0]
    r1 = (pr.B @ Z1[:, :, None])[..., 0]
    ct0 = np.zeros((K, m))
    ct1 = np.zeros((K, m))
    rows = np.arange(K)
    for j in range(pr.ridx.shape[1]):
        col = pr.nmot + j
        sel = (j < pr.nrp) & (col < 3) & ~lp
        ct0[rows[sel], pr.ridx[sel, j]] = Z0[rows[sel], col[sel]]
        ct1[rows[sel], pr.ridx[sel, j]] = Z1[rows[sel], col[sel]]
    return r0, r1, ct0, ct1, lp, skip, s_ub


_CACHE_STATES = 200_000  # cache the factorised states of grasps up to this size
CACHE_PRELOADS = 4


def prepared_states(
    grasp: Grasp, ctx: Context, p: NDArray[np.float64], chunk: int
) -> Iterator[Prepared]:
    """Factorised state chunks of ``(grasp, preload)``, cached on the grasp when small.

    The enumeration and the factorisations do not depend on the wrench, so
    repeated queries on one grasp (maps, sweeps) reuse them.
    """
    cache: dict[bytes, list[Prepared]] = grasp.__dict__.setdefault("_planar_cache", {})
    key = p.tobytes()
    if key in cache:
        yield from cache[key]
        return
    done: list[Prepared] = []
    total = 0
    for S, P in state_chunks(grasp, p, chunk):
        pr = _prepare(ctx, S, P)
        total += len(pr)
        if total <= _CACHE_STATES:
            done.append(pr)
        yield pr
    if total <= _CACHE_STATES:  # reached only when the enumeration ran to the end
        while len(cache) >= CACHE_PRELOADS:
            cache.pop(next(iter(cache)))
        cache[key] = done


def contact_forces(ctx: Context, S, P, r, ct):
    """Contact forces (K, m, 2) of states S, P at motion r with rolling friction ct."""
    cn = np.where(P, ctx.p - r @ ctx.N.T, 0.0)
    c_t = np.where(S == 0, ct, -ctx.mu * S * cn)
    return np.stack([cn, c_t], axis=-1)


def _rows(op, x: NDArray[Any], initial: Any = None) -> NDArray[Any]:
    """``op.reduce(x, axis=1)`` (with ``initial``), column by column for few columns:
    numpy reduces a short last axis row by row, an order of magnitude slower here.
    Exact for the ops used (maximum, minimum, logical_or)."""
    if x.shape[1] > 16 or x.shape[1] == 0:
        return op.reduce(x, axis=1) if initial is None else op.reduce(x, axis=1, initial=initial)
    out = x[:, 0].copy() if initial is None else np.full(len(x), initial, dtype=x.dtype)
    for j in range(0 if initial is not None else 1, x.shape[1]):
        op(out, x[:, j], out=out)
    return out


def _last(op, x: NDArray[Any]) -> NDArray[Any]:
    """``op.reduce(x, axis=-1)`` through :func:`_rows`."""
    return _rows(op, x.reshape(-1, x.shape[-1])).reshape(x.shape[:-1])


def _stage_bounds(g0, g1, e0, e1, lo, hi, hx, s_max):
    """Tighten ``[lo, hi]`` and ``hx`` by the row ``g0 + s g1 >= 0`` on ``s in [0, s_max]``.

    The slack grows with the solution at the ``s`` tested: the row passes when
    ``(g0 + e0) + s (g1 + e1) >= 0`` with ``e0 = eps (1 + |r0|)`` and
    ``e1 = eps |r1|``, so round-off in a row (relative to the motion it comes
    from) never cuts an interval and the slack does not depend on ``s_max``.
    ``hx`` is the exact upper end from rows whose slope is clearly negative.
    """
    a0 = g0 + e0
    a1 = g1 + e1
    pos = a1 > 0
    neg = a1 < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -a0 / a1
        exact = -g0 / g1
    lo = np.maximum(lo, _rows(np.maximum, np.where(pos, bound, 0.0), 0.0))
    hi = np.minimum(hi, _rows(np.minimum, np.where(neg, bound, s_max), s_max))
    steep = g1 < -e1
    hx = np.minimum(hx, _rows(np.minimum, np.where(steep, exact, s_max), s_max))
    bad = _rows(np.logical_or, ~pos & ~neg & (a0 < 0), False)
    return lo, np.where(bad, -np.inf, hi), hx


def intervals(ctx: Context, S, P, r0, r1, ct0, ct1, s_max: float, alive, d=None):
    """For each state, the interval of ``s in [0, s_max]`` where its solution holds.

    Conditions (all closed, relative tolerance ``ctx.tol`` per unit of
    motion, see :func:`_stage_bounds`), checked in stages on the surviving
    states only: contact normal state, slip direction and rolling, friction
    cone of rolling contacts, and equilibrium. Returns ``(feasible, s_hi)``
    with ``s_hi`` the largest feasible ``s`` (exact up to round-off). ``d``: the
    wrench per unit ``s``, ``ctx.d`` by default, or one row per state (direction sweeps).
    """
    K = len(S)
    d = ctx.d if d is None else d
    lo = np.zeros(K)
    hi = np.full(K, s_max)
    hx = np.full(K, s_max)
    hi[~alive] = -np.inf
    e0 = ctx.tol + EPS * _rows(np.maximum, np.abs(r0))
    d_max = np.abs(d).max() if d.ndim == 1 else _rows(np.maximum, np.abs(d))
    e1 = EPS * (d_max + _rows(np.maximum, np.abs(r1)))

    def live():
        return np.flatnonzero(lo <= hi)

    fixed = s_max == 0.0 and not np.any(d)  # Existence: only s = 0 matters

    def update(idx, g0, g1):
        if fixed:
            hi[idx[np.any(g0 < -e0[idx, None], axis=1)]] = -np.inf
            return
        lo[idx], hi[idx], hx[idx] = _stage_bounds(
            g0, g1, e0[idx, None], e1[idx, None], lo[idx], hi[idx], hx[idx], s_max
        )

    if fixed:  # normal: persist N r - p <= tol, detach N r - p >= -tol
        dN = r0 @ ctx.N.T
        dN -= ctx.p
        t = e0[:, None]
        hi[np.any(np.where(P, dN > t, dN < -t), axis=1)] = -np.inf
    else:
        idx = live()  # normal: persist p - N r >= 0, detach N r - p >= 0
        sg = np.where(P[idx], -1.0, 1.0)
        update(idx, sg * (r0[idx] @ ctx.N.T - ctx.p), sg * (r1[idx] @ ctx.N.T))
    idx = live()  # slip direction s_i T_i r >= 0; rolling |T_i r| <= tol
    Si = S[idx].astype(float)
    dT0, dT1 = r0[idx] @ ctx.T.T, r1[idx] @ ctx.T.T
    update(idx, Si * dT0, Si * dT1)
    rolling = Si == 0
    for sign in (1.0, -1.0):
        update(idx, np.where(rolling, sign * dT0, 0.0), np.where(rolling, sign * dT1, 0.0))
    idx = live()  # forces: cone of rolling contacts, then equilibrium
    Pi, Si = P[idx], S[idx]
    cn0 = np.where(Pi, ctx.p - r0[idx] @ ctx.N.T, 0.0)
    cn1 = np.where(Pi, -(r1[idx] @ ctx.N.T), 0.0)
    ct_0 = np.where(Si == 0, ct0[idx], -ctx.mu * Si * cn0)
    ct_1 = np.where(Si == 0, ct1[idx], -ctx.mu * Si * cn1)
    roll = (Si == 0) & Pi
    for sign in (1.0, -1.0):
        update(
            idx,
            np.where(roll, ctx.mu * cn0 - sign * ct_0, 0.0),
            np.where(roll, ctx.mu * cn1 - sign * ct_1, 0.0),
        )
    q0 = cn0 @ ctx.Gn + ct_0 @ ctx.Gt + ctx.w0
    q1 = cn1 @ ctx.Gn + ct_1 @ ctx.Gt + (d if d.ndim == 1 else d[idx])
    keep = lo[idx] <= hi[idx]
    idx, q0, q1 = idx[keep], q0[keep], q1[keep]
    update(idx, q0, q1)
    update(idx, -q0, -q1)
    feas = lo <= hi
    return feas, np.clip(hx, lo, hi)


def certified(ctx: Context, S, P, r, ct, s: float, rtol: float = 1e-7) -> bool:
    """Final check of one candidate against the model itself (not the state's system).

    Equilibrium, spring law, cone and maximum dissipation must hold to
    ``rtol`` relative to the forces involved (dissipation: times the motion).
    Guards every "stable" answer against ill-conditioned state systems.
    """
    c = contact_forces(ctx, S[None], P[None], r[None], ct[None])[0]
    w = ctx.w0 + s * ctx.d
    tol = rtol * (np.abs(w).max() + ctx.p.max(initial=0.0) + np.abs(c).max() + 1e-300)
    res = model_residuals(ctx.grasp, w, c, r, ctx.p)
    dissipation = res.pop("max_dissipation")
    res.pop("slide_alignment")  # the product above decides, as in sweep._certified_rows
    return max(res.values()) <= tol and dissipation <= tol * np.abs(r).max()


def state_names(S, P) -> NDArray[np.str_]:
    """Per contact ``"detach"``, ``"roll"``, ``"slip+"`` or ``"slip-"`` of state ``(S, P)``."""
    return np.array(
        ["detach" if not pp else STATE_NAMES[(1, int(ss))] for ss, pp in zip(S, P, strict=True)]
    )


def lp_state(ctx: Context, S, P, s_bounds: tuple[float, float], sense: int):
    """The thesis' LP for one state: variables (r, rolling c_t, s); sense +1 max s, -1 min s."""
    m = len(S)
    roll_p = np.flatnonzero((S == 0) & P)
    nr = len(roll_p)
    nv = 3 + nr + 1
    rows, lo, hi = [], [], []

    def add(a, lb, ub):
        rows.append(a)
        lo.append(lb)
        hi.append(ub)

    Q, h = equilibrium_terms(ctx, S[None], P[None])
    Q, h = Q[0], h[0]
    for a in range(3):  # equilibrium: -Q r + Gt c_t + s d = -h - w0
        row = np.zeros(nv)
        row[:3] = -Q[a]
        row[3 : 3 + nr] = ctx.Gt[roll_p, a]
        row[-1] = ctx.d[a]
        add(row, -h[a] - ctx.w0[a], -h[a] - ctx.w0[a])
    for i in range(m):
        row = np.zeros(nv)
        row[:3] = ctx.T[i]
        if S[i] == 0:
            add(row, 0.0, 0.0)
        else:
            add(S[i] * row, 0.0, INF)
        row = np.zeros(nv)
        row[:3] = ctx.N[i]
        if P[i]:
            add(row, -INF, ctx.p[i])
        else:
            add(row, ctx.p[i], INF)
    for j, i in enumerate(roll_p):  # |c_t| <= mu (p - N r)
        for sign in (1.0, -1.0):
            row = np.zeros(nv)
            row[:3] = ctx.mu[i] * ctx.N[i]
            row[3 + j] = sign
            add(row, -INF, ctx.mu[i] * ctx.p[i])
    cost = np.zeros(nv)
    cost[-1] = 1.0 if sense else 0.0
    lb = np.full(nv, -INF)
    ub = np.full(nv, INF)
    lb[-1], ub[-1] = s_bounds
    ok, x, _, _ = solve_lp(
        cost, np.array(rows), np.array(lo), np.array(hi), lb, ub, maximize=sense > 0
    )
    if not ok:
        return None
    ct = np.zeros(m)
    ct[roll_p] = x[3 : 3 + nr]
    return x[:3], ct, float(x[-1])
