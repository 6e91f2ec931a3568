"""Planar passive grasp stability in polynomial time (thesis chapter 4).

Model (rigid hand, point contacts with friction, thesis sec. 2dmodel): object
motion ``r = (x, y, theta)``; contact motion ``d = G^T r``, per contact
``d_n = N_i r`` and ``d_t = T_i r`` with ``N_i = [n_i, p_i x n_i]`` and
``T_i = [t_i, p_i x t_i]``. Unit virtual springs with preload ``p_i``:

* persist: ``d_n - p <= 0`` and ``c_n = p - d_n``; detach: ``d_n - p >= 0``, ``c_n = 0``;
* roll: ``d_t = 0``, ``|c_t| <= mu c_n``; slip+: ``d_t >= 0``, ``c_t = -mu c_n``;
  slip-: ``d_t <= 0``, ``c_t = mu c_n`` (maximum dissipation);
* equilibrium ``G c + w = 0``.

Inequalities are closed: on a boundary both neighbouring states give the same
forces, so a solution found for either is a solution of the model.

Algorithm (thesis Alg. complete, with exact geometry instead of one LP per
enumeration step): the candidate contact states are the faces of the
arrangement of the ``m`` central tangential planes (slip states, all faces) and
the ``m`` affine normal planes (detachment states, regions only), enumerated
*jointly* so that only combinations that co-occur for some motion ``r`` are
formed (see :mod:`stability._arrangement`). For every candidate state the
equations are linear in ``r`` restricted to the slip face plus the free
friction forces of rolling contacts; they reduce to a 3 x 3 system
``M z = -h - s d`` solved in batch (eq. linear_system), and the state's
inequalities are checked. States whose system is singular or has more than
three unknowns get the LP of the thesis (HiGHS). Stable iff some state admits
a solution. ``MaxDisturbance`` is exact: along ``w = s d`` each state's
solution is affine in ``s``, so its inequalities give an interval of ``s``
(an LP for singular states); the answer is the largest stable ``s``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._arrangement import affine_faces, central_faces, dedupe_planes
from ._lp import INF, solve_lp
from .api import register
from .errors import GraspError, MethodError
from .grasp import Grasp, cross2
from .queries import Existence, MaxDisturbance, checked_base, checked_direction_cap
from .solution import Solution, model_residuals

__all__ = [
    "slip_states",
    "detachment_states",
    "contact_states",
    "count_slip_faces",
    "motion_planes",
    "slip_states_thesis",
]

STATE_NAMES = {(1, 0): "roll", (1, 1): "slip+", (1, -1): "slip-"}
_EPS = 1e-9  # relative tolerance of the state checks (geometry normalised to size 1)


def motion_planes(grasp: Grasp) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rows ``T_i``, ``N_i`` (each (m, 3)) with ``d_t = T r`` and ``d_n = N r``."""
    _require_planar(grasp)
    p, n, t = grasp.points, grasp.normals, grasp.tangents[:, 0, :]
    T = np.concatenate([t, cross2(p, t)[:, None]], axis=1)
    N = np.concatenate([n, cross2(p, n)[:, None]], axis=1)
    return T, N


def _require_planar(grasp: Grasp) -> None:
    if not isinstance(grasp, Grasp):
        raise GraspError(f"expected a stability.Grasp, got {type(grasp).__name__}")
    if not grasp.planar:
        raise MethodError("the planar method needs a planar grasp (points of shape (m, 2))")


def _slip_arrangement(grasp: Grasp):
    """Distinct tangential planes ``Au`` (with ``idx``, ``orient`` back to contacts) and
    the sign vectors of all faces of their central arrangement."""
    T, _ = motion_planes(grasp)
    Au, _, idx, orient = dedupe_planes(T, np.zeros(len(T)))
    return Au, idx, orient, central_faces(Au)


def slip_states(grasp: Grasp) -> NDArray[np.int8]:
    """Every slip state consistent with a rigid motion of the object: (K, m) in {-1, 0, 1}.

    ``+1``/``-1``: the contact slips in the +t / -t direction (``d_t > 0`` /
    ``< 0``), ``0``: it rolls. Rows are the distinct sign vectors of the faces
    (regions, facets, lines, origin) of the central arrangement of the planes
    ``T_i r = 0``, computed exactly on the sphere in ``O(m^2 log m)`` plus
    ``O(m^3)`` sign evaluations; the first row is the all-rolling state. For
    ``m >= 3`` generic contacts ``K = 4m^2 - 4m + 2`` (thesis table) ``+ 1``
    (the all-rolling state, which we count). For ``m = 2`` the two opposite
    lines where both contacts roll share the all-rolling sign vector, so
    ``K = 9``; :func:`count_slip_faces` counts faces and gives the thesis' 10.
    """
    Au, idx, orient, faces = _slip_arrangement(grasp)
    S = faces[:, idx] * orient
    S = np.unique(S, axis=0)
    zero = np.flatnonzero(~S.any(axis=1))
    order = np.concatenate([zero, np.flatnonzero(S.any(axis=1))])
    return S[order]


