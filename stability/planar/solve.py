"""``method="planar"``: ``Existence`` and ``MaxDisturbance`` on a planar grasp, by visiting
the co-occurring contact states (:mod:`~stability.planar.enumeration`) and solving each
state's system (:mod:`~stability.planar.system`) until one admits a certified solution
(Existence) or none can beat the best ``s`` (MaxDisturbance: ``w = base + s d``, the
largest stable ``s`` in ``[0, cap]``). Option: ``chunk`` (states per batch, default 8192).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..api import register
from ..grasp import Grasp
from ..options import Deadline, MethodOptions, check_ranges
from ..queries import Existence, MaxDisturbance, checked_base, checked_direction_cap
from ..solution import Solution
from .enumeration import preload_vector
from .system import (
    Context,
    batch_solutions,
    certified,
    contact_forces,
    intervals,
    lp_state,
    prepared_states,
    state_names,
)

__all__ = ["PlanarOptions", "unit_grasp"]


def _solution(
    grasp: Grasp,
    query: Existence | MaxDisturbance,
    ctx: Context,
    state: tuple[NDArray[np.int8], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]],
    value: float | None,
    stats: dict[str, Any],
) -> Solution:
    """The stable answer of a certified contact state ``state = (S, P, r, c_t)``: its slip
    signs ``S`` (0: rolling) and persisting contacts ``P`` (:mod:`~stability.planar.system`),
    the object motion ``r`` and the rolling contacts' tangential forces ``c_t``, from which
    the contact forces follow; ``value`` the largest stable ``s`` (MaxDisturbance) or None
    (Existence)."""
    S, P, r, ct = state
    c = contact_forces(ctx, S[None], P[None], r[None], ct[None])[0]
    return Solution(
        stable=True,
        method="planar",
        grasp=grasp,
        query=query,
        forces=c,
        motion=r,
        value=value,
        states=state_names(S, P),
        stats=stats,
    )


@dataclass(frozen=True)
class PlanarOptions(MethodOptions):
    """Options of ``method="planar"``: ``chunk``, the states enumerated per batch (memory
    against vectorisation; the answer does not depend on it)."""

    chunk: int = 8192

    def check(self) -> None:
        check_ranges(self, {"chunk": (self.chunk >= 1, "a positive integer")})


@register(
    "planar",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=False,
    options=PlanarOptions,
    summary="thesis ch. 4: exact, polynomial-time enumeration of co-occurring states",
)
def _solve_planar(grasp: Grasp, query: Existence | MaxDisturbance, opts: PlanarOptions,
                  deadline: Deadline) -> Solution:  # fmt: skip
    chunk = opts.chunk
    p = preload_vector(grasp, query.preload)
    # Work in units where the grasp has size 1: the model is invariant under
    # points -> points / L with torques / L and rotations * L, and tolerances
    # are then dimensionally consistent (unit springs: force ~ length).
    L, unit = unit_grasp(grasp)
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


def unit_grasp(grasp: Grasp) -> tuple[float, Grasp]:
    """``(L, grasp with points / L)``, ``L`` the largest contact distance from the origin."""
    cached = grasp.__dict__.get("_planar_unit")
    if cached is None:
        L = float(np.abs(grasp.points).max())
        L = L if L > 0 else 1.0
        cached = (L, Grasp(grasp.points / L, grasp.normals, grasp.mu))
        grasp.__dict__["_planar_unit"] = cached
    return cached


def _existence(grasp, query, p, w, chunk) -> Solution:
    ctx = Context.make(grasp, p, w, np.zeros(3))
    n_states = n_lp = n_rejected = 0
    for pr in prepared_states(grasp, ctx, p, chunk):
        S, P = pr.S, pr.P
        n_states += len(S)
        r0, r1, ct0, ct1, lp, skip, _ = batch_solutions(ctx, pr)
        ok, _ = intervals(ctx, S, P, r0, r1, ct0, ct1, 0.0, ~lp & ~skip)
        for k in np.flatnonzero(ok):
            if certified(ctx, S[k], P[k], r0[k], ct0[k], 0.0):
                stats = {"states": n_states, "lps": n_lp}
                return _solution(grasp, query, ctx, (S[k], P[k], r0[k], ct0[k]), None, stats)
            n_rejected += 1
        for k in np.flatnonzero(lp):
            n_lp += 1
            res = lp_state(ctx, S[k], P[k], (0.0, 0.0), sense=0)
            if res is not None and certified(ctx, S[k], P[k], res[0], res[1], 0.0):
                r, ct, _ = res
                stats = {"states": n_states, "lps": n_lp}
                return _solution(grasp, query, ctx, (S[k], P[k], r, ct), None, stats)
    return Solution(
        stable=False,
        method="planar",
        grasp=grasp,
        query=query,
        stats={"states": n_states, "lps": n_lp, "rejected": n_rejected},
    )


def _max_disturbance(grasp, query, p, d, cap, chunk, base=None) -> Solution:
    ctx = Context.make(grasp, p, np.zeros(3) if base is None else base, d)
    pending: list[tuple[float, NDArray[np.int8], NDArray[np.bool_]]] = []
    best: tuple[float, Any] = (-1.0, None)
    n_states = n_lp = n_rejected = 0
    for pr in prepared_states(grasp, ctx, p, chunk):
        S, P = pr.S, pr.P
        n_states += len(S)
        r0, r1, ct0, ct1, lp, skip, s_ub = batch_solutions(ctx, pr, cap)
        feas, hi = intervals(ctx, S, P, r0, r1, ct0, ct1, cap, ~lp & ~skip)
        cand = np.flatnonzero(feas & (hi > best[0]))
        for k in cand[np.argsort(-hi[cand])]:  # best first; the first certified one wins
            s = hi[k]
            r, ct = r0[k] + s * r1[k], ct0[k] + s * ct1[k]
            if certified(ctx, S[k], P[k], r, ct, s):
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
        res = lp_state(ctx, S_k, P_k, (0.0, min(ub, cap)), sense=1)
        if res is not None and res[2] > best[0] and certified(ctx, S_k, P_k, *res):
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
    return _solution(grasp, query, ctx, best[1], value, stats)
