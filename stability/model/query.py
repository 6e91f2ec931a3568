"""A query of the 3D methods, validated once: :class:`QueryData`, and its statement on an
:class:`~stability.model.problem.ExactProblem` (:func:`add_query`, :func:`query_value`).

One class for every query: ``Existence`` (``wrench``), ``MaxDisturbance`` (``direction``,
``cap``, ``base``) and ``OptimalCommands`` (``wrench``, ``command_range``, ``objective``,
``weights``, ``max_normal_force``); all carry the per-contact ``preload`` [N] and the hand
``(R, f_c)`` (None for a rigid fixture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import GraspError
from ..grasp import Grasp
from ..mip import INF
from ..queries import (
    Existence,
    MotionLimit,
    OptimalCommands,
    checked_base,
    checked_direction_cap,
    checked_motion_limit,
)
from .problem import ExactPoint, ExactProblem, actuator_vector, hand_data, scale_bounds

__all__ = ["QueryData", "add_query", "query_value"]


@dataclass
class QueryData:
    """A validated query: ``wrench`` (Existence, OptimalCommands) or ``direction`` and
    ``cap`` (MaxDisturbance, with ``base`` the wrench always applied), ``preload`` (m,),
    ``hand`` ``(R, f_c)``; for OptimalCommands also ``command_range`` ``(lower, upper)``
    per actuator, ``objective`` (``"max"`` or ``"weighted"``), ``weights`` and
    ``max_normal_force``; ``motion_limit`` the validated :class:`MotionLimit` (Existence,
    MaxDisturbance) or None."""

    wrench: NDArray[np.float64] | None
    direction: NDArray[np.float64] | None
    cap: float
    preload: NDArray[np.float64]
    hand: tuple[NDArray[np.float64], NDArray[np.float64]] | None
    base: NDArray[np.float64] | None = None  # MaxDisturbance: the wrench always applied
    command_range: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    objective: str | None = None
    weights: NDArray[np.float64] | None = None
    max_normal_force: float | None = None
    motion_limit: MotionLimit | None = None

    @property
    def wrench_max(self) -> NDArray[np.float64]:
        """Per component the largest magnitude the query's wrench takes: ``wrench``
        (Existence, OptimalCommands), else ``max(|base|, |base + cap direction|)``."""
        if self.direction is None:
            return self.wrench
        base = np.zeros_like(self.direction) if self.base is None else self.base
        return np.maximum(np.abs(base), np.abs(base + self.cap * self.direction))

    @classmethod
    def of(cls, grasp: Grasp, query: Any, bound_factor: float = 100.0) -> QueryData:
        """The data of ``query`` on ``grasp``; GraspError for data that do not fit.
        ``bound_factor``: OptimalCommands without ``upper`` bounds the commands by the
        excess bound of :func:`~stability.model.problem.scale_bounds` at this factor."""
        if isinstance(query, OptimalCommands):
            return cls._optimal_commands(grasp, query, bound_factor)
        preload = grasp.per_contact(query.preload, "preload", nonneg=False)  # < 0: a gap
        hand = hand_data(grasp, query.commands)
        limit = checked_motion_limit(grasp, query)
        if isinstance(query, Existence):
            return cls(grasp.wrench(query.wrench), None, 0.0, preload, hand, motion_limit=limit)
        d, cap = checked_direction_cap(grasp, query)
        return cls(None, d, cap, preload, hand, checked_base(grasp, query), motion_limit=limit)

    @classmethod
    def _optimal_commands(
        cls, grasp: Grasp, query: OptimalCommands, bound_factor: float
    ) -> QueryData:
        if grasp.J is None:
            raise GraspError("OptimalCommands needs a hand: set J (and R) on the Grasp")
        wrench = grasp.wrench(query.wrench)
        preload = grasp.per_contact(query.preload, "preload", nonneg=False)  # < 0: a gap
        R, _ = hand_data(grasp, None)
        a = R.shape[1]
        lower = _per_actuator(query.lower, a, "lower", 0.0)
        if np.any(lower < 0):
            raise GraspError(f"OptimalCommands lower must be >= 0, got {lower}")
        if query.upper is None:  # a bound from the wrench's own scale
            b = scale_bounds(grasp, wrench, preload, (R, np.zeros(a)), bound_factor)
            upper = np.maximum(b.excess, lower)
        else:
            upper = _per_actuator(query.upper, a, "upper", 0.0)
        if np.any(upper < lower):
            raise GraspError(f"OptimalCommands upper {upper} below lower {lower}")
        if query.objective not in ("max", "weighted"):
            raise GraspError(
                f"OptimalCommands objective must be 'max' or 'weighted', got {query.objective!r}"
            )
        weights = _per_actuator(query.weights, a, "weights", 1.0)
        if np.any(weights < 0):
            raise GraspError(f"OptimalCommands weights must be >= 0, got {weights}")
        nmax = query.max_normal_force
        if nmax is not None:
            nmax = float(nmax)
            if not (math.isfinite(nmax) and nmax > 0):
                raise GraspError(f"max_normal_force must be finite and > 0 N, got {nmax!r}")
        scale_cmd = upper if query.upper is not None else np.zeros(a)  # for scale_bounds only
        return cls(wrench, None, 0.0, preload, (R, scale_cmd), command_range=(lower, upper),
                   objective=query.objective, weights=weights,
                   max_normal_force=nmax)  # fmt: skip


def _per_actuator(v: Any, a: int, name: str, default: float) -> NDArray[np.float64]:
    return actuator_vector(v, a, f"OptimalCommands {name}", default)


def add_query(prob: ExactProblem, data: QueryData) -> int | None:
    """Object equilibrium, the query's motion limit and its objective on ``prob``: the index
    of ``s`` (MaxDisturbance), of the largest command (OptimalCommands "max"), -1
    (OptimalCommands "weighted": the objective is ``weights . f_c``) or None (Existence)."""
    M = prob.model
    var = None
    if data.motion_limit is not None:
        prob.limit_motion(data.motion_limit)
    if data.direction is not None:
        base = 0.0 * data.direction if data.base is None else data.base
        var = prob.add_object_equilibrium(base, data.direction, data.cap)
        M.set_objective([var], [1.0], maximize=True)
    else:
        prob.add_object_equilibrium(data.wrench)
        if data.command_range is not None:
            fc = prob.fc
            if data.objective == "max":
                var = M.add_var(0.0, float(data.command_range[1].max()), "C", "max_command")
                for j in fc:  # t >= f_c,j
                    M.add_row([var, int(j)], [1.0, -1.0], 0.0, INF)
                M.set_objective([var], [1.0])
            else:
                var = -1
                M.set_objective(fc, data.weights)
    return var


def query_value(model: Any, pt: ExactPoint, var: int | None, data: QueryData) -> float | None:
    """The query's value at ``pt`` (``model.prob`` the ExactProblem ``var`` came from):
    ``s`` (MaxDisturbance, clipped to ``[0, cap]``), the largest or weighted commands
    (OptimalCommands), None (Existence)."""
    if var is None:
        return None
    if data.direction is not None:
        return float(min(data.cap, max(0.0, pt.x[var])))
    if var == -1:
        return float(data.weights @ pt.x[model.prob.fc])
    return float(pt.x[model.prob.fc].max(initial=0.0))
