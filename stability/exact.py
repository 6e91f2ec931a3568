"""``method="exact"``: the exact nonconvex problem solved globally by SCIP's spatial
branch-and-bound (the thesis' "future work" alternative to ch. 6; our accuracy reference).
``method="spatial"`` is an alias that warns (``DeprecationWarning``).

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
motions ``|d_t| <= motion_bound * D`` (``D = 2 B / min k``: ``ExactBounds.displacement``;
the same box as ``refinement``'s edge weights), translations within that, rotations
within it over the grasp's size ``L`` and joint motions within it over their lever; an answer at the
box is flagged ``stats["at_bound"]`` and, for an optimisation query, solved again in a larger box
("The box" below).

Queries: ``Existence``, ``MaxDisturbance`` (maximise ``s``), ``OptimalCommands`` (the
objectives and limits of ``refinement``), all in one solve. Options: ``time_limit`` (a
time-out returns ``status="timeout"`` with SCIP's incumbent and dual bound in
``stats["incumbent"]``/``stats["dual_bound"]``; the incumbent is the feasible side of the
bracket only when its point, polished, passes the exact conditions and lies against its
slides within ``ALIGN_RTOL (1 + B)`` (``stats["incumbent_checked"]``), and then it is that
point's value), ``gap`` (relative optimality gap at which
SCIP stops, default 1e-4), ``bound_factor``, ``verbose``, ``normal_uncertainty`` (eta: the
spring law uses ``d_n cos eta + s_i sin eta``, the worst normal within eta, as
``refinement`` does), ``motion_bound``, ``feastol`` (SCIP's feasibility tolerance, default
its own 1e-6; 1e-9 makes SoPlex ask for 1e-12), ``presolve`` (SCIP's presolve, default
True), ``recheck`` (default True; "Rechecks" below). Backend: SCIP only (HiGHS has no
nonlinear rows).

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

Unpolished points. Where the LP polish fails (SCIP's binaries admit no exact mode LP),
SCIP's own point is returned; it can slide contacts by SCIP's tolerance with friction
inside the cone, a product within the tolerance ``1e-6 (1 + B) (1 + max |d_t|)`` whose
value is right but whose point is not exact. Maximum dissipation as a force,
``stats["violations"]["alignment"]`` (the ``slide_alignment`` residual, which
``Solution.max_residual()`` covers), shows it; beyond ``ALIGN_RTOL (1 + B)`` the answer keeps
SCIP's value but its feasible side (MaxDisturbance ``lower``, OptimalCommands ``upper``) is
None, it is not certified, and ``stats["inexact_point"]`` says why; ``stats["polished"]`` is
False.

Rechecks. SCIP's spatial branch-and-bound prunes wrongly now and then, and no single
setting prevents it (the survey that showed it: docs/notebook/2026-11-28-exact-rechecks.md).
Two rechecks, both on by default (``recheck=False`` gives one solve): an "infeasible" is
solved once more without presolve (as the MIP methods do, :func:`stability.model.run.run`;
``stats["infeasible_rechecked"]`` is that solve's status); and a MaxDisturbance optimum
``v`` below the cap is solved once more in a box fitted to it (cap ``max(2 v, 1e-3 cap)``,
doubled while the answer reaches it; ``stats["recheck"]``): a higher checked point there
(beyond the gap) is returned and the disagreement reported
(``stats["recheck"]["disagreement"]``, ``stats["message"]``); a higher SCIP optimum whose
point fails the exact conditions ends the query as ``status="error"`` with the first value
in ``stats["incumbent"]``. Within the gap the first point is kept. The rechecks bound what a
wrong prune can do; they prove nothing: an optimum wrongly pruned beyond twice the returned
value, or in both boxes alike, stays unseen.

Brackets (``sol.lower``/``sol.upper``, ``stats["certified"]``): the returned checked point's
value on the feasible side, SCIP's dual bound *in the query's box* on the other
(``stats["dual_bound"]``; a fitted box's bound holds only in that box and stays in its
row of ``stats["recheck"]["solves"]``). A disagreement (a checked point above the first
optimum by more than ``RECHECK_RTOL`` relative, or above the query box's dual bound by
more than the gap; a fitted optimum below the checked first point by more than
``RECHECK_RTOL``; the ``status="error"`` above) shows SCIP pruning wrongly on this query,
so its dual bound proves nothing there: ``upper`` is None and ``certified`` False. A
recheck stopped by the time limit (``stats["recheck"]["stopped"]``, ``stats["message"]``)
leaves SCIP's bracket, not ``certified``. ``certified`` means "SCIP's bound met", not a
proof. A time-out's feasible side is SCIP's incumbent only where its point, polished,
passes the same checks (``stats["incumbent_checked"]``); otherwise that side is None.

The box. Every bound above holds for motions inside the box (``bound_factor``, default
:data:`EXACT_BOUND_FACTOR` = 100 times the force scale). An optimisation answer whose
motion reaches it (``stats["box_reached"]``: a tangential, object or joint motion at 99 %
of its bound) may have been cut off there: the box grows tenfold and the query is solved
again within the same deadline, at most :data:`~stability.options.BOX_RETRIES` times
(:func:`~stability.options.enlarge_box`; ``stats["box_enlarged"]`` lists the
enlargements). A larger box's answer replaces the smaller's when it is solved; a
time-out or an error there leaves the answer found. An answer (or a
time-out's checked incumbent) still at its box has no dual-bound side (MaxDisturbance
``upper``, OptimalCommands ``lower`` None) and is not certified. A larger default box is
slower where it does not bind, hence 100 and the retries.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
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
from .options import Deadline, check_ranges, enlarge_box, finite
from .queries import Existence, MaxDisturbance, OptimalCommands
from .solution import Solution, slide_alignment

__all__ = ["ExactOptions"]

EXACT_BOUND_FACTOR = 100.0  # the default box (bound_factor); enlarged where an answer reaches it
# MaxDisturbance rechecks (module docstring): the fitted box's smallest cap, as a fraction
# of the query's, and the relative difference reported as a disagreement
RECHECK_FLOOR = 1e-3
RECHECK_RTOL = 1e-3
ALIGN_RTOL = 1e-6  # slide_alignment [N] beyond this times (1 + force bound): not exact


@dataclass(frozen=True)
class ExactOptions(MipOptions):
    """Options of ``method="exact"``: :class:`~stability.model.run.MipOptions` (``backend``
    SCIP only: the model is nonlinear; ``bound_factor`` default :data:`EXACT_BOUND_FACTOR`)
    and ``normal_uncertainty`` [rad] (each normal anywhere in a cone of that half-angle),
    ``motion_bound`` (the motions' box per ``D = 2 B / min k``), ``feastol`` (SCIP's feasibility
    tolerance), ``gap`` (SCIP's relative gap, the bracket's closing width), ``recheck`` and
    ``presolve`` (module docstring)."""

    backend: str | None = "scip"
    bound_factor: float = EXACT_BOUND_FACTOR
    normal_uncertainty: float = 0.0
    motion_bound: float = 4.0
    feastol: float = 1e-6
    gap: float = 1e-4
    recheck: bool = True
    presolve: bool = True

    @classmethod
    def of(cls, method: str, options: dict[str, Any]) -> ExactOptions:
        """:meth:`MipOptions.of` with SCIP as the backend unless another is asked for (a
        :class:`MethodError`: only SCIP has spatial branch-and-bound)."""
        return super().of(method, {"backend": "scip", **options})

    def check(self) -> None:
        if self.backend not in (None, "scip"):
            raise MethodError(
                f"method 'exact' needs SCIP's spatial branch-and-bound (backend='scip'), got "
                f"backend={self.backend!r}: HiGHS has no nonlinear constraints"
            )
        super().check()
        eta = self.normal_uncertainty
        check_ranges(self, {
            "normal_uncertainty": (finite(eta) and 0.0 <= eta < math.pi / 2, "in [0, pi/2) rad"),
            "motion_bound": (finite(self.motion_bound) and self.motion_bound >= 1.0,
                             "a finite number >= 1"),
            "feastol": (finite(self.feastol) and 0.0 < self.feastol <= 1e-3, "in (0, 1e-3]"),
            "gap": (finite(self.gap) and 0.0 <= self.gap < 0.5, "in [0, 0.5)"),
        })  # fmt: skip


@register(
    "exact",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    options=ExactOptions,
    hand=True,
    compliance=True,
    motion_limit=True,
    summary="exact nonconvex problem (circular cone, bilinear maximum dissipation) solved "
    "globally by SCIP's spatial branch-and-bound: the accuracy reference for small grasps",
)
def _solve_exact(grasp: Grasp, query: Any, opts: ExactOptions, deadline: Deadline) -> Solution:
    # The box (bound_factor times the force scale): an optimisation answer whose motion
    # reaches it may have been cut off there; it grows tenfold and the query is solved
    # again (module docstring, "The box").
    optimisation = isinstance(query, MaxDisturbance | OptimalCommands)

    def attempt(factor: float, prev: Solution | None) -> tuple[Solution, str | None]:
        sol = _solve_once(grasp, query, dataclasses.replace(opts, bound_factor=factor),
                          deadline)  # fmt: skip
        reached = sol.status == "solved" and sol.stats.get("box_reached") and optimisation
        return sol, "the answer's motion reaches the box" if reached else None

    def keep(prev: Solution, sol: Solution) -> str | None:
        if sol.status != "solved" or sol.value is None:
            return f"{sol.status}, value {sol.value}"
        return None

    sol, notes = enlarge_box(attempt, opts.bound_factor, deadline, keep)
    if notes:
        sol.stats["box_enlarged"] = notes
    if sol.stats.get("box_reached") and sol.status in ("solved", "timeout"):
        # the dual bound holds only within the box, which the answer reaches: none given
        if isinstance(query, MaxDisturbance):
            sol.upper, sol.stats["certified"] = None, False
        elif isinstance(query, OptimalCommands):
            sol.lower, sol.stats["certified"] = None, False
    return sol


def _solve_once(grasp: Grasp, query: Any, opts: ExactOptions, deadline: Deadline) -> Solution:
    """One solve of the query in the box of ``opts.bound_factor``."""
    if grasp.planar:
        raise GraspError("method 'exact' takes spatial grasps; use 'planar' for planar ones")
    data = QueryData.of(grasp, query, opts.bound_factor)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"backend": "scip", "normal_uncertainty": opts.normal_uncertainty,
                             "feastol": opts.feastol, "gap": opts.gap}  # fmt: skip
    bounds_stats(bounds, stats)
    conditions = exact_conditions(opts.normal_uncertainty)
    t0 = time.perf_counter()
    run = _Run(grasp, opts, deadline)
    try:
        ex, var, res = run.attempt(data, bounds, stats)
        if res is not None and data.direction is not None and opts.recheck:
            ex, var, res, data = _recheck(run, data, (ex, var, res), stats)
    except Stop as e:
        # a time-out's incumbent is on the feasible side only if its point passed the
        # exact conditions (_run: stats["incumbent_checked"])
        inc = stats.get("incumbent") if stats.get("incumbent_checked") else None
        return _bracket(stopped("exact", grasp, query, stats, e), data, inc)
    finally:
        stats["solve_time_s"] = time.perf_counter() - t0
    if res is None:
        if data.direction is not None:
            stats["capped"] = False
        return solution("exact", grasp, query, False, stats, conditions=conditions)
    pt = ex.prob.point(res)
    stats["box_reached"] = reached = _box_reached(ex, res)
    pt.at_bound = pt.at_bound or reached
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
    exact point on the feasible side, its dual bound in the query's box on the other
    (MaxDisturbance: at most the cap); ``stats["certified"]`` when they meet within the
    relative ``gap`` asked. After a recheck that disagreed (``stats["recheck"]``) SCIP has
    pruned wrongly on this query: no upper bound, not certified; after one the time limit
    stopped, SCIP's bracket stands, not certified (module docstring)."""
    if sol.stats.get("recheck", {}).get("disagreement"):
        sol.lower, sol.upper = value, None
        sol.stats["certified"] = False
        return sol
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
    align = sol.stats.get("violations", {}).get("alignment")
    if align is not None and align > _align_limit(sol.stats["force_bound"]):
        # the point slides a contact with friction off its slide: not an exact point, so
        # its value bounds nothing (module docstring, "Unpolished points")
        sol.stats["inexact_point"] = (
            f"friction {align:.3g} N off a contact's slide "
            "(slide_alignment): the feasible side is withdrawn"
        )
        if data.direction is not None:
            sol.lower = None
        else:
            sol.upper = None
        sol.stats["certified"] = False
        return sol
    if sol.lower is not None and sol.upper is not None:
        width = sol.upper - sol.lower
        sol.stats["certified"] = width <= sol.stats["gap"] * max(abs(sol.upper), 1e-12) + 1e-9
    if sol.stats.get("recheck", {}).get("stopped"):  # asked for, not done: not certified
        sol.stats["certified"] = False
    return sol


