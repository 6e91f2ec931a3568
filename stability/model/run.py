"""What the MIP methods (``no_mdp``, ``iterative``, ``refinement``, ``exact``) share: their
options (:class:`MipOptions`), one solve of an :class:`~stability.model.problem.ExactProblem`
within the deadline, checked against the model's exact conditions (:func:`run`), and the
:class:`~stability.Solution` they return (:func:`solution`, :func:`stopped`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from .. import mip
from ..grasp import Grasp
from ..options import Deadline, MethodOptions, check_ranges, finite
from ..queries import Query
from ..solution import Solution
from .problem import ExactBounds, ExactPoint, ExactProblem

# the model_residuals keys every exact-model method enforces (not max_dissipation)
HAND_CONDITIONS = ("hand_equilibrium", "actuator_command", "nonbackdrivable",
                   "actuator_complementarity")  # fmt: skip
CONDITIONS = ("equilibrium", "normal_sign", "friction_cone", "spring_law", *HAND_CONDITIONS,
              "motion_limit")  # fmt: skip


# The faster backend per method in ``python -m stability.bench mip`` (docs/bench/stability.md):
# HiGHS for no_mdp's one MIP per query, SCIP for iterative's many small ones; both backends
# give the same answers.
DEFAULT_BACKENDS = {"no_mdp": "highs", "iterative": "scip", "refinement": "scip"}


_M = TypeVar("_M", bound="MipOptions")


def default_backend(method: str) -> str:
    """The measured faster backend for ``method`` if installed, else any installed one."""
    want = DEFAULT_BACKENDS.get(method, mip.DEFAULT_BACKEND)
    have = mip.available_backends()
    return want if want in have or not have else have[0]


@dataclass(frozen=True)
class MipOptions(MethodOptions):
    """Options of every MIP method: ``backend`` (``"highs"``, ``"scip"`` or, with ``gurobipy``
    installed, ``"gurobi"``; default: the method's measured faster one,
    :data:`DEFAULT_BACKENDS`; checked by :func:`stability.mip.check_backend`), ``time_limit``
    [s] for the whole method call (None: none), ``verbose`` (the solver's log), ``edges``
    (friction polygon sides, spatial contacts), ``bound_factor`` (model bounds as a multiple
    of the problem's force scale, :func:`stability.model.problem.scale_bounds`)."""

    backend: str | None = None
    time_limit: float | None = None
    verbose: bool = False
    edges: int = 8
    bound_factor: float = 100.0

    def __post_init__(self) -> None:
        if self.backend is None:
            object.__setattr__(self, "backend", mip.DEFAULT_BACKEND)
        super().__post_init__()

    @classmethod
    def of(cls: type[_M], method: str, options: dict[str, Any]) -> _M:
        """:meth:`MethodOptions.of`, the backend defaulting to the method's
        (:data:`DEFAULT_BACKENDS`)."""
        if options.get("backend") is None:
            options = {**options, "backend": default_backend(method)}
        return super().of(method, options)

    def check(self) -> None:
        super().check()
        mip.check_backend(self.backend)
        check_ranges(self, {"edges": (self.edges >= 3, "an integer >= 3"),
                            "bound_factor": (finite(self.bound_factor) and self.bound_factor
                                             >= 1.0, "a finite number >= 1")})  # fmt: skip


class Stop(Exception):
    """A MIP gave no answer (time-out or solver error): ends the method with that status."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status, self.message = status, message


def run(problem: ExactProblem, opts: MipOptions, deadline: Deadline,
        stats: dict[str, Any]) -> ExactPoint | None:  # fmt: skip
    """Solve ``problem.model`` within ``deadline``; the point, None when infeasible;
    :class:`Stop` otherwise."""
    left = deadline.remaining()
    if left is not None and left <= 0.0:
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached")
    gap = 1e-9 if problem.model.gap is None else problem.model.gap
    res = mip.solve(problem.model, backend=opts.backend, time_limit=left, verbose=opts.verbose,
                    gap=gap)  # fmt: skip
    _count(res, stats)
    if opts.backend == "scip" and res.status in ("infeasible", "infeasible_or_unbounded"):
        # SCIP's presolve can prove a feasible model infeasible (barrett_cube's grasp read
        # from MuJoCo, a torque about x: tests/stability/test_scip_presolve.py). An
        # infeasible round ends a query ("unstable"), so that claim is checked once more
        # without presolve; feasible answers need no second look (they are certified).
        problem.model.presolve = False
        left = deadline.remaining()
        if left is not None and left <= 0.0:
            raise Stop("timeout", f"time_limit {opts.time_limit} s reached")
        try:
            res = mip.solve(problem.model, backend=opts.backend, time_limit=left,
                            verbose=opts.verbose, gap=gap)  # fmt: skip
        finally:
            problem.model.presolve = True
        _count(res, stats)
        stats["infeasible_rechecked"] = stats.get("infeasible_rechecked", 0) + 1
    if res.status == "optimal":
        stats["dual_bound"] = res.bound  # within the model's gap of the point's value
        x = res.x
        tidy = problem.tidy(x)
        if tidy is not None and _certified(problem, tidy):
            x = tidy
        elif not _certified(problem, x):
            raise Stop("error", f"{opts.backend}: answer fails the exact conditions "
                       f"{problem.model.violations(x)} at the model's force scale")  # fmt: skip
        return problem.point(x)
    if res.status in ("infeasible", "infeasible_or_unbounded"):
        return None
    if res.status == "timeout":
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached ({res.message})")
    raise Stop("error", f"{opts.backend}: {res.status}: {res.message}")


def _count(res: Any, stats: dict[str, Any]) -> None:
    stats["mips"] = stats.get("mips", 0) + 1
    stats["mip_time_s"] = stats.get("mip_time_s", 0.0) + res.time_s
    stats["nodes"] = stats.get("nodes", 0) + res.nodes


def _certified(problem: ExactProblem, x: NDArray[np.float64], tol: float = 1e-7) -> bool:
    """``x`` meets the model's exact conditions within ``tol`` times its force bound (not
    times ``max|x|``: the motions are unbounded and must not widen the tolerance)."""
    viol = problem.model.violations(x)
    return max(viol.values()) <= tol * (1.0 + problem.bounds.force)


def solution(
    method: str,
    grasp: Grasp,
    query: Query,
    stable: bool | None,
    stats: dict[str, Any],
    problem: ExactProblem | None = None,
    pt: ExactPoint | None = None,
    value: float | None = None,
    status: str = "solved",
    conditions: tuple[str, ...] = CONDITIONS,
) -> Solution:
    """A :class:`Solution` from an exact-model point (or none)."""
    sol = Solution(stable, method, grasp, query, value=value, stats=stats, status=status,
                   conditions=conditions)  # fmt: skip
    if pt is not None and problem is not None:
        sol.forces, sol.motion = pt.forces, pt.motion
        sol.hand_motion, sol.actuator_forces = pt.hand_motion, pt.actuator_forces
        sol.hand_reference = problem.hand_reference
        sol.states = problem.states(pt)
        stats["at_bound"] = pt.at_bound
    return sol


def stopped(method: str, grasp: Grasp, query: Query, stats: dict[str, Any], e: Stop) -> Solution:
    stats["message"] = e.message
    return Solution(None, method, grasp, query, stats=stats, status=e.status)


def bounds_stats(bounds: ExactBounds, stats: dict[str, Any]) -> None:
    """Record the model's force bound and the force scale it came from in ``stats``."""
    stats["force_bound"] = bounds.force
    stats["force_scale"] = bounds.scale


__all__ = ["CONDITIONS", "DEFAULT_BACKENDS", "HAND_CONDITIONS", "MipOptions", "Stop",
           "bounds_stats", "default_backend", "run", "solution", "stopped"]  # fmt: skip