def count_slip_faces(grasp: Grasp) -> dict[str, int]:
    """Faces of the tangential-plane arrangement by dimension (thesis sec. state_number).

    ``regions`` (3-faces, all contacts slip), ``facets`` (2-faces), ``lines``
    (1-faces, counted as rays from the origin) and ``origin`` (1 when the
    planes meet only at the origin). ``total`` = regions + facets + lines is
    the thesis' ``#(S)``: ``4m^2 - 4m + 2`` for generic contacts.
    """
    Au, _, _, faces = _slip_arrangement(grasp)
    rank_all = np.linalg.matrix_rank(Au)
    counts = {"regions": 0, "facets": 0, "lines": 0, "origin": 0}
    for f in faces:
        z = np.flatnonzero(f == 0)
        dim = 3 - (np.linalg.matrix_rank(Au[z]) if len(z) else 0)
        if len(z) == len(Au):  # the all-rolling face: origin, or the common line
            if rank_all == 3:
                counts["origin"] += 1
            elif rank_all == 2:
                counts["lines"] += 2
            continue
        counts[{3: "regions", 2: "facets", 1: "lines"}[dim]] += 1
    counts["total"] = counts["regions"] + counts["facets"] + counts["lines"]
    return counts


def _preload(grasp: Grasp, preload: Any) -> NDArray[np.float64]:
    return grasp.per_contact(preload, "preload")


def detachment_states(
    grasp: Grasp, preload: float | NDArray[np.float64] | None = None
) -> NDArray[np.int8]:
    """Detachment states: (K, m) with 1 = contact persists, 0 = detaches (thesis ``U_k``).

    The regions of the affine arrangement ``N_i r = p_i`` (closed on the
    persist side). With preload the planes miss the origin, and there are up
    to ``sum_{k<=3} C(m, k)`` regions; without, ``m(m-1) + 2``.
    """
    _, N = motion_planes(grasp)
    p = _preload(grasp, preload)
    Au, bu, idx, orient = dedupe_planes(N, p)
    faces = np.concatenate(list(affine_faces(Au, bu, np.zeros(len(Au), dtype=bool))))
    faces = faces[np.all(faces != 0, axis=1)]  # regions only (non-simple vertices give all faces)
    U = (faces[:, idx] * orient <= 0).astype(np.int8)
    return np.unique(U, axis=0)


def _planes(grasp: Grasp, p: NDArray[np.float64]):
    T, N = motion_planes(grasp)
    m = grasp.m
    A = np.concatenate([T, N])
    b = np.concatenate([np.zeros(m), p])
    Au, bu, idx, orient = dedupe_planes(A, b)
    may_zero = np.zeros(len(Au), dtype=bool)
    may_zero[idx[:m]] = True
    return T, N, Au, bu, idx, orient, may_zero


def _state_chunks(
    grasp: Grasp, p: NDArray[np.float64], chunk: int = 8192
) -> Iterator[tuple[NDArray[np.int8], NDArray[np.bool_]]]:
    """Candidate (slip state S, persist mask P) chunks co-occurring for some motion.

    Small pieces from the enumeration are merged to about ``chunk`` rows so
    that the batched solves amortise their overhead.
    """
    m = grasp.m
    _, _, Au, bu, idx, orient, may_zero = _planes(grasp, p)
    buf: list[NDArray[np.int8]] = []
    rows = 0
    first = True
    for f in affine_faces(Au, bu, may_zero, chunk=chunk):
        buf.append(f)
        rows += len(f)
        if rows >= chunk or first:  # the first piece (the origin's faces) goes out alone
            first = False
            sv = np.concatenate(buf)[:, idx] * orient
            yield sv[:, :m], sv[:, m:] <= 0
            buf, rows = [], 0
    if buf:
        sv = np.concatenate(buf)[:, idx] * orient
        yield sv[:, :m], sv[:, m:] <= 0