@dataclass(frozen=True)
class _Run:
    """What every SCIP solve of one query shares: the grasp, the options, the deadline."""

    grasp: Grasp
    opts: ExactOptions
    deadline: Deadline

    def attempt(self, data: QueryData, bounds: Any,
                stats: dict[str, Any]) -> tuple[CoulombModel, int | None, Any]:  # fmt: skip
        """The exact model of ``data`` within ``bounds``, its query variable and SCIP's
        checked point (None: infeasible); :class:`Stop` otherwise."""
        o = self.opts
        ex = CoulombModel(self.grasp, data, bounds, o.normal_uncertainty, o.motion_bound)
        var = add_query(ex.prob, data)
        ex.prob.model.presolve = o.presolve
        return ex, var, _run(ex, self, stats)


def _recheck(run: _Run, data: QueryData, found: tuple[CoulombModel, int | None, Any],
             stats: dict[str, Any]) -> tuple:  # fmt: skip
    """MaxDisturbance: SCIP's optimum ``v`` below the cap solved once more in a box fitted
    to it (cap ``max(2 v, 1e-3 cap)``, the model's bounds from that; module docstring,
    "Rechecks"), doubling that cap while the answer reaches it. Returns the model, query
    variable, point and data of the higher of the two verified points;
    ``stats["recheck"]`` records the fitted solves. ``stats["dual_bound"]`` stays the
    query's box's (a fitted box's bounds only that box: its row has it). ``found``: the
    model, query variable and point of the query's box."""
    ex, var, res = found
    grasp, gap = run.grasp, run.opts.gap
    first = query_value(ex, ex.prob.point(res), var, data)
    cap = data.cap
    fitted = min(cap, max(2.0 * first, RECHECK_FLOOR * cap))
    rows: list[dict[str, Any]] = []
    stats["recheck"] = {"first": first, "solves": rows, "disagreement": False}
    best = (ex, var, res, data, first)
    while fitted < cap * (1.0 - 1e-9):
        d2 = dataclasses.replace(data, cap=fitted)
        b2 = scale_bounds(grasp, d2.wrench_max, d2.preload, d2.hand, run.opts.bound_factor)
        sub: dict[str, Any] = {}
        t0 = time.perf_counter()
        try:
            ex2, var2, res2 = run.attempt(d2, b2, sub)
        except Stop as e:  # the first answer stands, unconfirmed ...
            rows.append({"cap": fitted, "status": e.status, "message": e.message,
                         "objective": sub.get("objective"), "time_s": time.perf_counter() - t0,
                         "force_bound": b2.force})  # fmt: skip
            other = sub.get("objective")
            if e.status == "error" and other is not None and other > first * (1 + RECHECK_RTOL):
                # ... unless SCIP's optimum there, though its point fails the exact
                # conditions, contradicts it beyond any tolerance: then there is no answer
                stats["incumbent"] = first
                stats["recheck"]["disagreement"] = True
                raise Stop("error", f"SCIP's optimum {first:.6g} in the query's box is "
                           f"contradicted by {other:.6g} in a box fitted to it, whose point "
                           f"fails the exact conditions ({e.message}); no exact optimum "
                           "can be given") from None  # fmt: skip
            stats["recheck"]["stopped"] = e.status
            stats["message"] = (
                f"the recheck in a box fitted to {first:.6g} stopped ({e.message}): "
                "the answer is SCIP's, unconfirmed"
            )
            break
        finally:
            for k in ("mips", "mip_time_s", "nodes"):
                stats[k] = stats.get(k, 0) + sub.get(k, 0)
        value = None if res2 is None else query_value(ex2, ex2.prob.point(res2), var2, d2)
        rows.append({"cap": fitted, "value": value, "time_s": time.perf_counter() - t0,
                     "nodes": sub.get("nodes"), "dual_bound": sub.get("dual_bound"),
                     "force_bound": b2.force})  # fmt: skip
        if value is None:  # no point in the fitted box: its bounds cut the first one off
            break
        if value > best[4] * (1.0 + gap) + 1e-12 * cap:  # within the gap: keep the first
            best = (ex2, var2, res2, d2, value)
            for k in ("polished", "violations", "infeasible_rechecked"):
                if k in sub:
                    stats[k] = sub[k]
        if value < fitted * (1.0 - 1e-8):
            break
        fitted = min(cap, 2.0 * fitted)  # at the fitted cap: the optimum may lie beyond
    ex, var, res, d2, value = best
    tol = RECHECK_RTOL * first + 1e-12 * cap
    bound = stats.get("dual_bound")  # SCIP's, in the query's box
    refuted = bound is not None and math.isfinite(bound) and value > bound * (1 + gap) + 1e-9
    if value > first + tol or refuted:
        stats["recheck"]["disagreement"] = True
        said = "" if bound is None else f" (its dual bound {bound:.6g})"
        stats["message"] = (
            f"SCIP's optimum {first:.6g} in the query's box{said} was refuted by "
            f"{value:.6g} found in a box fitted to it (an exact point, checked); the higher "
            "is returned, with no upper bound"
        )
    elif any(r.get("value") is not None and r["value"] < first - tol for r in rows):
        stats["recheck"]["disagreement"] = True
        stats["message"] = (
            f"SCIP's optimum in a box fitted to {first:.6g} came out lower than that "
            "checked point; the checked point is returned, with no upper bound"
        )
    return ex, var, res, dataclasses.replace(d2, cap=cap)


