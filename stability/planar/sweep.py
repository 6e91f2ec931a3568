"""Direction sweeps: ``MaxDisturbance`` of the planar method for many directions at once
(:func:`max_disturbance_map`, the resistible-force maps of :mod:`stability.maps`), the
same answers as one ``solve`` per direction from the same states, vectorised over
(state, direction) pairs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..api import method_info
from ..errors import GraspError, MethodError
from ..grasp import Grasp
from ..queries import MaxDisturbance, checked_base, checked_direction_cap
from .enumeration import preload_vector, require_planar
from .solve import PlanarOptions, unit_grasp
from .system import (
    CACHE_PRELOADS,
    Context,
    Prepared,
    certified,
    contact_forces,
    intervals,
    lp_state,
    prepared_states,
    singular_screen,
)

__all__ = ["max_disturbance_map"]

_SWEEP_ROWS = 32_768  # (state, direction) rows per vectorised block
_PRECHECK_RTOL = 1e-6  # margin of the LP precheck, relative to the forces and motions involved
_PIN_RTOL = 1e-3  # s counts as pinned by equilibrium when |e1| >= this * |d|


@dataclass
class _Sweep:
    """The distinct states of ``(grasp, preload)``, split for direction sweeps.

    ``S, P, B, C, h, inv``: states with a nonsingular system, whose solution is affine
    in ``s`` for every direction (as in :class:`Prepared`, with ``c_t = C z``); ``r*`` and
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


def _friction_selector(pr: Prepared, m: int) -> NDArray[np.float64]:
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


def _sweep_states(grasp: Grasp, ctx: Context, p: NDArray[np.float64], chunk: int) -> _Sweep:
    """:class:`_Sweep` of ``(grasp, preload)``, cached on the grasp next to
    :func:`~stability.planar.system.prepared_states`."""
    cache: dict[bytes, _Sweep] = grasp.__dict__.setdefault("_planar_sweep", {})
    key = p.tobytes()
    if key in cache:
        return cache[key]
    m = grasp.m
    parts: dict[str, list[NDArray[Any]]] = {k: [] for k in (*_Sweep.__dataclass_fields__, "M")}
    for pr in prepared_states(grasp, ctx, p, chunk):
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
    if len(cache) >= CACHE_PRELOADS:
        cache.pop(next(iter(cache)))
    cache[key] = sweep
    return sweep


def _certified_rows(ctx: Context, S, P, r, ct, s, d, rtol: float = 1e-7) -> NDArray[np.bool_]:
    """:func:`certified` for many candidates at once: rows of states, motions, friction,
    ``s`` and directions ``d`` (wrench ``w0 + s d``); the same residuals and tolerances."""
    n, m = S.shape
    c = contact_forces(ctx, S, P, r, ct)
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


def _sweep_square(ctx: Context, sw: _Sweep, D: NDArray[np.float64], cap: float):
    """Best certified ``s`` per direction over the square states: ``(found, best)``.

    All (state, direction) pairs go through :func:`intervals` at once; per direction
    the candidates are certified best first, as in ``solve``'s MaxDisturbance
    (:mod:`stability.planar.solve`).
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
        feas, hi = intervals(ctx, S, P, R0, r1, CT0, ct1, cap, np.ones(K * nb, bool), d_rows)
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


def _precheck(ctx: Context, sw: _Sweep, k, s, d) -> NDArray[np.bool_]:
    """Whether the LP of rank-2 singular state ``k`` may have a solution at the ``s`` that
    equilibrium pins, per pair (``k``, ``s``, ``d`` rows).

    At that ``s`` the solutions of the state's system form a line ``z = z_p + t n``;
    every condition of :func:`intervals` is affine in ``t``. False only when no ``t``
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


def _zonotope_bounds(ctx: Context, sw: _Sweep, D, cap: float):
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


def _singular_bounds(ctx: Context, sw: _Sweep, D, cap: float):
    """The range test of :func:`batch_solutions` for every singular state and direction.

    Returns ``(solvable, s_ub, pinned)``, (K_rest, N) each: the LP is needed,
    its bound on ``s``, and whether equilibrium pins ``s`` (rank 2, the right-hand
    side's component off the range grows with ``s``) so that :func:`_precheck` applies.
    """
    rhs0 = -(sw.rh + ctx.w0)
    e0 = np.einsum("kai,ka->ki", sw.U_perp, rhs0)  # (Kr, 3)
    e1 = -np.einsum("kai,ja->kji", sw.U_perp, D)  # (Kr, N, 3)
    d_max = np.abs(D).max(axis=1)
    solvable, s_ub = singular_screen(
        e0[:, None, :], e1, np.abs(rhs0).max(axis=1)[:, None], d_max[None, :], cap
    )
    pinned = sw.rank2[:, None] & (np.abs(e1[:, :, 2]) >= _PIN_RTOL * d_max[None, :])
    return solvable, s_ub, pinned


def _sweep_lp(ctx, sw: _Sweep, D, cap: float, found, best) -> int:
    """The LP states of ``solve``'s MaxDisturbance, per direction, in place on ``found``,
    ``best``: only those whose bound beats the best so far and that pass the precheck
    reach :func:`lp_state`. Returns the number of LPs solved."""
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
            res = lp_state(cj, S_k, P_k, (0.0, min(ub, cap)), sense=1)
            if res is not None and res[2] > b and certified(cj, S_k, P_k, *res):
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
    require_planar(grasp)
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
    reason = method_info("planar").refuses(grasp, query)
    if reason is not None:
        raise MethodError(f"method 'planar' {reason}")
    chunk = PlanarOptions.of("planar", dict(options)).chunk
    _, cap_f = checked_direction_cap(grasp, query)
    w0 = checked_base(grasp, query)
    p = preload_vector(grasp, preload)
    L, unit = unit_grasp(grasp)
    scale = np.array([1.0, 1.0, 1.0 / L])
    D = dirs * scale
    ctx = Context.make(unit, p, w0 * scale, np.zeros(3))
    sw = _sweep_states(unit, ctx, p, chunk)
    found, best = _sweep_square(ctx, sw, D, cap_f)
    _sweep_lp(ctx, sw, D, cap_f, found, best)
    values = np.where(found, np.minimum(best, cap_f), 0.0)
    capped = found & (values >= cap_f * (1 - 1e-12))
    return values, capped, found
