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
:func:`max_disturbance_map` answers many directions at once against the same states.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._arrangement import affine_faces, central_faces, dedupe_planes
from ._lp import INF, solve_lp
from .api import _METHODS, register
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
    "max_disturbance_map",
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
    M_rest: NDArray[np.float64]  # (K_rest, 3, 3) the singular systems themselves

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
    return _Prep(S, P, B, nmot, nrp, ridx, h, many, square, inv, rest, U_perp, M[rest])


def _singular_screen(e0, e1, rhs0_max, d_max, s_max: float):
    """Range test of singular systems: ``(solvable, s_ub)``, elementwise over leading axes.

    ``e0 + s e1`` (last axis) are the components of the right-hand side off the range
    of ``M``; equilibrium is solvable for some ``s`` in ``[0, s_max]`` iff they vanish
    (to ``eps`` of the right-hand side) at the least-squares ``s``, which bounds the
    state's stable ``s`` (``s_max`` when ``e1 = 0``, any ``s``).
    """
    etol = _EPS * (rhs0_max + (1.0 + s_max) * d_max)
    n1 = _last(np.add, e1**2)
    s_star = np.clip(-_last(np.add, e0 * e1) / np.maximum(n1, 1e-300), 0.0, s_max)
    resid = np.where(
        n1 > 0,
        _last(np.maximum, np.abs(e0 + s_star[..., None] * e1)),
        _last(np.maximum, np.abs(e0)),
    )
    return resid <= etol, np.where(n1 > 0, s_star, s_max)


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
        solvable, s_ub[rest] = _singular_screen(
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


def _intervals(ctx: _Ctx, S, P, r0, r1, ct0, ct1, s_max: float, alive, d=None):
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
    e0 = ctx.tol + _EPS * _rows(np.maximum, np.abs(r0))
    d_max = np.abs(d).max() if d.ndim == 1 else _rows(np.maximum, np.abs(d))
    e1 = _EPS * (d_max + _rows(np.maximum, np.abs(r1)))

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
def _solve_planar(grasp: Grasp, query: Existence | MaxDisturbance, **options: Any) -> Solution:
    chunk = _options(options)
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


def _options(options: dict[str, Any]) -> int:
    """The planar method's options: ``chunk`` (states per batch, default 8192)."""
    chunk = options.pop("chunk", 8192)
    if options:
        raise GraspError(f"unknown option(s) for method 'planar': {sorted(options)}")
    if not isinstance(chunk, int | np.integer) or chunk < 1:
        raise GraspError(f"option chunk must be a positive integer, got {chunk!r}")
    return int(chunk)


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


# ----------------------------------------------------------------------------------------
# direction sweeps: MaxDisturbance for many directions at once (resistible-force maps)

_SWEEP_ROWS = 32_768  # (state, direction) rows per vectorised block
_PRECHECK_RTOL = 1e-6  # margin of the LP precheck, relative to the forces and motions involved
_PIN_RTOL = 1e-3  # s counts as pinned by equilibrium when |e1| >= this * |d|


@dataclass
class _Sweep:
    """The distinct states of ``(grasp, preload)``, split for direction sweeps.

    ``S, P, B, C, h, inv``: states with a nonsingular system, whose solution is affine
    in ``s`` for every direction (as in :class:`_Prep`, with ``c_t = C z``); ``r*`` and
    ``U_perp``: singular systems (LP states where the range test passes); ``m*``: more
    than three unknowns (always LP states). For the singular states of rank 2, ``pinv``
    and ``null`` (pseudo-inverse and unit null vector of ``M``) serve the precheck that
    spares the LP where equilibrium pins ``s`` and the state's conditions have no
    solution there; ``fixed`` marks the states with more unknowns whose rolling
    contacts hold the object still (generic for ``m >= 4``: all rolling), where the
    stable wrenches form a zonotope (:func:`_zonotope_bounds`).
    """

    S: NDArray[np.int8]
    P: NDArray[np.bool_]
    B: NDArray[np.float64]
    C: NDArray[np.float64]  # (K, m, 3): rolling friction c_t = C z
    h: NDArray[np.float64]
    inv: NDArray[np.float64]
    rS: NDArray[np.int8]
    rP: NDArray[np.bool_]
    rB: NDArray[np.float64]
    rC: NDArray[np.float64]
    rh: NDArray[np.float64]
    U_perp: NDArray[np.float64]
    pinv: NDArray[np.float64]  # (K_rest, 3, 3)
    null: NDArray[np.float64]  # (K_rest, 3)
    rank2: NDArray[np.bool_]  # null space of dimension 1 (precheck applies)
    mS: NDArray[np.int8]
    mP: NDArray[np.bool_]
    mh: NDArray[np.float64]  # (K_many, 3) preload wrench
    fixed: NDArray[np.bool_]  # (K_many,) rolling contacts pin the motion to r = 0


def _friction_selector(pr: _Prep, m: int) -> NDArray[np.float64]:
    """(K, m, 3) 0/1 matrices with ``c_t = C z`` for the rolling, persisting contacts."""
    K = len(pr)
    C = np.zeros((K, m, 3))
    rows = np.arange(K)
    for j in range(pr.ridx.shape[1]):
        col = pr.nmot + j
        sel = (j < pr.nrp) & (col < 3)
        C[rows[sel], pr.ridx[sel, j], col[sel]] = 1.0
    return C


def _distinct(S: NDArray[np.int8], P: NDArray[np.bool_]) -> NDArray[np.intp]:
    """Indices of the first occurrence of each distinct ``(S, P)`` row, in order."""
    if len(S) == 0:
        return np.zeros(0, dtype=np.intp)
    _, first = np.unique(np.concatenate([S, P.astype(np.int8)], axis=1), axis=0, return_index=True)
    return np.sort(first)


def _sweep_states(grasp: Grasp, ctx: _Ctx, p: NDArray[np.float64], chunk: int) -> _Sweep:
    """:class:`_Sweep` of ``(grasp, preload)``, cached on the grasp next to :func:`_prepared`."""
    cache: dict[bytes, _Sweep] = grasp.__dict__.setdefault("_planar_sweep", {})
    key = p.tobytes()
    if key in cache:
        return cache[key]
    m = grasp.m
    parts: dict[str, list[NDArray[Any]]] = {k: [] for k in (*_Sweep.__dataclass_fields__, "M")}
    for pr in _prepared(grasp, ctx, p, chunk):
        C = _friction_selector(pr, m)
        sq = np.flatnonzero(pr.square)
        for name, val in zip(
            ("S", "P", "B", "C", "h", "inv"),
            (pr.S[sq], pr.P[sq], pr.B[sq], C[sq], pr.h[sq], pr.inv),
            strict=True,
        ):
            parts[name].append(val)
        r = pr.rest
        for name, val in zip(
            ("rS", "rP", "rB", "rC", "rh", "U_perp", "M"),
            (pr.S[r], pr.P[r], pr.B[r], C[r], pr.h[r], pr.U_perp, pr.M_rest),
            strict=True,
        ):
            parts[name].append(val)
        many = np.flatnonzero(pr.many)
        parts["mS"].append(pr.S[many])
        parts["mP"].append(pr.P[many])
        parts["mh"].append(pr.h[many])
        parts["fixed"].append(pr.nmot[many] == 0)
    cat = {k: np.concatenate(v) for k, v in parts.items() if v}
    keep = _distinct(cat["S"], cat["P"])
    for k in ("S", "P", "B", "C", "h", "inv"):
        cat[k] = cat[k][keep]
    keep = _distinct(cat["rS"], cat["rP"])
    for k in ("rS", "rP", "rB", "rC", "rh", "U_perp", "M"):
        cat[k] = cat[k][keep]
    keep = _distinct(cat["mS"], cat["mP"])
    for k in ("mS", "mP", "mh", "fixed"):
        cat[k] = cat[k][keep]
    # r = 0 only when the rolling contacts' tangential planes meet well away from rank 3
    roll = cat["mS"] == 0
    if len(roll) and m >= 3:
        sv = np.linalg.svd(ctx.That[None] * roll[:, :, None], compute_uv=False)
        cat["fixed"] &= sv[:, 2] >= 1e-3
    else:
        cat["fixed"][:] = False
    # rank-2 singular systems: pseudo-inverse on the range, unit null vector
    M = cat.pop("M")
    U, sv, Vt = np.linalg.svd(M) if len(M) else (M, np.zeros((0, 3)), M)
    rank2 = (sv[:, 1] > 1e-9 * sv[:, 0]) & ~np.any(cat["U_perp"][:, :, :2], axis=(1, 2))
    inv_sv = np.where(rank2[:, None], 1.0 / np.where(sv[:, :2] > 0, sv[:, :2], 1.0), 0.0)
    cat["pinv"] = np.einsum("kai,ka,kja->kij", Vt[:, :2, :], inv_sv, U[:, :, :2])
    cat["null"] = Vt[:, 2, :]
    cat["rank2"] = rank2
    sweep = _Sweep(**cat)
    if len(cache) >= _CACHE_PRELOADS:
        cache.pop(next(iter(cache)))
    cache[key] = sweep
    return sweep


def _certified_rows(ctx: _Ctx, S, P, r, ct, s, d, rtol: float = 1e-7) -> NDArray[np.bool_]:
    """:func:`_certified` for many candidates at once: rows of states, motions, friction,
    ``s`` and directions ``d`` (wrench ``w0 + s d``); the same residuals and tolerances."""
    n, m = S.shape
    c = _forces(ctx, S, P, r, ct)
    w = ctx.w0 + s[:, None] * d
    tol = rtol * (
        np.abs(w).max(axis=1) + ctx.p.max(initial=0.0) + np.abs(c).max(axis=(1, 2)) + 1e-300
    )
    G = ctx.grasp.G
    cn, c_t = c[..., 0], c[..., 1]
    mot = (r @ G).reshape(n, m, 2)
    dn, dt = mot[..., 0], mot[..., 1]
    worst = np.max(
        [
            np.abs(c.reshape(n, -1) @ G.T + w).max(axis=1),  # equilibrium
            np.maximum(0.0, -cn).max(axis=1),  # normal sign
            np.maximum(0.0, np.abs(c_t) - ctx.mu * cn).max(axis=1),  # friction cone
            np.abs(cn - np.maximum(0.0, ctx.p - dn)).max(axis=1),  # spring law
        ],
        axis=0,
    )
    dissipation = np.abs(c_t * dt + ctx.mu * cn * np.abs(dt)).max(axis=1)
    return (worst <= tol) & (dissipation <= tol * np.abs(r).max(axis=1))


def _sweep_square(ctx: _Ctx, sw: _Sweep, D: NDArray[np.float64], cap: float):
    """Best certified ``s`` per direction over the square states: ``(found, best)``.

    All (state, direction) pairs go through :func:`_intervals` at once; per direction
    the candidates are certified best first, as in :func:`_max_disturbance`.
    """
    K, nd = len(sw.S), len(D)
    found = np.zeros(nd, dtype=bool)
    best = np.full(nd, -1.0)
    if K == 0 or nd == 0:
        return found, best
    rhs0 = -(sw.h + ctx.w0)
    Z0 = (sw.inv @ rhs0[:, :, None])[..., 0]
    r0 = (sw.B @ Z0[:, :, None])[..., 0]
    ct0 = (sw.C @ Z0[:, :, None])[..., 0]
    step = max(1, _SWEEP_ROWS // K)
    for a in range(0, nd, step):
        Db = D[a : a + step]
        nb = len(Db)
        Z1 = -(sw.inv @ Db.T)  # (K, 3, nb)
        r1 = (sw.B @ Z1).transpose(0, 2, 1).reshape(-1, 3)
        ct1 = (sw.C @ Z1).transpose(0, 2, 1).reshape(-1, ctx.grasp.m)
        S = np.repeat(sw.S, nb, axis=0)
        P = np.repeat(sw.P, nb, axis=0)
        R0 = np.repeat(r0, nb, axis=0)
        CT0 = np.repeat(ct0, nb, axis=0)
        d_rows = np.tile(Db, (K, 1))
        feas, hi = _intervals(ctx, S, P, R0, r1, CT0, ct1, cap, np.ones(K * nb, bool), d_rows)
        H = np.where(feas, hi, -np.inf).reshape(K, nb)
        todo = np.arange(nb)
        while len(todo):
            k = np.argmax(H[:, todo], axis=0)
            s = H[k, todo]
            live = s > -np.inf
            todo, k, s = todo[live], k[live], s[live]
            if not len(todo):
                break
            rows = k * nb + todo
            ok = _certified_rows(
                ctx, S[rows], P[rows], R0[rows] + s[:, None] * r1[rows],
                CT0[rows] + s[:, None] * ct1[rows], s, Db[todo],
            )  # fmt: skip
            found[a + todo[ok]] = True
            best[a + todo[ok]] = s[ok]
            H[k[~ok], todo[~ok]] = -np.inf  # rejected: the next best state of the direction
            todo = todo[~ok]
    return found, best


def _precheck(ctx: _Ctx, sw: _Sweep, k, s, d) -> NDArray[np.bool_]:
    """Whether the LP of rank-2 singular state ``k`` may have a solution at the ``s`` that
    equilibrium pins, per pair (``k``, ``s``, ``d`` rows).

    At that ``s`` the solutions of the state's system form a line ``z = z_p + t n``;
    every condition of :func:`_intervals` is affine in ``t``. False only when no ``t``
    satisfies them all, each relaxed by ``_PRECHECK_RTOL`` of the forces and motions
    involved, so that a "no" is one the LP would give too (the tests hold it to HiGHS).
    """
    if len(k) == 0:
        return np.zeros(0, dtype=bool)
    S, P = sw.rS[k], sw.rP[k]
    w = ctx.w0 + s[:, None] * d
    zp = (sw.pinv[k] @ (-(sw.rh[k] + w))[:, :, None])[..., 0]
    nv = sw.null[k]
    Bk, Ck = sw.rB[k], sw.rC[k]
    ra, rb = (Bk @ zp[:, :, None])[..., 0], (Bk @ nv[:, :, None])[..., 0]
    cta, ctb = (Ck @ zp[:, :, None])[..., 0], (Ck @ nv[:, :, None])[..., 0]
    cn_a = np.where(P, ctx.p - ra @ ctx.N.T, 0.0)
    cn_b = np.where(P, -(rb @ ctx.N.T), 0.0)
    ct_a = np.where(S == 0, cta, -ctx.mu * S * cn_a)
    ct_b = np.where(S == 0, ctb, -ctx.mu * S * cn_b)
    sg = np.where(P, -1.0, 1.0)
    dTa, dTb = ra @ ctx.T.T, rb @ ctx.T.T
    roll = S == 0
    rp = roll & P
    q_a = cn_a @ ctx.Gn + ct_a @ ctx.Gt + w
    q_b = cn_b @ ctx.Gn + ct_b @ ctx.Gt
    g0 = np.concatenate(
        [sg * (ra @ ctx.N.T - ctx.p), S * dTa, np.where(roll, dTa, 0.0),
         np.where(roll, -dTa, 0.0), np.where(rp, ctx.mu * cn_a - ct_a, 0.0),
         np.where(rp, ctx.mu * cn_a + ct_a, 0.0), q_a, -q_a],
        axis=1,
    )  # fmt: skip
    g1 = np.concatenate(
        [sg * (rb @ ctx.N.T), S * dTb, np.where(roll, dTb, 0.0), np.where(roll, -dTb, 0.0),
         np.where(rp, ctx.mu * cn_b - ct_b, 0.0), np.where(rp, ctx.mu * cn_b + ct_b, 0.0),
         q_b, -q_b],
        axis=1,
    )  # fmt: skip
    size = np.abs(w).max(axis=1) + ctx.p.max(initial=0.0) + np.abs(zp).max(axis=1)
    a0 = g0 + (_PRECHECK_RTOL * (1.0 + size))[:, None]  # row holds when a0 + t g1 >= 0
    flat = np.abs(g1) <= 1e-12 * (1.0 + np.abs(g0))
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -a0 / g1
    lo = np.max(np.where(~flat & (g1 > 0), bound, -np.inf), axis=1)
    hi = np.min(np.where(~flat & (g1 < 0), bound, np.inf), axis=1)
    bad = np.any(flat & (a0 < 0), axis=1)
    return ~bad & (lo <= hi + _PRECHECK_RTOL * (1.0 + np.abs(lo) + np.abs(hi)))


def _zonotope_bounds(ctx: _Ctx, sw: _Sweep, D, cap: float):
    """``(feasible, s_hi)``, (K_fixed, N) each: the LP of the ``fixed`` states, per direction.

    With ``r = 0`` the state's stable wrenches ``s d`` form the zonotope ``V = -(h + w0)
    + sum_i [-mu_i p_i, mu_i p_i] Gt_i`` over its rolling, persisting contacts, and the
    LP is a ray cast: ``s (a . d) <= h_V(a)`` for every unit ``a``, ``h_V`` the support
    function. Unit cross products of the contacts' ``Gt`` pairs (and the axes) hold the
    facet normals, so ``s_hi`` is the LP's value up to round-off (``1e-13`` slack, never
    below it) where the LP is feasible; ``feasible`` is False only with
    ``_PRECHECK_RTOL`` slack (the LP has no solution). Rows: the states ``sw.fixed`` selects.
    """
    Gt = ctx.Gt
    m = len(Gt)
    i, j = np.triu_indices(m, 1)
    A = np.concatenate([np.cross(Gt[i], Gt[j]), np.eye(3)])
    A = A[np.linalg.norm(A, axis=1) > 1e-12]
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    A = np.concatenate([A, -A])  # (F, 3)
    S, P = sw.mS[sw.fixed], sw.mP[sw.fixed]
    rho = np.where((S == 0) & P, ctx.mu * ctx.p, 0.0)  # (K, m) half-widths
    c0 = -(sw.mh[sw.fixed] + ctx.w0)
    H = c0 @ A.T + rho @ np.abs(A @ Gt.T).T  # (K, F) support function
    size = np.abs(c0).max(axis=1) + rho @ np.linalg.norm(Gt, axis=1)
    AD = A @ D.T  # (F, N)
    tau = 1e-9 * np.abs(D).max(axis=1)
    up, down = AD > tau, AD < -tau
    with np.errstate(divide="ignore", invalid="ignore"):
        tight = (H + 1e-13 * (1.0 + size)[:, None])[:, :, None] / AD
        loose = (H + _PRECHECK_RTOL * (1.0 + size)[:, None])[:, :, None] / AD
    s_hi = np.minimum(cap, np.min(np.where(up, tight, np.inf), axis=1))
    s_out = np.minimum(cap, np.min(np.where(up, loose, np.inf), axis=1))
    s_in = np.maximum(0.0, np.max(np.where(down, loose, -np.inf), axis=1))
    flat_bad = np.any(
        ~up & ~down & (H + _PRECHECK_RTOL * (1.0 + size)[:, None] < 0)[:, :, None], axis=1
    )
    return ~flat_bad & (s_in <= s_out), s_hi


def _singular_bounds(ctx: _Ctx, sw: _Sweep, D, cap: float):
    """The range test of :func:`_batch` for every singular state and direction.

    Returns ``(solvable, s_ub, pinned)``, (K_rest, N) each: the LP is needed,
    its bound on ``s``, and whether equilibrium pins ``s`` (rank 2, the right-hand
    side's component off the range grows with ``s``) so that :func:`_precheck` applies.
    """
    rhs0 = -(sw.rh + ctx.w0)
    e0 = np.einsum("kai,ka->ki", sw.U_perp, rhs0)  # (Kr, 3)
    e1 = -np.einsum("kai,ja->kji", sw.U_perp, D)  # (Kr, N, 3)
    d_max = np.abs(D).max(axis=1)
    solvable, s_ub = _singular_screen(
        e0[:, None, :], e1, np.abs(rhs0).max(axis=1)[:, None], d_max[None, :], cap
    )
    pinned = sw.rank2[:, None] & (np.abs(e1[:, :, 2]) >= _PIN_RTOL * d_max[None, :])
    return solvable, s_ub, pinned


def _sweep_lp(ctx, sw: _Sweep, D, cap: float, found, best) -> int:
    """The LP states of :func:`_max_disturbance`, per direction, in place on ``found``,
    ``best``: only those whose bound beats the best so far and that pass the precheck
    reach :func:`_lp_state`. Returns the number of LPs solved."""
    nd = len(D)
    pending: list[list[tuple[float, NDArray[np.int8], NDArray[np.bool_]]]] = [[] for _ in range(nd)]
    margin = best + 1e-12 * (1.0 + best)
    if len(sw.rS):
        solvable, s_ub, pin = _singular_bounds(ctx, sw, D, cap)
        k, j = np.nonzero(solvable & (s_ub > margin[None, :]))
        if len(k):
            pinned = pin[k, j]
            maybe = np.ones(len(k), dtype=bool)
            maybe[pinned] = _precheck(ctx, sw, k[pinned], s_ub[k[pinned], j[pinned]], D[j[pinned]])
            for kk, jj in zip(k[maybe], j[maybe], strict=True):
                pending[jj].append((float(s_ub[kk, jj]), sw.rS[kk], sw.rP[kk]))
    if len(sw.mS):
        may = np.repeat((cap > margin)[None, :], len(sw.mS), axis=0)
        if sw.fixed.any():
            feasible, s_hi = _zonotope_bounds(ctx, sw, D, cap)
            may[sw.fixed] = feasible & (s_hi > margin[None, :])
        for kk, jj in zip(*np.nonzero(may), strict=True):
            pending[jj].append((cap, sw.mS[kk], sw.mP[kk]))
    n_lp = 0
    for jj in range(nd):
        if not pending[jj]:
            continue
        cj = replace(ctx, d=D[jj])
        b = best[jj]
        for ub, S_k, P_k in sorted(pending[jj], key=lambda x: -x[0]):
            if ub <= b + 1e-12 * (1.0 + b):
                break
            n_lp += 1
            res = _lp_state(cj, S_k, P_k, (0.0, min(ub, cap)), sense=1)
            if res is not None and res[2] > b and _certified(cj, S_k, P_k, *res):
                b = res[2]
                found[jj] = True
        best[jj] = b
    return n_lp


def max_disturbance_map(
    grasp: Grasp,
    directions: ArrayLike,
    preload: float | ArrayLike | None = None,
    commands: ArrayLike | None = None,
    cap: float = 1e3,
    base: ArrayLike | None = None,
    **options: Any,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """``MaxDisturbance`` of the planar method for many directions at once.

    For each row ``d`` of ``directions`` ((N, 3) wrenches ``(fx, fy, tz)`` [N, N m]
    applied to the object about its frame's origin, any non-zero length) the largest
    ``s`` in ``[0, cap]`` such that ``w = base + s d`` is stable: the same answer as
    ``solve(grasp, MaxDisturbance(direction=d, preload=preload, commands=commands,
    cap=cap, base=base), method="planar")``. The contact states are enumerated and
    factorised once (cached on the grasp per preload, as for ``solve``) and every
    nonsingular state's interval of ``s`` is evaluated for all directions together
    (numpy); the LP states are screened for all directions (range test, a precheck
    where equilibrium pins ``s``, a zonotope ray cast where rolling contacts hold the
    object still) and HiGHS gets only what these cannot settle, direction by direction.

    Returns ``(values, capped, stable)``, each (N,): ``values`` the largest stable
    ``s`` (in units of ``d``: N when ``d`` is a unit force), 0 where no ``s`` is stable;
    ``capped`` True where the value reached ``cap`` (resists *at least* ``cap``);
    ``stable`` False where no ``s`` in ``[0, cap]`` is stable. ``preload`` [N] is a
    scalar or one value per contact. The planar method models a rigid hand:
    ``commands`` must be None (:class:`MethodError` otherwise, as from ``solve``).
    ``options``: those of the planar method (``chunk``).
    """
    _require_planar(grasp)
    try:
        dirs = np.asarray(directions, dtype=float)
    except (TypeError, ValueError):
        dirs = None
    if dirs is None or dirs.ndim != 2 or dirs.shape[1] != grasp.wrench_dim:
        shape = None if dirs is None else dirs.shape
        raise GraspError(
            f"directions must be an (N, {grasp.wrench_dim}) array of wrenches, got "
            f"{shape if shape is not None else type(directions).__name__}"
        )
    if not np.all(np.isfinite(dirs)):
        raise GraspError("directions must be finite")
    zero = np.flatnonzero(~np.any(dirs != 0.0, axis=1))
    if len(zero):
        raise GraspError(f"MaxDisturbance direction must be non-zero (rows {zero.tolist()})")
    probe = dirs[0] if len(dirs) else np.eye(grasp.wrench_dim)[0]
    query = MaxDisturbance(probe, preload=preload, commands=commands, cap=cap, base=base)
    reason = _METHODS["planar"].refuses(grasp, query)
    if reason is not None:
        raise MethodError(f"method 'planar' {reason}")
    chunk = _options(dict(options))
    _, cap_f = checked_direction_cap(grasp, query)
    w0 = checked_base(grasp, query)
    p = _preload(grasp, preload)
    L, unit = _unit_grasp(grasp)
    scale = np.array([1.0, 1.0, 1.0 / L])
    D = dirs * scale
    ctx = _Ctx.make(unit, p, w0 * scale, np.zeros(3))
    sw = _sweep_states(unit, ctx, p, chunk)
    found, best = _sweep_square(ctx, sw, D, cap_f)
    _sweep_lp(ctx, sw, D, cap_f, found, best)
    values = np.where(found, np.minimum(best, cap_f), 0.0)
    capped = found & (values >= cap_f * (1 - 1e-12))
    return values, capped, found


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