def _run(ex: CoulombModel, run: _Run, stats: dict[str, Any]) -> NDArray[np.float64] | None:
    """Solve; the point (None: infeasible), :class:`Stop` on a time-out or an error. With
    ``recheck``, an "infeasible" is checked once more without SCIP's presolve (module
    docstring)."""
    opts, gap = run.opts, run.opts.gap
    left = run.deadline.remaining()
    if left is not None and left <= 0.0:
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached")
    res = _scip(ex, opts, left, stats)
    infeasible = res.status in ("infeasible", "infeasible_or_unbounded")
    if infeasible and opts.recheck and ex.prob.model.presolve:
        left = run.deadline.remaining()
        if left is not None and left <= 0.0:
            raise Stop("timeout", f"time_limit {opts.time_limit} s reached (rechecking "
                       "SCIP's infeasibility without presolve)")  # fmt: skip
        ex.prob.model.presolve = False
        try:
            res = _scip(ex, opts, left, stats)
        finally:
            ex.prob.model.presolve = True
        stats["infeasible_rechecked"] = res.status
    if res.status in ("infeasible", "infeasible_or_unbounded"):
        return None
    if res.status == "timeout":
        stats["incumbent"] = res.objective
        stats["incumbent_checked"] = False
        x = None
        if res.x is not None:  # the incumbent's point, polished and checked like an optimum
            check: dict[str, Any] = {}
            try:
                x = _checked(ex, polish(ex, res.x, gap, {}), stats=check)
            except Stop:
                pass
        # an exact point: the conditions of _checked and friction against each slide (the
        # optimum's alignment is judged in _bracket); its value is the polished point's
        if x is not None and check["violations"]["alignment"] <= _align_limit(ex.prob.bounds.force):
            stats["incumbent"] = ex.prob.model.objective_value(x)
            stats["incumbent_checked"] = True
            stats["box_reached"] = _box_reached(ex, x)
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached ({res.message}; "
                   f"incumbent {res.objective}, dual bound {res.bound})")  # fmt: skip
    if res.status == "optimal" and res.x is not None:
        return _checked(ex, polish(ex, res.x, gap, stats), stats)
    raise Stop("error", f"scip: {res.status}: {res.message}")


