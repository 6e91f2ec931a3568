"""Query types: what a solver is asked about a grasp.

Wrenches are ``(fx, fy, tz)`` for planar grasps and ``(fx, fy, fz, tx, ty, tz)``
for spatial ones, applied to the object about the object-frame origin, in N and
N m. A preload ``p_i >= 0`` [N] pre-stresses the unit virtual spring at contact
``i``: ``c_n = max(0, p - d_n)`` (thesis eq. normal_compliance). ``commands``
are actuator forces for hands with a transmission ``R`` (chapter 5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GraspError

__all__ = [
    "Existence",
    "MaxDisturbance",
    "OptimalCommands",
    "Query",
    "checked_base",
    "checked_direction_cap",
]


@dataclass(frozen=True)
class Existence:
    """Is there an equilibrium of the grasp model under external wrench ``wrench``?

    Stable means: a motion and contact forces exist that satisfy equilibrium
    ``G c + w = 0``, the spring law, Coulomb friction and maximum dissipation.
    """

    wrench: ArrayLike
    preload: float | ArrayLike | None = None
    commands: ArrayLike | None = None


@dataclass(frozen=True)
class MaxDisturbance:
    """Largest ``s >= 0`` such that ``w = base + s * direction`` is stable (``value``).

    ``cap`` bounds the search: a result equal to ``cap`` means "at least cap"
    and is flagged ``stats["capped"] = True``. ``base`` (default zero) is a wrench that is
    always applied, in the grasp's wrench frame and units like ``direction``: e.g. the
    object's weight (``ihm.contacts.SceneGrasp.gravity_wrench``). When ``base`` alone is
    not stable the answer is unstable.
    """

    direction: ArrayLike
    preload: float | ArrayLike | None = None
    commands: ArrayLike | None = None
    cap: float = 1e3
    base: ArrayLike | None = None


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