def contact_states(
    grasp: Grasp, preload: float | NDArray[np.float64] | None = None
) -> tuple[NDArray[np.int8], NDArray[np.int8]]:
    """All co-occurring (slip, detachment) state pairs, deduplicated.

    Returns ``(S, U)``, each (K, m): ``S`` in {-1, 0, 1} (slip-, roll, slip+),
    ``U`` in {0, 1} (detach, persist). This is the set the solver visits
    (thesis ``T = U x S``, restricted to pairs some motion realises).
    """
    _require_planar(grasp)
    p = _preload(grasp, preload)
    parts = [np.concatenate([S, P.astype(np.int8)], axis=1) for S, P in _state_chunks(grasp, p)]
    both = np.unique(np.concatenate(parts), axis=0)
    return both[:, : grasp.m], both[:, grasp.m :]


# ----------------------------------------------------------------------------------------
# per-state solve


@dataclass
class _Ctx:
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
    def make(cls, grasp: Grasp, p, w0, d) -> _Ctx:
        T, N = motion_planes(grasp)
        G = grasp.G
        Gn, Gt = G[:, 0::2].T.copy(), G[:, 1::2].T.copy()
        GnN = np.einsum("ia,ib->iab", Gn, N).reshape(-1, 9)
        GtN = np.einsum("ia,ib->iab", Gt, N).reshape(-1, 9)
        # the model is homogeneous in the force scale (unit springs): no absolute floor
        scale = np.abs(w0).max() + p.max(initial=0.0) + 1e-300
        That = T / np.linalg.norm(T, axis=1, keepdims=True)
        Tperp = np.linalg.svd(That[:, None, :])[2][:, 1:, :].transpose(0, 2, 1)
        return cls(grasp, T, N, p, grasp.mu, Gn, Gt, GnN, GtN, That, Tperp, w0, d, _EPS * scale)


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


def _null_bases(ctx: _Ctx, S: NDArray[np.int8]) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
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
class _Prep:
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

    def __len__(self) -> int:
        return len(self.S)


