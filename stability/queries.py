"""Query types: what a solver is asked about a grasp.

Wrenches are ``(fx, fy, tz)`` for planar grasps and ``(fx, fy, fz, tx, ty, tz)`` for
spatial ones, applied to the object about the object-frame origin, in N and N m. A
preload ``p_i >= 0`` [N] pre-stresses the unit virtual spring at contact ``i``: ``c_n =
max(0, p - d_n)`` (thesis eq. normal_compliance). ``modesearch``, ``refinement``,
``exact`` and ``no_mdp`` also take ``p_i < 0``, a gap (our extension): the contact
closes only after the object has moved ``-p_i / k_i`` towards it (``d_n <= p_i / k_i``);
``planar``, ``gws`` and ``iterative`` refuse it. ``commands`` are actuator forces for
hands with a transmission ``R`` (chapter 5). ``motion_limit`` (:class:`MotionLimit`, our
extension) asks for an equilibrium whose object motion stays within a bound, as a
simulated ramp stops at a set displacement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GraspError

__all__ = [
    "Existence",
    "MaxDisturbance",
    "MotionLimit",
    "OptimalCommands",
    "Query",
    "checked_base",
    "checked_direction_cap",
    "checked_motion_limit",
]


@dataclass(frozen=True)
class MotionLimit:
    """The object motion an equilibrium may have: the displacement of ``point`` at most
    ``shift`` and the rotation at most ``turn`` (Euclidean norms of the small-motion model's
    ``v + omega x point`` and ``omega``; planar: ``|theta|``).

    Units are the grasp's: with physical stiffness (``Grasp(..., stiffness=...)`` in N/m)
    ``shift`` is in m and ``turn`` in rad, as a simulator's stop rule; with the thesis' unit
    springs a motion is measured in newtons of spring force. ``point`` (object frame, default
    the origin) is where the displacement is measured, e.g. the centre of mass. ``inf``
    leaves a part free. ``open`` (optional, (m,) booleans): contacts that must stay open,
    ``c_n = 0`` and so ``k d_n >= p`` (a simulator's stop on a new contact: a gapped contact,
    preload ``p < 0``, that may not close). Our extension of the thesis' model (module
    :mod:`stability.model.problem`, "motion limit")."""

    shift: float = math.inf
    turn: float = math.inf
    point: ArrayLike | None = None
    open: ArrayLike | None = None


@dataclass(frozen=True)
class Existence:
    """Is there an equilibrium of the grasp model under external wrench ``wrench``?

    Stable means: a motion and contact forces exist that satisfy equilibrium
    ``G c + w = 0``, the spring law, Coulomb friction and maximum dissipation.
    """

    wrench: ArrayLike
    preload: float | ArrayLike | None = None
    commands: ArrayLike | None = None
    motion_limit: MotionLimit | None = None


@dataclass(frozen=True)
class MaxDisturbance:
    """Largest ``s >= 0`` such that ``w = base + s * direction`` is stable (``value``).

    ``cap`` bounds the search: a result equal to ``cap`` means "at least cap"
    and is flagged ``stats["capped"] = True``. ``base`` (default zero) is a wrench that is
    always applied, in the grasp's wrench frame and units like ``direction``: e.g. the
    object's weight (``ihm.contacts.SceneGrasp.gravity_wrench``). When ``base`` alone is
    not stable the answer is unstable. ``motion_limit``: the largest ``s`` whose
    equilibrium moves the object within the limit (:class:`MotionLimit`).
    """

    direction: ArrayLike
    preload: float | ArrayLike | None = None
    commands: ArrayLike | None = None
    cap: float = 1e3
    base: ArrayLike | None = None
    motion_limit: MotionLimit | None = None


@dataclass(frozen=True)
class OptimalCommands:
    """Actuator commands ``f_c`` that make ``wrench`` stable at least cost (chapter 6).

    ``objective="max"`` (the thesis'): minimise the largest command ``max_j f_c,j``;
    ``"weighted"``: minimise ``weights . f_c`` (default weights: ones, the sum).
    ``lower``/``upper`` bound the commands per actuator [N or N m] (default ``0`` and a
    bound from the problem's force scale, flagged ``at_bound`` when reached);
    ``max_normal_force`` [N] caps every contact normal force (not to crush the object).
    ``value`` is the optimal cost and ``Solution.commands`` the commands.
    """

    wrench: ArrayLike
    preload: float | ArrayLike | None = None
    lower: ArrayLike | None = None
    upper: ArrayLike | None = None
    weights: ArrayLike | None = None
    objective: str = "max"
    max_normal_force: float | None = None


Query = Existence | MaxDisturbance | OptimalCommands


def checked_direction_cap(grasp, query: MaxDisturbance) -> tuple[NDArray[np.float64], float]:
    """Validated ``(direction, cap)`` of a MaxDisturbance query: non-zero finite direction of
    the grasp's wrench size, finite ``cap > 0``; :class:`GraspError` otherwise."""
    d = grasp.wrench(query.direction, "direction")
    if not np.any(d != 0.0):
        raise GraspError("MaxDisturbance direction must be non-zero")
    try:
        cap = float(query.cap)
    except (TypeError, ValueError) as exc:
        raise GraspError(f"MaxDisturbance cap must be a number, got {query.cap!r}") from exc
    if not (np.isfinite(cap) and cap > 0):
        raise GraspError(f"MaxDisturbance cap must be finite and > 0, got {query.cap!r}")
    return d, cap


def checked_base(grasp, query: MaxDisturbance) -> NDArray[np.float64]:
    """The validated ``base`` wrench of a MaxDisturbance query (zeros when None)."""
    if query.base is None:
        return np.zeros(grasp.wrench_dim)
    return grasp.wrench(query.base, "base")


def checked_motion_limit(grasp, query: Query) -> MotionLimit | None:
    """The query's :class:`MotionLimit` validated (``shift``, ``turn`` > 0 or inf, ``point``
    a finite point of the grasp's dimension, returned as an array; ``open`` (m,) booleans,
    returned as an array, all False when not given), or None when it has none;
    :class:`GraspError` otherwise."""
    lim = getattr(query, "motion_limit", None)
    if lim is None:
        return None
    if not isinstance(lim, MotionLimit):
        raise GraspError(f"motion_limit must be a stability.MotionLimit, got {type(lim).__name__}")
    try:
        shift, turn = float(lim.shift), float(lim.turn)
    except (TypeError, ValueError) as exc:
        raise GraspError(f"MotionLimit shift and turn must be numbers, got {lim!r}") from exc
    if not (shift > 0 and turn > 0) or math.isnan(shift) or math.isnan(turn):
        raise GraspError(f"MotionLimit shift and turn must be > 0 (inf: free), got {lim!r}")
    point = np.zeros(grasp.dim) if lim.point is None else np.array(lim.point, dtype=float)
    if point.shape != (grasp.dim,) or not np.all(np.isfinite(point)):
        raise GraspError(f"MotionLimit point must be {grasp.dim} finite numbers (object "
                         f"frame), got {lim.point!r}")  # fmt: skip
    if lim.open is None:
        keep = np.zeros(grasp.m, dtype=bool)
    else:
        keep = np.asarray(lim.open)
        if keep.shape != (grasp.m,) or keep.dtype != bool:
            raise GraspError(f"MotionLimit open must be {grasp.m} booleans (one per contact), "
                             f"got {lim.open!r}")  # fmt: skip
    return MotionLimit(shift, turn, point, keep.copy())
