"""``method="no_mdp"``: the exact model with the friction cone and no maximum dissipation.

Thesis sec. 3dfriction, the "cautionary formulation": drop the maximum dissipation
principle (eq. mdp) and keep only the cone (eq. frictioncone), and the problem is one MIP
(:class:`~stability.model.problem.ExactProblem` plus object equilibrium ``G c + w = 0``). It is
wrong: an unloaded object can "wedge" itself by a virtual rotation that compresses springs
while the applied force does no work, and friction then "holds" it (thesis Fig. twist:
energy is created). It exists to be shown wrong; see ``tests/stability/test_no_mdp_iterative.py``.

``Existence``: is the MIP feasible? ``MaxDisturbance``: maximise ``s in [0, cap]`` with
``w = s d``. Options: :class:`stability.model.run.MipOptions`. The model's force bound
(:func:`~stability.model.problem.scale_bounds`) can decide an answer (a wedge with a tiny angle
needs forces far above the load); so an infeasible model, or an answer at a bound, is
solved once more with a 100x larger bound (``stats["retried_bound_factor"]``), and an
answer still at a bound says so (``stats["at_bound"]``: the value is then a lower bound
limited by the model, an "unstable" means none within ``stats["force_bound"]``).
"""

from __future__ import annotations

from typing import Any

from .api import register
from .grasp import Grasp
from .model.problem import ExactProblem, scale_bounds
from .model.query import QueryData, add_query
from .model.run import MipOptions, Stop, bounds_stats, run, solution, stopped
from .options import Deadline
from .queries import Existence, MaxDisturbance
from .solution import Solution

__all__: list[str] = []


@register(
    "no_mdp",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=True,
    options=MipOptions,
    hand=True,
    compliance=True,
    motion_limit=True,
    summary="thesis ch. 5 baseline: one MIP, friction cone without maximum dissipation "
    "(wrong where a virtual rotation wedges the object)",
)
def _solve_no_mdp(grasp: Grasp, query: Existence | MaxDisturbance, opts: MipOptions,
                  deadline: Deadline) -> Solution:  # fmt: skip
    data = QueryData.of(grasp, query)
    stats: dict[str, Any] = {"backend": opts.backend}
    sol = _attempt(grasp, query, data, opts, deadline, opts.bound_factor, stats)
    if sol.status == "solved" and (not sol.stable or stats.get("at_bound")):
        # infeasible or at a bound: the bound may be what decided; once more, 100x larger
        stats["retried_bound_factor"] = 100.0 * opts.bound_factor
        sol = _attempt(grasp, query, data, opts, deadline, 100.0 * opts.bound_factor, stats)
    return sol


def _attempt(grasp, query, data, opts, deadline, bound_factor, stats) -> Solution:
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, bound_factor)
    prob = ExactProblem(grasp, data.preload, data.hand, bounds, opts.edges, name="no_mdp")
    bounds_stats(bounds, stats)
    s = add_query(prob, data)
    try:
        pt = run(prob, opts, deadline, stats)
    except Stop as e:
        return stopped("no_mdp", grasp, query, stats, e)
    if pt is None:
        if data.direction is not None:
            stats["capped"] = False
        return solution("no_mdp", grasp, query, False, stats)
    value = None
    if s is not None:
        value = float(min(data.cap, max(0.0, pt.x[s])))
        stats["capped"] = value >= data.cap * (1 - 1e-8)  # the tidy LP may give up 1e-10
    return solution("no_mdp", grasp, query, True, stats, prob, pt, value)
