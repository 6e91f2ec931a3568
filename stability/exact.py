"""``method="exact"``: the exact nonconvex problem solved globally by SCIP's spatial
branch-and-bound (the thesis' "future work" alternative to ch. 6; our accuracy reference).
Formerly ``method="spatial"``, which still works and warns (``DeprecationWarning``).

The exact model of ch. 5 (:class:`~stability.model.problem.ExactProblem`: unilateral springs with
preload, nonbackdrivable actuators, object and hand equilibrium, the binaries ``y`` and
``z``) with Coulomb friction and maximum dissipation stated *exactly* per contact ``i``,
with no linearisation of the cone::

    |c_t|^2 <= mu^2 c_n^2                  (the circular cone; a second-order cone)
    |d_t|^2 <= s_i^2,  s_i >= 0            (s_i bounds the tangential slide)
    c_t . d_t + mu c_n s_i <= 0            (maximum dissipation; bilinear)

with ``d_t = G_t^T r - J_t q`` the tangential motion of the object at the contact. Since
``c_t . d_t >= -|c_t| |d_t| >= -mu c_n |d_t| >= -mu c_n s_i``, the last row holds only with
equality throughout: either ``c_n = 0`` (an open or unloaded contact, no friction), or
``d_t = 0 = s_i`` (sticking, ``c_t`` anywhere in the cone), or ``|d_t| = s_i > 0``,
``|c_t| = mu c_n`` and ``c_t`` opposite to ``d_t`` (sliding with maximum dissipation: thesis
eq. mdp). SCIP handles the cones as convex and the bilinear row by spatial branching on
``c_t, d_t, c_n, s`` with McCormick envelopes, so every variable there needs finite
bounds: forces from :func:`~stability.model.problem.scale_bounds` (``|c_t| <= mu B``), tangential
motions ``|d_t| <= motion_bound * 2 B`` (the same box as ``refinement``'s edge weights),
translations within that, rotations within it over the grasp's size ``L`` and joint
motions within it over their lever; an answer at the box is flagged ``stats["at_bound"]``.

Queries: ``Existence``, ``MaxDisturbance`` (maximise ``s``), ``OptimalCommands`` (the
objectives and limits of ``refinement``), all in one solve. Options: ``time_limit`` (a
time-out returns ``status="timeout"`` with SCIP's incumbent and dual bound in
``stats["incumbent"]``/``stats["dual_bound"]``), ``gap`` (relative optimality gap at which
SCIP stops, default 1e-4), ``bound_factor``, ``verbose``, ``normal_uncertainty`` (eta: the
spring law uses ``d_n cos eta + s_i sin eta``, the worst normal within eta, as
``refinement`` does), ``motion_bound``, ``feastol`` (SCIP's feasibility tolerance, default
its own 1e-6; 1e-9 made SoPlex ask for 1e-12). Backend: SCIP only (HiGHS has no nonlinear
rows).

SCIP's point is then polished (:func:`stability.model.coulomb.polish`): with the binaries and
each contact's mode fixed (sliding along ``u``, sticking, open) the exact problem is an LP,
whose least-motion optimum replaces SCIP's point when it is no worse than the gap
(``stats["polished"]``: ``"motion"``/``"force"``, where the slide direction came from, or
False). Every answer is checked against the exact conditions (the linear model's, the
cone and maximum dissipation) before it is returned: force conditions within
``1e-6 (1 + B)``, dissipation within that times the motion's scale; anything worse is
``status="error"``, never a silent wrong answer. This is global optimisation: exact up
to SCIP's tolerances and the gap, and its time grows quickly with the number of contacts
(``python -m stability.bench tradeoff``; docs/bench/stability.md).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import register
from .errors import GraspError, MethodError
from .grasp import Grasp
from .mip import MipResult, optimize_scip
from .model.coulomb import CoulombModel, exact_conditions, polish
from .model.problem import scale_bounds
from .model.query import QueryData, add_query, query_value
from .model.run import MipOptions, Stop, bounds_stats, solution, stopped
from .queries import Existence, MaxDisturbance, OptimalCommands
from .solution import Solution

__all__: list[str] = []

_EXACT_OPTIONS = ("normal_uncertainty", "motion_bound", "feastol", "gap")


@register(
    "exact",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    hand=True,
    summary="exact nonconvex problem (circular cone, bilinear maximum dissipation) solved "
    "globally by SCIP's spatial branch-and-bound: the accuracy reference for small grasps",
)
def _solve_exact(grasp: Grasp, query: Any, **options: Any) -> Solution:
    got = {k: options.pop(k) for k in list(options) if k in _EXACT_OPTIONS}
    eta = float(got.get("normal_uncertainty", 0.0))
    if not (math.isfinite(eta) and 0.0 <= eta < math.pi / 2):
        raise GraspError(f"normal_uncertainty must be in [0, pi/2) rad, got {eta!r}")
    motion_bound = float(got.get("motion_bound", 4.0))
    if not (math.isfinite(motion_bound) and motion_bound >= 1.0):
        raise GraspError(f"motion_bound must be a finite number >= 1, got {motion_bound!r}")
    feastol = float(got.get("feastol", 1e-6))
    if not (math.isfinite(feastol) and 0.0 < feastol <= 1e-3):
        raise GraspError(f"feastol must be in (0, 1e-3], got {feastol!r}")
    gap = float(got.get("gap", 1e-4))
    if not (math.isfinite(gap) and 0.0 <= gap < 0.5):
        raise GraspError(f"gap must be in [0, 0.5), got {gap!r}")
    if options.get("backend") not in (None, "scip"):
        raise MethodError(
            f"method 'exact' needs SCIP's spatial branch-and-bound (backend='scip'), got "
            f"backend={options['backend']!r}: HiGHS has no nonlinear constraints"
        )
    options["backend"] = "scip"
    opts = MipOptions.of("exact", options)
    if grasp.planar:
        raise GraspError("method 'exact' takes spatial grasps; use 'planar' for planar ones")
    data = QueryData.of(grasp, query, opts.bound_factor)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"backend": "scip", "normal_uncertainty": eta, "feastol": feastol,
                             "gap": gap}  # fmt: skip
    bounds_stats(bounds, stats)
    conditions = exact_conditions(eta)
    t0 = time.perf_counter()
    ex = CoulombModel(grasp, data, bounds, eta, motion_bound)
    var = add_query(ex.prob, data)
    try:
        res = _run(ex, opts, feastol, gap, stats)
    except Stop as e:
        return _bracket(stopped("exact", grasp, query, stats, e), data, stats.get("incumbent"))
    finally:
        stats["solve_time_s"] = time.perf_counter() - t0
    if res is None:
        if data.direction is not None:
            stats["capped"] = False
        return solution("exact", grasp, query, False, stats, conditions=conditions)
    pt = ex.prob.point(res)
    M = ex.prob.model
    motion = np.r_[ex.dt.reshape(-1), ex.prob.r, [] if ex.prob.q is None else ex.prob.q]
    box = np.array([M.ub[int(j)] for j in motion])
    pt.at_bound = pt.at_bound or bool(np.any(np.abs(res[motion.astype(int)]) >= 0.99 * box))
    value = query_value(ex, pt, var, data)
    if data.direction is not None:
        stats["capped"] = value >= data.cap * (1 - 1e-8)
    sol = solution("exact", grasp, query, True, stats, ex.prob, pt, value,
                   conditions=conditions)  # fmt: skip
    if data.command_range is not None:
        sol.commands = pt.x[ex.prob.fc]
    return _bracket(sol, data, value)


def _bracket(sol: Solution, data: Any, value: float | None) -> Solution:
    """``sol.lower``/``sol.upper`` of an optimisation query: the value of SCIP's (polished)
    exact point on the feasible side, its dual bound on the other (MaxDisturbance: at most
    the cap); ``stats["certified"]`` when they meet within the relative ``gap`` asked."""
    bound = sol.stats.get("dual_bound")
    if bound is not None and not math.isfinite(bound):
        bound = None
    if data.direction is not None:
        hi = None if bound is None else min(float(bound), data.cap)
        if hi is not None and value is not None:
            hi = max(hi, value)
        sol.lower, sol.upper = value, hi
    elif data.command_range is not None:
        lo = None if bound is None else float(bound)
        if lo is not None and value is not None:
            lo = min(lo, value)
        sol.lower, sol.upper = lo, value
    else:
        return sol
    if sol.lower is not None and sol.upper is not None:
        width = sol.upper - sol.lower
        sol.stats["certified"] = width <= sol.stats["gap"] * max(abs(sol.upper), 1e-12) + 1e-9
    return sol


def _run(ex: CoulombModel, opts: MipOptions, feastol: float, gap: float,
         stats: dict[str, Any]) -> NDArray[np.float64] | None:  # fmt: skip
    """Solve; the point (None: infeasible), :class:`Stop` on a time-out or an error."""
    t0 = time.perf_counter()
    try:
        m, x = ex.scip_model(opts.time_limit, opts.verbose, feastol, gap)
        m.setParam("limits/absgap", 1e-9)  # gap is relative: small answers need it so
        raw = optimize_scip(m, x, ex.prob.model, t0)
    except Exception as e:  # noqa: BLE001  (a solver's internal failure is a status)
        raise Stop("error", f"scip failed: {type(e).__name__}: {e}") from None
    res = MipResult(raw["status"], "scip", raw["x"], raw["objective"], raw["bound"],
                    raw["time_s"], raw["nodes"], raw["message"])  # fmt: skip
    stats["mips"] = 1
    stats["mip_time_s"] = res.time_s
    stats["nodes"] = res.nodes
    stats["dual_bound"] = res.bound
    if res.status in ("infeasible", "infeasible_or_unbounded"):
        return None
    if res.status == "timeout":
        stats["incumbent"] = res.objective
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached ({res.message}; "
                   f"incumbent {res.objective}, dual bound {res.bound})")  # fmt: skip
    if res.status == "optimal" and res.x is not None:
        x = polish(ex, res.x, gap, stats)
        viol = ex.violations(x)
        stats["violations"] = viol
        # force conditions within 1e-6 of the force bound; dissipation (force x motion)
        # within that times the motion's scale
        B = ex.prob.bounds.force
        dmax = 1.0 + float(np.abs(x[ex.dt]).max(initial=0.0))
        lim = {k: 1e-6 * (1.0 + B) * (dmax if k == "dissipation" else 1.0) for k in viol}
        bad = {k: v for k, v in viol.items() if v > lim[k]}
        if bad:
            raise Stop("error", f"SCIP's answer fails the exact conditions {bad}")
        return x
    raise Stop("error", f"scip: {res.status}: {res.message}")
