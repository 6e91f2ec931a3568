"""``method="modesearch"``: Coulomb friction with maximum dissipation by one branch-and-bound
tree over contact modes and slide arcs, one LP per node (the thesis' ch. 6 Discussion and
ch. 8: "make the refinement part of the branch and bound itself").

The model is the exact one of ch. 5 (:class:`~stability.model.coulomb.CoulombModel`:
unilateral springs with preload, nonbackdrivable actuators, equilibrium, tangential motions
``d_t``), with its on/off conditions and its friction law relaxed per node:

* per contact a **normal state**: undecided, closed (``u = 0``: ``c_n = p - d_n``) or open
  (``c_n = 0``); undecided keeps the convex hull of ``c_n u = 0`` in the box,
  ``c_n + u <= B``;
* per nonbackdrivable actuator: undecided, locked (``v = 0``) or moving (``f = f_c``);
  undecided keeps the hull ``(f - f_c) / E + v / V <= 1``;
* per contact a **tangential state**: undecided; sticking (``d_t = 0``) with friction in an
  arc ``[a, a + w]`` of directions; or sliding within an arc: friction ``c_t`` and the
  negative slide ``-d_t`` both in the arc's cone (``n_a . c_t >= 0``, ``n_b . c_t >= 0`` with
  the arc's inward normals, the same for ``-d_t``) and ``|c_t| = mu c_n`` relaxed to
  the chord, ``m . c_t >= mu c_n cos(w / 2)`` (``m`` the arc's mid direction). Friction is
  always within the outer octagon of the cone, and in an arc also within the tangents at
  its ends and middle (``e . c_t <= mu c_n``).

Every exact solution lies in some child of every node (the states split a closed set into
closed pieces that cover it: ``C``/``O``, locked/moving, stick / two half-circle slide arcs,
an arc into two), so the LP optimum of a node bounds every exact point in it: **the largest
bound over the open, unresolved and pruned nodes is a proven bound** on the query's optimum.
Branching takes the most violated complementarity, normal and actuator ones first, then
the largest misalignment of friction against the slide (or friction outside the cone),
and splits an arc between the friction's and the slide's angles; nodes are taken
best-first, deeper first on ties.

Contacts at one point (the same columns of ``G`` and rows of ``J``: a piecewise-linear
contact law's steps) share ``d_n`` and ``d_t``, so a branch on one decides
the others where that loses no exact point: closing contact ``i`` (``d_n <= p_i / k_i``)
closes every one that closes at a larger ``d_n``, opening it opens every one that closes
at a smaller one; a tangential split of an undecided contact gives the undecided ones at
its point the same state (all stick, or all slide in the same half-circle: a closed one
slides against ``-d_t``, an open one carries no friction), and halving a slide arc halves
theirs in that arc. Points with ``d_t = 0`` and friction in different halves of a slide arc
are left out of that arc's children, but every one lies in the sibling where all stick.

Exact points come from polishing only (:func:`stability.model.slides.slide_search`, the
certificate of ``refinement``): a node's modes and slide directions are fixed and the slide
angles optimised by sequential LP; the point must pass the exact conditions. A leaf whose LP
point satisfies every complementarity (within ``1e-7 (1 + B)``) is polished; so is a dive
every :data:`DIVE_EVERY` nodes. A leaf with an arc narrower than ``min_width`` whose polish
falls short keeps its bound as "unresolved".

Round-off: a node's bound is not HiGHS's objective but a safe dual bound (Neumaier and
Shcherbina, Math. Program. 99, 2004) from its duals: for any multipliers ``y`` of the rows
``L <= A x <= U`` and the box ``l <= x <= u``, ``c.x <= sum_i max(y_i L_i, y_i U_i) +
sum_j max(z_j l_j, z_j u_j)`` with ``z = c - A^T y``; every variable has finite bounds (the
motion box below), so the bound is finite, and it holds whatever the LP's tolerances. A
node proven infeasible by HiGHS is pruned only when its dual ray certifies it the same way;
otherwise it is solved again at tight tolerances, and kept with its parent's bound if it
still cannot be certified.

The box (``bound_factor``, default :data:`MODESEARCH_BOUND_FACTOR` times the query's force
scale): forces and separations ``B``, transmission motions ``V``, excess actuator forces
``E`` (:func:`~stability.model.problem.scale_bounds`) and the motions ``r``, ``q``, ``d_t``
(``motion_bound * 2 B / min k``, as ``exact``). The bound holds for exact points inside it; an
exact point beyond the bound, or one at the box, grows it tenfold and the query is solved
again, at most :data:`~stability.options.BOX_RETRIES` times
(:func:`~stability.options.enlarge_box`). An answer at the box has no proven bound
(``upper``/``lower`` None, ``stats["box_reached"]``). The enlargements stop early when the
larger box moved the exact value by no more than the bracket's tolerance (a grasp whose best
value is approached only as a slide grows without limit, a mechanism: its value converges
as the box grows), and a search in a larger box that takes more than
:data:`RETRY_NODE_FACTOR` times the nodes of the one before it (plus
:data:`RETRY_NODE_SLACK`), or runs out of time, is dropped for the answer of the smaller box:
its LPs mix motions of ``1e7`` with forces of 1 and stop resolving them.

Status semantics are ``refinement``'s: ``"solved"`` only with an exact point that passes
:meth:`Solution.residuals`; ``lower``/``upper`` the bracket, the feasible side an exact
point's value and the other a proven bound; ``stats["certified"]`` when they meet within
``gap`` relative or ``abs_gap`` times the force scale absolute; a time-out returns the
bracket reached. ``Existence`` is "stable" only with an exact point and "unstable" only
when the tree is exhausted. A ``MaxDisturbance`` answer is ``stats["capped"]`` when its
exact point reaches the cap, or when the bracket is certified and its proven bound is the
cap (the point then lies within ``gap`` of it).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..api import register
from ..errors import GraspError
from ..grasp import Grasp
from ..model.coulomb import CoulombModel, exact_conditions
from ..model.problem import ExactBounds, length_scale, scale_bounds
from ..model.query import QueryData, add_query, query_value
from ..model.run import bounds_stats, solution
from ..options import BOX_RETRIES, Deadline, MethodOptions, check_ranges, enlarge_box, finite
from ..queries import Existence, MaxDisturbance, OptimalCommands
from ..solution import Solution
from .node import NodeLP
from .search import Search

__all__ = ["MODESEARCH_BOUND_FACTOR", "ModeSearchOptions"]

MODESEARCH_BOUND_FACTOR = 1e3  # the default box, times the query's force scale
RETRY_NODE_FACTOR = 5  # a larger box's search may take this many times the nodes before it
RETRY_NODE_SLACK = 1000  # ... plus these


@dataclass(frozen=True)
class ModeSearchOptions(MethodOptions):
    """Options of ``method="modesearch"``.

    ``time_limit`` [s] (None: none); ``gap``: relative width at which a bracket is closed
    (default 1e-4); ``abs_gap``: absolute width, as a fraction of the query's force scale
    (:func:`~stability.model.problem.scale_bounds`'s ``S``, in the value's units: divided
    by the direction's force for MaxDisturbance), default 1e-6, so that a value near zero
    closes too; ``bound_factor``: the box (module docstring); ``motion_bound``: the motions'
    box per ``2 B`` (as ``exact``); ``min_width`` [rad]: arcs narrower than this are not
    split; ``node_limit``: nodes before the search stops (``status="not_converged"``);
    ``normal_uncertainty``: 0 only (the search has exact normals; ``refinement`` and
    ``exact`` take an uncertainty)."""

    time_limit: float | None = None
    gap: float = 1e-4
    abs_gap: float = 1e-6
    bound_factor: float = MODESEARCH_BOUND_FACTOR
    motion_bound: float = 4.0
    min_width: float = 1e-6
    node_limit: int = 1_000_000
    normal_uncertainty: float = 0.0

    def check(self) -> None:
        super().check()
        if self.normal_uncertainty != 0.0:
            raise GraspError("modesearch has no normal_uncertainty: use method='refinement'")
        check_ranges(self, {
            "gap": (finite(self.gap) and 0.0 <= self.gap < 1.0, "in [0, 1)"),
            "abs_gap": (finite(self.abs_gap) and 0.0 <= self.abs_gap < 1.0, "in [0, 1)"),
            "bound_factor": (finite(self.bound_factor) and self.bound_factor >= 1.0,
                             "a finite number >= 1"),
            "motion_bound": (finite(self.motion_bound) and self.motion_bound >= 1.0,
                             "a finite number >= 1"),
            "min_width": (finite(self.min_width) and 0.0 < self.min_width < 1.0,
                          "in (0, 1) rad"),
            "node_limit": (self.node_limit >= 1, "a positive integer"),
        })  # fmt: skip


def _abs_tol(data: QueryData, bounds: ExactBounds, grasp: Grasp, opts: ModeSearchOptions) -> float:
    """``abs_gap`` in the value's units (ModeSearchOptions)."""
    S = bounds.scale
    if data.direction is not None:
        d = np.asarray(data.direction, dtype=float)
        L = length_scale(grasp)
        force = max(float(np.abs(d[:3]).max()), float(np.abs(d[3:]).max()) / L)
        return opts.abs_gap * S / max(force, 1e-300)
    return opts.abs_gap * S


def _box_reached(ex: CoulombModel, x: NDArray[np.float64]) -> bool:
    """An exact point at 99 % of the box (module docstring, "The box"), or beyond: forces,
    separations, excess actuator forces, transmission motions, object, joint and tangential
    motions."""
    p = ex.prob
    M = p.model
    B = p.bounds.force
    if np.any(x[p.c[:, 0]] >= 0.99 * B) or np.any(x[p.u] >= 0.99 * B):
        return True
    motion = np.r_[ex.dt.reshape(-1), p.r, [] if p.q is None else p.q].astype(int)
    box = np.array([M.ub[j] for j in motion])
    if np.any(np.abs(x[motion]) >= 0.99 * box):
        return True
    if p.hand is not None:
        live = ~p.backdrivable
        fc = p.hand[1] if p.fc is None else x[p.fc]
        if np.any((x[p.f] - fc)[live] >= 0.99 * p.bounds.excess[live]):
            return True
        if np.any(x[p.v][live] >= 0.99 * p.bounds.motion[live]):
            return True
    return False


def _solve_once(grasp: Grasp, query: Any, opts: ModeSearchOptions,
                deadline: Deadline) -> Solution:  # fmt: skip
    """One search in the box of ``opts.bound_factor``. Where the box may have cut the
    optimum off, the answer keeps its exact point and has no proven bound
    (``stats["box_reached"]`` says why)."""
    data = QueryData.of(grasp, query, 100.0)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    abs_tol = _abs_tol(data, bounds, grasp, opts)
    stats: dict[str, Any] = {"bound_factor": opts.bound_factor, "abs_tol": abs_tol}
    bounds_stats(bounds, stats)
    conditions = exact_conditions(0.0)
    tb = time.perf_counter()
    ex = CoulombModel(grasp, data, bounds, 0.0, opts.motion_bound)
    qvar = add_query(ex.prob, data)
    lp = NodeLP(ex, data)
    stats["build_time_s"] = time.perf_counter() - tb
    search = Search(lp, opts, data, qvar, deadline.at(), abs_tol)
    existence = data.direction is None and data.command_range is None
    # a first exact point: every contact sticking, every actuator locked (one LP)
    tp = time.perf_counter()
    search.stuck()
    search.quick_time += time.perf_counter() - tp
    outcome = "done"
    if not (existence and search.best is not None):
        outcome = search.run(feasibility=existence)
    search.finish()
    stats.update({"nodes": search.nodes, "quick_polishes": search.quicks,
                  "quick_time_s": search.quick_time, "lps": lp.lp_count, "lp_time_s": lp.lp_time,
                  "lp_ms": 1e3 * lp.lp_time / max(1, lp.lp_count),
                  "simplex_iterations": lp.iterations, "polishes": search.polishes,
                  "rejected_points": search.rejected,
                  "polish_time_s": search.polish_time, "unresolved": len(search.unresolved),
                  "first_exact_node": search.first_exact_node,
                  "root_bound": None if search.root_bound is None
                  else search.root_bound * lp.sign})  # fmt: skip
    upper = search.upper()
    best = search.best
    cut = None
    if best is not None and not existence and _box_reached(ex, best[0]):
        cut = "the best exact point reaches the box"
    if best is not None and upper is not None and best[1] > upper + 1e-7 * (1 + abs(upper)):
        cut = f"exact value {best[1]} beyond the proven bound {upper}"
    if cut is not None:  # the bound holds only within the box, which the answer reaches
        stats["box_reached"] = cut
        upper = None
    closed = outcome == "done" and not search.unresolved
    if existence:
        if best is not None:
            return _answer(grasp, query, stats, ex, best[0], qvar, data, conditions, True)
        if closed:
            stats["reason"] = "every node of the tree is infeasible: no equilibrium"
            return solution("modesearch", grasp, query, False, stats, conditions=conditions)
        return _open(grasp, query, stats, outcome, search)
    if best is None:
        if closed:  # no exact point anywhere in the box
            stats["reason"] = "every node of the tree is infeasible: no equilibrium"
            if data.direction is not None:
                stats["capped"] = False
            return solution("modesearch", grasp, query, False, stats, conditions=conditions)
        return _bracketed(_open(grasp, query, stats, outcome, search), upper, lp.sign)
    value = best[1]
    certified = upper is not None and upper - value <= max(opts.gap * abs(upper), search.abs_tol)
    sol = _answer(grasp, query, stats, ex, best[0], qvar, data, conditions, certified)
    if data.direction is not None and certified and upper >= data.cap * (1 - 1e-8):
        sol.stats["capped"] = True  # the proven bound is the cap, the point within the gap
    if outcome != "done":
        sol.status, sol.stable = outcome if outcome == "timeout" else "not_converged", None
        sol.stats["message"] = _message(outcome, opts)
    return _bracketed(sol, upper, lp.sign)


def _message(outcome: str, opts: ModeSearchOptions) -> str:
    if outcome == "timeout":
        return f"time_limit {opts.time_limit} s reached; the bracket reached is returned"
    return f"node_limit {opts.node_limit} reached; the bracket reached is returned"


def _open(grasp: Grasp, query: Any, stats: dict[str, Any], outcome: str,
          search: Search) -> Solution:  # fmt: skip
    """No exact point: a time-out, a node limit, or unresolved leaves."""
    if outcome == "done":
        stats["reason"] = (f"{len(search.unresolved)} leaves with arcs narrower than "
                           "min_width and no exact point: neither answer is proven")  # fmt: skip
        status = "not_converged"
    else:
        status = "timeout" if outcome == "timeout" else "not_converged"
        stats["message"] = _message(outcome, search.opts)
    return Solution(None, "modesearch", grasp, query, stats=stats, status=status)


def _bracketed(sol: Solution, upper: float | None, sign: float) -> Solution:
    """``lower``/``upper`` in the query's terms: the exact point's value (``sol.value``)
    on the feasible side, the proven bound ``upper`` of the search (which maximises ``sign *
    objective``) on the other."""
    if not isinstance(sol.query, MaxDisturbance | OptimalCommands):
        return sol
    hi = None if upper is None or not math.isfinite(upper) else upper
    if sign > 0:
        sol.lower, sol.upper = sol.value, hi
        if hi is not None and sol.value is not None:
            sol.upper = max(hi, sol.value)
    else:
        sol.lower = None if hi is None else -hi
        if hi is not None and sol.value is not None:
            sol.lower = min(-hi, sol.value)
        sol.upper = sol.value
    sol.stats["certified"] = bool(sol.stats.get("certified"))
    return sol


def _answer(grasp: Grasp, query: Any, stats: dict[str, Any], ex: CoulombModel,
            x: NDArray[np.float64], qvar: int | None, data: QueryData,
            conditions: tuple[str, ...], certified: bool) -> Solution:  # fmt: skip
    pt = ex.prob.point(x)
    value = query_value(ex, pt, qvar, data)
    stats["certified"] = certified
    stats["exact_value"] = value
    if data.direction is not None:
        stats["capped"] = value is not None and value >= data.cap * (1 - 1e-8)
    sol = solution("modesearch", grasp, query, True, stats, ex.prob, pt, value,
                   conditions=conditions)  # fmt: skip
    if data.command_range is not None:
        sol.commands = pt.x[ex.prob.fc]
    return sol


@register(
    "modesearch",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    options=ModeSearchOptions,
    hand=True,
    compliance=True,
    motion_limit=True,
    summary="Coulomb friction with maximum dissipation by one branch-and-bound tree over "
    "contact modes and slide arcs, one LP per node (exact points, proven brackets)",
)
def _solve_modesearch(grasp: Grasp, query: Any, opts: ModeSearchOptions,
                      deadline: Deadline) -> Solution:  # fmt: skip
    def attempt(factor: float, prev: Solution | None) -> tuple[Solution, str | None]:
        nodes = opts.node_limit
        if prev is not None:  # a larger box's search may take a few times the nodes
            nodes = min(nodes, RETRY_NODE_FACTOR * int(prev.stats["nodes"]) + RETRY_NODE_SLACK)
        o = replace(opts, bound_factor=factor, node_limit=nodes)
        sol = _solve_once(grasp, query, o, deadline)
        converged = prev is not None and _converged(prev, sol, opts)
        return sol, None if converged else sol.stats.get("box_reached")

    def keep(prev: Solution, sol: Solution) -> str | None:
        if sol.status in ("timeout", "not_converged"):
            return f"{sol.status} ({sol.stats['nodes']} nodes)"
        return None

    sol, notes = enlarge_box(attempt, opts.bound_factor, deadline, keep, BOX_RETRIES)
    if notes:
        sol.stats["box_enlarged"] = notes
    return sol


def _converged(prev: Solution, sol: Solution, opts: ModeSearchOptions) -> bool:
    """The larger box moved the exact value by at most the bracket's tolerance."""
    a, b = prev.stats.get("exact_value"), sol.stats.get("exact_value")
    if a is None or b is None:
        return False
    tol = max(opts.gap * abs(b), float(sol.stats.get("abs_tol", 0.0)))
    return abs(b - a) <= tol
