"""``method="no_mdp"``: the exact model with the friction cone and no maximum dissipation.

Thesis sec. 3dfriction, the "cautionary formulation": drop the maximum dissipation
principle (eq. mdp) and keep only the cone (eq. frictioncone), and the problem is one MIP
(:class:`~stability.exact.ExactProblem` plus object equilibrium ``G c + w = 0``). It is
wrong: an unloaded object can "wedge" itself by a virtual rotation that compresses springs
while the applied force does no work, and friction then "holds" it (thesis Fig. twist:
energy is created). It exists to be shown wrong; see ``tests/test_mip_methods.py``.

``Existence``: is the MIP feasible? ``MaxDisturbance``: maximise ``s in [0, cap]`` with
``w = s d``. Options: :class:`stability._mipcommon.MipOptions`.
"""

from __future__ import annotations

from typing import Any

from ._mipcommon import MipOptions, QueryData, Stop, bounds_stats, run, solution, stopped
from .api import register
from .exact import ExactProblem, scale_bounds
from .grasp import Grasp
from .queries import Existence, MaxDisturbance
from .solution import Solution

__all__: list[str] = []


@register(
    "no_mdp",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=True,
    hand=True,
    summary="thesis ch. 5 baseline: one MIP, friction cone without maximum dissipation "
    "(wrong where a virtual rotation wedges the object)",
)
def _solve_no_mdp(grasp: Grasp, query: Existence | MaxDisturbance, **options: Any) -> Solution:
    opts = MipOptions.of("no_mdp", options)
    data = QueryData.of(grasp, query)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    prob = ExactProblem(grasp, data.preload, data.hand, bounds, opts.edges, name="no_mdp")
    stats: dict[str, Any] = {"backend": opts.backend}
    bounds_stats(prob, stats)
    s = None
    if data.direction is None:
        prob.add_object_equilibrium(data.wrench)
    else:
        s = prob.add_object_equilibrium(0.0 * data.direction, data.direction, data.cap)
        prob.model.set_objective([s], [1.0], maximize=True)
    try:
        pt = run(prob, opts, stats)
    except Stop as e:
        return stopped("no_mdp", grasp, query, stats, e)
    if pt is None:
        if data.direction is not None:
            stats["capped"] = False
        return solution("no_mdp", grasp, query, False, stats)
    value = None
    if s is not None:
        value = float(min(data.cap, max(0.0, pt.x[s])))
        if value >= data.cap * (1 - 1e-8):  # the least-motion LP may give up 1e-10 of s
            value = data.cap
        stats["capped"] = value == data.cap
    return solution("no_mdp", grasp, query, True, stats, prob, pt, value)
