"""One entry point, many methods: ``solve(grasp, query, method=...)``.

Methods register themselves with :func:`register`, declaring which query types
and grasp kinds they answer, like ``qpsolvers.solve_qp(..., solver=...)``. A renamed
method keeps its old name as an alias that warns (:data:`RENAMED_METHODS`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import GraspError, MethodError
from .grasp import Grasp
from .options import MethodOptions
from .queries import Existence, MaxDisturbance, OptimalCommands, Query, checked_motion_limit
from .solution import Solution

__all__ = [
    "solve",
    "register",
    "available_methods",
    "method_info",
    "MethodInfo",
    "RENAMED_METHODS",
    "DEFAULT_SPATIAL_METHOD",
    "in_motion_unit",
    "motion_unit",
]


@dataclass(frozen=True)
class MethodInfo:
    """What a registered method can answer."""

    name: str
    fn: Callable[..., Solution]
    queries: tuple[type, ...]
    planar: bool
    spatial: bool
    hand: bool  # answers grasps with a hand model (J, R) and commands
    summary: str
    options: type[MethodOptions]  # its options, checked once by solve()
    compliance: bool = False  # models contact and actuator stiffness and stop gaps
    motion_limit: bool = False  # answers queries with a MotionLimit

    def refuses(self, grasp: Grasp, query: Query) -> str | None:
        """Why this method cannot answer, or None when it can."""
        if not isinstance(query, self.queries):
            return f"does not answer {type(query).__name__} queries"
        if grasp.planar and not self.planar:
            return "does not handle planar grasps"
        if not grasp.planar and not self.spatial:
            return "handles planar grasps only"
        has_hand = grasp.J is not None or getattr(query, "commands", None) is not None
        if has_hand and not self.hand:
            return "models a rigid hand only (no J, R or actuator commands)"
        if grasp.compliant and not self.compliance:
            return ("models unit contact springs and rigid transmissions only (this grasp "
                    "has stiffness or stop gaps)")  # fmt: skip
        if getattr(query, "motion_limit", None) is not None and not self.motion_limit:
            return "does not bound the object's motion (the query has a motion_limit)"
        return None


_METHODS: dict[str, MethodInfo] = {}

# the method ``solve(..., method=None)`` uses for spatial grasps (planar ones: "planar"):
# measured faster than "refinement" with answers as good (docs/bench/stability.md#grasps)
DEFAULT_SPATIAL_METHOD = "modesearch"

# old method name -> new one: ``solve(..., method=old)`` still works, with a DeprecationWarning
RENAMED_METHODS = {"spatial": "exact"}


def register(
    name: str,
    queries: tuple[type, ...],
    planar: bool,
    spatial: bool,
    options: type[MethodOptions],
    hand: bool = False,
    summary: str = "",
    compliance: bool = False,
    motion_limit: bool = False,
) -> Callable[[Callable[..., Solution]], Callable[..., Solution]]:
    """Decorator: add a solver function ``fn(grasp, query, opts, deadline) -> Solution``
    whose options are the frozen dataclass ``options`` (:class:`MethodOptions`):
    :func:`solve` builds them from its keyword arguments and starts the
    :class:`~stability.options.Deadline` of their ``time_limit``. ``compliance``: the
    method models ``Grasp.stiffness``, ``actuator_stiffness`` and ``stop_gap`` (others
    refuse a grasp that sets them); ``motion_limit``: it honours a query's
    :class:`~stability.queries.MotionLimit` (others refuse such a query)."""

    def deco(fn: Callable[..., Solution]) -> Callable[..., Solution]:
        _METHODS[name] = MethodInfo(
            name, fn, queries, planar, spatial, hand, summary, options, compliance, motion_limit
        )
        return fn

    return deco


def available_methods(grasp: Grasp | None = None, query: Query | None = None) -> list[str]:
    """Names of registered methods, optionally only those that can answer ``query`` on ``grasp``."""
    if grasp is None or query is None:
        return sorted(_METHODS)
    return sorted(n for n, info in _METHODS.items() if info.refuses(grasp, query) is None)


def method_info(name: str) -> MethodInfo:
    """The registered method ``name`` (what it answers, its solver function); MethodError if
    none is registered under that name."""
    info = _METHODS.get(name)
    if info is None:
        raise MethodError(f"unknown method {name!r}; registered: {sorted(_METHODS)}")
    return info


def solve(grasp: Grasp, query: Query, method: str | None = None, **options: Any) -> Solution:
    """Answer ``query`` about ``grasp`` with ``method``.

    ``method=None`` picks ``"planar"`` for planar grasps, :data:`DEFAULT_SPATIAL_METHOD`
    (``"modesearch"``) for spatial ones; an old name of :data:`RENAMED_METHODS`
    (``"spatial"``, now ``"exact"``) still works and emits a ``DeprecationWarning``.
    ``options`` are the method's (``method_info(method).options``, a frozen dataclass),
    checked once here. ``stats["time_s"]`` is the wall time of the method call [s].

    Raises
    ------
    MethodError
        Unknown method, or one that cannot answer this query on this grasp (the message
        names the methods that can); an unknown option or one of the wrong type (the
        message lists the method's options).
    GraspError
        Invalid query data (shapes, NaN, negative preload, ...) or an option out of its
        range.
    """
    if not isinstance(grasp, Grasp):
        raise GraspError(f"grasp must be a stability.Grasp, got {type(grasp).__name__}")
    if not isinstance(query, Existence | MaxDisturbance | OptimalCommands):
        raise GraspError(
            "query must be Existence, MaxDisturbance or OptimalCommands, "
            f"got {type(query).__name__}"
        )
    if method is None:
        method = "planar" if grasp.planar else DEFAULT_SPATIAL_METHOD
    if method in RENAMED_METHODS:
        new = RENAMED_METHODS[method]
        warnings.warn(
            f"method {method!r} is deprecated: it is called {new!r} now "
            f"(solve(..., method={new!r}))",
            DeprecationWarning,
            stacklevel=2,
        )
        method = new
    info = _METHODS.get(method)
    able = available_methods(grasp, query)
    if info is None:
        raise MethodError(
            f"unknown method {method!r}; methods that can answer this "
            f"{type(query).__name__} query: {able or 'none yet'} (registered: {sorted(_METHODS)})"
        )
    reason = info.refuses(grasp, query)
    if reason is not None:
        raise MethodError(
            f"method {method!r} {reason}; methods that can answer this "
            f"{type(query).__name__} query on this grasp: {able or 'none yet'}"
        )
    opts = info.options.of(method, options)
    t0 = time.perf_counter()
    unit = motion_unit(grasp) if info.compliance else 1.0
    if unit == 1.0:
        sol = info.fn(grasp, query, opts, opts.deadline())
    else:
        sol = info.fn(in_motion_unit(grasp, unit), query_in_motion_unit(grasp, query, unit), opts,
                      opts.deadline())  # fmt: skip
        sol = replace(sol, grasp=grasp, query=query, motion=_times(sol.motion, 1.0 / unit),
                      hand_motion=_times(sol.hand_motion, 1.0 / unit),
                      hand_reference=_times(sol.hand_reference, 1.0 / unit))  # fmt: skip
    sol.stats["time_s"] = time.perf_counter() - t0
    return _answer_or_error(sol)


def motion_unit(grasp: Grasp) -> float:
    """The length the 3D methods measure motions in, as a stiffness ``k_u`` [N/m]: the
    median contact stiffness (1 for the thesis' unit springs). A motion of ``1 / k_u`` m
    loads a typical contact by 1 N, so a grasp in physical units (``k`` of 1e3-1e5 N/m,
    motions of 1e-4 m) reaches the solvers at the scale of the unit model, where their
    absolute tolerances (1e-9) are meant."""
    return float(np.median(grasp.stiffness))


def in_motion_unit(grasp: Grasp, unit: float) -> Grasp:
    """``grasp`` with motions measured in ``1 / unit`` m: stiffness divided by ``unit``,
    stop gaps times it. The forces of every equilibrium are the same; its motions are
    ``unit`` times the physical ones."""
    K, gap = (None, None) if grasp.J is None else (grasp.actuator_stiffness / unit,
                                                   grasp.stop_gap * unit)  # fmt: skip
    return Grasp(grasp.points, grasp.normals, grasp.mu, None if grasp.planar else grasp.tangents,
                 grasp.J, grasp.R, grasp.backdrivable, grasp.stiffness / unit, K,
                 gap)  # fmt: skip


def query_in_motion_unit(grasp: Grasp, query: Query, unit: float) -> Query:
    """``query`` with its motion limit (if any, validated on ``grasp``) in motions of
    ``1 / unit`` m, as :func:`in_motion_unit` measures them: ``shift`` and ``turn`` times
    ``unit``."""
    lim = checked_motion_limit(grasp, query)
    if lim is None:
        return query
    return replace(query, motion_limit=replace(lim, shift=lim.shift * unit, turn=lim.turn * unit))


def _times(x: NDArray[np.float64] | None, factor: float) -> NDArray[np.float64] | None:
    return None if x is None else np.asarray(x, dtype=float) * factor


def _answer_or_error(sol: Solution) -> Solution:
    """Every method's answer passes here: a ``"solved"`` answer says stable or not, and a
    stable answer of an optimisation query (MaxDisturbance, OptimalCommands) has a finite
    ``value``. Anything else is turned into ``status="error"`` (``stable=None``,
    ``stats["message"]`` says what was missing), never passed on as an answer; the
    method's point, if any, is kept for inspection."""
    if sol.status != "solved":
        return sol
    problem = None
    if sol.stable is None:
        problem = "status 'solved' without a stable/unstable answer"
    elif sol.stable and isinstance(sol.query, MaxDisturbance | OptimalCommands):
        v = sol.value
        try:
            finite = v is not None and math.isfinite(float(v))
        except (TypeError, ValueError):
            finite = False
        if not finite:
            problem = f"a stable {type(sol.query).__name__} answer without a value ({v!r})"
    if problem is not None:
        sol.stats["message"] = f"method {sol.method!r} returned {problem}"
        sol.stats["unchecked_status"] = sol.status
        sol.status, sol.stable = "error", None
    return sol
