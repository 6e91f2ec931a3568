"""Query types: what a solver is asked about a grasp.

Wrenches are ``(fx, fy, tz)`` for planar grasps and ``(fx, fy, fz, tx, ty, tz)``
for spatial ones, applied to the object about the object-frame origin, in N and
N m. A preload ``p_i >= 0`` [N] pre-stresses the unit virtual spring at contact
``i``: ``c_n = max(0, p - d_n)`` (thesis eq. normal_compliance). ``commands``
are actuator forces for hands with a transmission ``R`` (chapter 5).
"""

from __future__ import annotations

from dataclasses import dataclass

from numpy.typing import ArrayLike

__all__ = ["Existence", "MaxDisturbance", "OptimalCommands", "Query"]


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
    """Largest ``s >= 0`` such that ``w = s * direction`` is stable (``value``).

    ``cap`` bounds the search: a result equal to ``cap`` means "at least cap"
    and is flagged ``stats["capped"] = True``.
    """

    direction: ArrayLike
    preload: float | ArrayLike | None = None
    commands: ArrayLike | None = None
    cap: float = 1e3


@dataclass(frozen=True)
class OptimalCommands:
    """Actuator commands that make ``wrench`` stable at least cost (chapter 6).

    ``lower``/``upper`` bound the commands [N or N m per actuator]; the cost is
    ``weights . f`` (default: the sum of commands).
    """

    wrench: ArrayLike
    preload: float | ArrayLike | None = None
    lower: ArrayLike | None = None
    upper: ArrayLike | None = None
    weights: ArrayLike | None = None


Query = Existence | MaxDisturbance | OptimalCommands