def _align_limit(force_bound: float) -> float:
    """The largest ``slide_alignment`` [N] of an exact point, ``ALIGN_RTOL (1 + B)``: friction
    off a slide by more is not an exact point (module docstring, "Unpolished points")."""
    return ALIGN_RTOL * (1.0 + force_bound)


def _box_reached(ex: CoulombModel, x: NDArray[np.float64]) -> bool:
    """A tangential, object or joint motion of ``x`` at 99 % of its bound in the box."""
    M = ex.prob.model
    motion = np.r_[ex.dt.reshape(-1), ex.prob.r, [] if ex.prob.q is None else ex.prob.q]
    box = np.array([M.ub[int(j)] for j in motion])
    return bool(np.any(np.abs(x[motion.astype(int)]) >= 0.99 * box))


def _checked(ex: CoulombModel, x: NDArray[np.float64],
             stats: dict[str, Any]) -> NDArray[np.float64]:  # fmt: skip
    """``x`` if it passes the exact conditions (``stats["violations"]``); :class:`Stop`
    ``"error"`` otherwise."""
    viol = ex.violations(x)
    stats["violations"] = viol
    # force conditions within 1e-6 of the force bound; dissipation (force x motion)
    # within that times the motion's scale
    B = ex.prob.bounds.force
    dmax = 1.0 + float(np.abs(x[ex.dt]).max(initial=0.0))
    lim = {k: 1e-6 * (1.0 + B) * (dmax if k == "dissipation" else 1.0) for k in viol}
    bad = {k: v for k, v in viol.items() if v > lim[k]}
    # maximum dissipation as a force (slide_alignment of model_residuals), reported,
    # not enforced: an unpolished point can slide contacts by SCIP's tolerance with
    # friction inside the cone (module docstring, "Unpolished points")
    g, pt = ex.grasp, ex.prob.point(x)
    d = g.contact_motion(pt.motion, pt.hand_motion)
    viol["alignment"] = slide_alignment(g.mu, pt.forces, d)
    if bad:
        raise Stop("error", f"SCIP's answer fails the exact conditions {bad}")
    return x