def _equilibrium_terms(ctx: _Ctx, S, P) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(Q, h)`` per state (K, 3, 3) and (K, 3): the wrench of the normal and slip forces
    is ``sum_persist (Gn_i - mu_i s_i Gt_i)(p_i - N_i r) = h - Q r``."""
    Pf = P.astype(float)
    PS = Pf * S * ctx.mu
    Q = (Pf @ ctx.GnN - PS @ ctx.GtN).reshape(-1, 3, 3)
    h = Pf @ (ctx.p[:, None] * ctx.Gn) - PS @ (ctx.p[:, None] * ctx.Gt)
    return Q, h


def _prepare(ctx: _Ctx, S: NDArray[np.int8], P: NDArray[np.bool_]) -> _Prep:
    """Build and factorise each state's system ``M z = -h - w0 - s d`` (eq. linear_system).

    Unknowns ``z``: motion coordinates in the slip face (``r = B z``) and the
    friction of rolling, persisting contacts; equations: equilibrium
    ``sum_persist (Gn_i - mu_i s_i Gt_i)(p_i - N_i r) + sum_roll Gt_i c_t,i + w = 0``.
    """
    K, m = S.shape
    Pf = P.astype(float)
    Q, h = _equilibrium_terms(ctx, S, P)
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
    return _Prep(S, P, B, nmot, nrp, ridx, h, many, square, inv, rest, U_perp)


def _batch(ctx: _Ctx, pr: _Prep, s_max: float = 0.0):
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
        # singular: the LP is needed only if equilibrium is solvable for some s, i.e.
        # rhs0 + s rhs1 lies in range(M) (components e0 + s e1 off the range vanish)
        e0 = np.einsum("kai,ka->ki", pr.U_perp, rhs0[rest])
        e1 = np.einsum("kai,ka->ki", pr.U_perp, rhs1[rest])
        etol = _EPS * (np.abs(rhs0[rest]).max(axis=1) + (1.0 + s_max) * np.abs(ctx.d).max())
        n1 = (e1**2).sum(axis=1)
        s_star = np.clip(-(e0 * e1).sum(axis=1) / np.maximum(n1, 1e-300), 0.0, s_max)
        resid = np.where(
            n1 > 0, np.abs(e0 + s_star[:, None] * e1).max(axis=1), np.abs(e0).max(axis=1)
        )
        lp[rest[resid <= etol]] = True
        skip[rest[resid > etol]] = True
        s_ub[rest] = np.where(n1 > 0, s_star, s_max)
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
_CACHE_PRELOADS = 4


def _prepared(grasp: Grasp, ctx: _Ctx, p: NDArray[np.float64], chunk: int) -> Iterator[_Prep]:
    """Factorised state chunks of ``(grasp, preload)``, cached on the grasp when small.

    The enumeration and the factorisations do not depend on the wrench, so
    repeated queries on one grasp (maps, sweeps) reuse them.
    """
    cache: dict[bytes, list[_Prep]] = grasp.__dict__.setdefault("_planar_cache", {})
    key = p.tobytes()
    if key in cache:
        yield from cache[key]
        return
    done: list[_Prep] = []
    total = 0
    for S, P in _state_chunks(grasp, p, chunk):
        pr = _prepare(ctx, S, P)
        total += len(pr)
        if total <= _CACHE_STATES:
            done.append(pr)
        yield pr
    if total <= _CACHE_STATES:  # reached only when the enumeration ran to the end
        while len(cache) >= _CACHE_PRELOADS:
            cache.pop(next(iter(cache)))
        cache[key] = done


def _forces(ctx: _Ctx, S, P, r, ct):
    """Contact forces (K, m, 2) of states S, P at motion r with rolling friction ct."""
    cn = np.where(P, ctx.p - r @ ctx.N.T, 0.0)
    c_t = np.where(S == 0, ct, -ctx.mu * S * cn)
    return np.stack([cn, c_t], axis=-1)


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
    lo = np.maximum(lo, np.max(np.where(pos, bound, 0.0), axis=1, initial=0.0))
    hi = np.minimum(hi, np.min(np.where(neg, bound, s_max), axis=1, initial=s_max))
    steep = g1 < -e1
    hx = np.minimum(hx, np.min(np.where(steep, exact, s_max), axis=1, initial=s_max))
    bad = np.any(~pos & ~neg & (a0 < 0), axis=1)
    return lo, np.where(bad, -np.inf, hi), hx


def _intervals(ctx: _Ctx, S, P, r0, r1, ct0, ct1, s_max: float, alive):
    """For each state, the interval of ``s in [0, s_max]`` where its solution holds.

    Conditions (all closed, relative tolerance ``ctx.tol`` per unit of
    motion, see :func:`_stage_bounds`), checked in stages on the surviving
    states only: contact normal state, slip direction and rolling, friction
    cone of rolling contacts, and equilibrium. Returns ``(feasible, s_hi)``
    with ``s_hi`` the largest feasible ``s`` (exact up to round-off).
    """
    K = len(S)
    lo = np.zeros(K)
    hi = np.full(K, s_max)
    hx = np.full(K, s_max)
    hi[~alive] = -np.inf
    e0 = ctx.tol + _EPS * np.abs(r0).max(axis=1)
    e1 = _EPS * (np.abs(ctx.d).max() + np.abs(r1).max(axis=1))

    def live():
        return np.flatnonzero(lo <= hi)

    fixed = s_max == 0.0 and not np.any(ctx.d)  # Existence: only s = 0 matters

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
    q1 = cn1 @ ctx.Gn + ct_1 @ ctx.Gt + ctx.d
    keep = lo[idx] <= hi[idx]
    idx, q0, q1 = idx[keep], q0[keep], q1[keep]
    update(idx, q0, q1)
    update(idx, -q0, -q1)
    feas = lo <= hi
    return feas, np.clip(hx, lo, hi)


def _certified(ctx: _Ctx, S, P, r, ct, s: float, rtol: float = 1e-7) -> bool:
    """Final check of one candidate against the model itself (not the state's system).

    Equilibrium, spring law, cone and maximum dissipation must hold to
    ``rtol`` relative to the forces involved (dissipation: times the motion).
    Guards every "stable" answer against ill-conditioned state systems.
    """
    c = _forces(ctx, S[None], P[None], r[None], ct[None])[0]
    w = ctx.w0 + s * ctx.d
    tol = rtol * (np.abs(w).max() + ctx.p.max(initial=0.0) + np.abs(c).max() + 1e-300)
    res = model_residuals(ctx.grasp, w, c, r, ctx.p)
    dissipation = res.pop("max_dissipation")
    return max(res.values()) <= tol and dissipation <= tol * np.abs(r).max()


def _names(S, P) -> NDArray[np.str_]:
    return np.array(
        ["detach" if not pp else STATE_NAMES[(1, int(ss))] for ss, pp in zip(S, P, strict=True)]
    )


def _lp_state(ctx: _Ctx, S, P, s_bounds: tuple[float, float], sense: int):
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

    Q, h = _equilibrium_terms(ctx, S[None], P[None])
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


def _solution(grasp, query, ctx, S, P, r, ct, s, stable, value, stats) -> Solution:
    c = _forces(ctx, S[None], P[None], r[None], ct[None])[0]
    return Solution(
        stable=stable,
        method="planar",
        grasp=grasp,
        query=query,
        forces=c,
        motion=r,
        value=value,
        states=_names(S, P),
        stats=stats,
    )


@register(
    "planar",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=False,
    summary="thesis ch. 4: exact, polynomial-time enumeration of co-occurring states",
)
def _solve_planar(
    grasp: Grasp, query: Existence | MaxDisturbance, chunk: int = 8192, **options: Any
) -> Solution:
    if options:
        raise GraspError(f"unknown option(s) for method 'planar': {sorted(options)}")
    if not isinstance(chunk, int | np.integer) or chunk < 1:
        raise GraspError(f"option chunk must be a positive integer, got {chunk!r}")
    p = _preload(grasp, query.preload)
    # Work in units where the grasp has size 1: the model is invariant under
    # points -> points / L with torques / L and rotations * L, and tolerances
    # are then dimensionally consistent (unit springs: force ~ length).
    L, unit = _unit_grasp(grasp)
    scale = np.array([1.0, 1.0, 1.0 / L])
    if isinstance(query, Existence):
        w = grasp.wrench(query.wrench)
        sol = _existence(unit, query, p, w * scale, chunk)
    else:
        d, cap = checked_direction_cap(grasp, query)
        base = checked_base(grasp, query)
        sol = _max_disturbance(unit, query, p, d * scale, cap, chunk, base * scale)
    sol.grasp = grasp
    if sol.motion is not None:
        sol.motion = sol.motion * scale  # theta = theta_unit / L
    return sol


def _unit_grasp(grasp: Grasp) -> tuple[float, Grasp]:
    """``(L, grasp with points / L)``, ``L`` the largest contact distance from the origin."""
    cached = grasp.__dict__.get("_planar_unit")
    if cached is None:
        L = float(np.abs(grasp.points).max())
        L = L if L > 0 else 1.0
        cached = (L, Grasp(grasp.points / L, grasp.normals, grasp.mu))
        grasp.__dict__["_planar_unit"] = cached
    return cached


def _existence(grasp, query, p, w, chunk) -> Solution:
    ctx = _Ctx.make(grasp, p, w, np.zeros(3))
    n_states = n_lp = n_rejected = 0
    for pr in _prepared(grasp, ctx, p, chunk):
        S, P = pr.S, pr.P
        n_states += len(S)
        r0, r1, ct0, ct1, lp, skip, _ = _batch(ctx, pr)
        ok, _ = _intervals(ctx, S, P, r0, r1, ct0, ct1, 0.0, ~lp & ~skip)
        for k in np.flatnonzero(ok):
            if _certified(ctx, S[k], P[k], r0[k], ct0[k], 0.0):
                stats = {"states": n_states, "lps": n_lp}
                return _solution(
                    grasp, query, ctx, S[k], P[k], r0[k], ct0[k], 0.0, True, None, stats
                )
            n_rejected += 1
        for k in np.flatnonzero(lp):
            n_lp += 1
            res = _lp_state(ctx, S[k], P[k], (0.0, 0.0), sense=0)
            if res is not None and _certified(ctx, S[k], P[k], res[0], res[1], 0.0):
                r, ct, _ = res
                stats = {"states": n_states, "lps": n_lp}
                return _solution(grasp, query, ctx, S[k], P[k], r, ct, 0.0, True, None, stats)
    return Solution(
        stable=False,
        method="planar",
        grasp=grasp,
        query=query,
        stats={"states": n_states, "lps": n_lp, "rejected": n_rejected},
    )


def _max_disturbance(grasp, query, p, d, cap, chunk, base=None) -> Solution:
    ctx = _Ctx.make(grasp, p, np.zeros(3) if base is None else base, d)
    pending: list[tuple[float, NDArray[np.int8], NDArray[np.bool_]]] = []
    best: tuple[float, Any] = (-1.0, None)
    n_states = n_lp = n_rejected = 0
    for pr in _prepared(grasp, ctx, p, chunk):
        S, P = pr.S, pr.P
        n_states += len(S)
        r0, r1, ct0, ct1, lp, skip, s_ub = _batch(ctx, pr, cap)
        feas, hi = _intervals(ctx, S, P, r0, r1, ct0, ct1, cap, ~lp & ~skip)
        cand = np.flatnonzero(feas & (hi > best[0]))
        for k in cand[np.argsort(-hi[cand])]:  # best first; the first certified one wins
            s = hi[k]
            r, ct = r0[k] + s * r1[k], ct0[k] + s * ct1[k]
            if _certified(ctx, S[k], P[k], r, ct, s):
                best = (s, (S[k], P[k], r, ct))
                break
            n_rejected += 1
        pending += [(s_ub[k], S[k], P[k]) for k in np.flatnonzero(lp)]
    # LP states last, most promising first; stop once none can beat the best s
    pending.sort(key=lambda x: -x[0])
    for ub, S_k, P_k in pending:
        if ub <= best[0] + 1e-12 * (1.0 + best[0]):
            break
        n_lp += 1
        res = _lp_state(ctx, S_k, P_k, (0.0, min(ub, cap)), sense=1)
        if res is not None and res[2] > best[0] and _certified(ctx, S_k, P_k, *res):
            r, ct, s = res
            best = (s, (S_k, P_k, r, ct))
    stats: dict[str, Any] = {"states": n_states, "lps": n_lp, "rejected": n_rejected}
    if best[1] is None:
        stats["capped"] = False
        return Solution(
            stable=False, method="planar", grasp=grasp, query=query, value=None, stats=stats
        )
    value = float(min(best[0], cap))
    stats["capped"] = bool(value >= cap * (1 - 1e-12))
    S, P, r, ct = best[1]
    return _solution(grasp, query, ctx, S, P, r, ct, value, True, value, stats)


def slip_states_thesis(grasp: Grasp) -> NDArray[np.int8]:
    """The thesis' own slip-state enumeration (sec. enumeration), as a reference.

    Step 1 (Alg. buildset): add the planes ``T_i r = 0`` one at a time and keep
    every region that meets each open half-space, one LP each (HiGHS; regions
    are open cones, so ``s_j T_j r >= 1`` stands for ``> 0``). Step 2: regions
    whose sign vectors differ in one entry share a facet (the dual
    polyhedron's edges). Step 3: the faces of the dual polyhedron, from a
    minimum cycle basis (networkx) plus the symmetric sum of its cycles, are
    the lines. Step 4: the all-rolling state. Returns the distinct states like
    :func:`slip_states`; used by the benchmark (the thesis' algorithm timed on
    the same machine) and by the tests (agreement of independent methods).
    """
    import networkx as nx

    T, _ = motion_planes(grasp)
    m = grasp.m
    regions: list[tuple[int, ...]] = [()]
    for i in range(m):
        grown = []
        for s in regions:
            for side in (1, -1):
                rows = np.array([sj * T[j] for j, sj in enumerate(s)] + [side * T[i]])
                ok, _, _, _ = solve_lp(
                    np.zeros(3), rows, np.ones(len(rows)), np.full(len(rows), INF),
                    np.full(3, -INF), np.full(3, INF),
                )  # fmt: skip
                if ok:
                    grown.append((*s, side))
        regions = grown
    R = np.array(regions, dtype=np.int8)
    graph = nx.Graph()
    graph.add_nodes_from(range(len(R)))
    states = [np.zeros((1, m), dtype=np.int8), R]
    diff = (R[:, None, :] != R[None, :, :]).sum(axis=2)
    for a, b in zip(*np.nonzero(np.triu(diff == 1)), strict=True):
        graph.add_edge(int(a), int(b))
        f = R[a].copy()
        f[R[a] != R[b]] = 0
        states.append(f[None])
    if graph.number_of_edges():
        cycles = [set(c) for c in nx.minimum_cycle_basis(graph)]
        edge_sets = [{e for e in graph.subgraph(c).edges()} for c in cycles]
        last: set = set()
        for es in edge_sets:
            last ^= {tuple(sorted(e)) for e in es}
        faces = [sorted({n for e in es for n in e}) for es in edge_sets]
        if last:
            faces.append(sorted({n for e in last for n in e}))
        for nodes in faces:
            sub = R[nodes]
            f = sub[0].copy()
            f[np.any(sub != sub[0], axis=0)] = 0
            states.append(f[None])
    return np.unique(np.concatenate(states), axis=0)