def _scip(ex: CoulombModel, opts: ExactOptions, time_limit: float | None,
          stats: dict[str, Any]) -> MipResult:  # fmt: skip
    """One SCIP solve of ``ex`` (presolve as ``ex.prob.model.presolve``); its counts added
    to ``stats``. A solver's internal failure is :class:`Stop` ``"error"``."""
    t0 = time.perf_counter()
    try:
        m, x = ex.scip_model(time_limit, opts.verbose, opts.feastol, opts.gap)
        m.setParam("limits/absgap", 1e-9)  # gap is relative: small answers need it so
        if not ex.prob.model.presolve:
            # without presolve SCIP's symmetry detection can run on past the time limit
            # (the pinch's Existence(-2.5 z, commands 0.1)): off
            m.setParam("misc/usesymmetry", 0)
        raw = optimize_scip(m, x, ex.prob.model, t0)
    except Exception as e:  # noqa: BLE001  (a solver's internal failure is a status)
        raise Stop("error", f"scip failed: {type(e).__name__}: {e}") from None
    res = MipResult(raw["status"], "scip", raw["x"], raw["objective"], raw["bound"],
                    raw["time_s"], raw["nodes"], raw["message"])  # fmt: skip
    stats["mips"] = stats.get("mips", 0) + 1
    stats["mip_time_s"] = stats.get("mip_time_s", 0.0) + res.time_s
    stats["nodes"] = stats.get("nodes", 0) + res.nodes
    stats["dual_bound"] = res.bound
    stats["objective"] = res.objective  # SCIP's, before any check
    return res
