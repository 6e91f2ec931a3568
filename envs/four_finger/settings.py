"""The settings of the four-finger rotation env, in groups: what :class:`FourFingerRotate`
takes, and what a trainer keeps in its config and passes to the env as they are.

- :class:`RewardSettings`: the reward's terms (env module doc, "Rewards");
- :class:`SimSettings`: the simulation: gravity, torsional friction, timestep, substeps per
  policy step, solver and the actuators' setpoint step;
- :class:`StartSettings`: where episodes start: the grasp set and cache size, the grip,
  failure replay and turned cube starts;
- :class:`ObservationSettings`: the observed frames and the critic's privileged state;
- :class:`RenderSettings`: the camera and image size of ``render()``.

The randomised physics has its own group, :class:`envs.four_finger.Randomization` (drawn per
episode), beside the fixed :class:`envs.four_finger.PhysicsSample`. Each group checks its
values when it is made (:class:`FourFingerError` naming the field) and keeps them as plain
Python numbers (``int`` weights become ``float``, ``numpy`` integers ``int``);
:func:`apply_overrides` sets fields of the groups by name (``drop_weight=1.0``,
``gravity=False``): the env's ``**overrides``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from envs.four_finger.cache import GRASP_SETS, GRIPS
from envs.four_finger.physics import FRAME_SKIP, SOLVERS, TIMESTEP, FourFingerError

__all__ = [
    "HEIGHT_FROM",
    "ObservationSettings",
    "RenderSettings",
    "RewardSettings",
    "SimSettings",
    "StartSettings",
    "apply_overrides",
]

HEIGHT_FROM = ("hold", "start")  # the height term's references: HOLD_Z, the start height


def _probability(group: Any, name: str) -> None:
    """Check that field ``name`` of ``group`` is a probability; store it as a float."""
    v = getattr(group, name)
    if not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
        raise FourFingerError(f"{name} must be in [0, 1], got {v!r}")
    object.__setattr__(group, name, float(v))


def _whole(group: Any, name: str) -> None:
    """Check that field ``name`` of ``group`` is an integer >= 1; store it as an int."""
    v = getattr(group, name)
    if not isinstance(v, (int, np.integer)) or v < 1:
        raise FourFingerError(f"{name} must be an integer >= 1, got {v!r}")
    object.__setattr__(group, name, int(v))


def _weight(group: Any, name: str) -> None:
    """Check that field ``name`` of ``group`` is a finite number >= 0; store it as a float."""
    v = getattr(group, name)
    if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
        raise FourFingerError(f"{name} must be a finite number >= 0, got {v!r}")
    object.__setattr__(group, name, float(v))


@dataclass(frozen=True)
class RewardSettings:
    """The reward ``rotation + drop + action + height + slip + tilt`` (env module doc,
    "Rewards"). The defaults are the thesis' reward: the uncapped rotation rate alone.

    ``rotation_cap`` [rad/s] bounds the rotation term (``inf``: none). Weights, all >= 0:
    ``drop_weight`` (the step that drops the object), ``action_weight`` (``|a|^2 / 12``),
    ``height_weight`` (the sag as a fraction of the way to the drop height, from the
    reference ``height_from``: ``"hold"``, ``HOLD_Z``, or ``"start"``, the start height),
    ``slip_weight`` (per m/s of mean contact sliding speed) and ``tilt_weight`` (per rad of
    tilt since the episode's start)."""

    rotation_cap: float = math.inf
    drop_weight: float = 0.0
    action_weight: float = 0.0
    height_weight: float = 0.0
    height_from: str = "hold"
    slip_weight: float = 0.0
    tilt_weight: float = 0.0

    def __post_init__(self) -> None:
        for name in ("drop_weight", "action_weight", "height_weight", "slip_weight", "tilt_weight"):
            _weight(self, name)
        cap = self.rotation_cap
        if not isinstance(cap, (int, float)) or math.isnan(cap) or cap <= 0:
            raise FourFingerError(f"rotation_cap must be > 0 (inf: no cap), got {cap!r}")
        object.__setattr__(self, "rotation_cap", float(cap))
        if self.height_from not in HEIGHT_FROM:
            raise FourFingerError(
                f"height_from must be one of {HEIGHT_FROM}, got {self.height_from!r}"
            )


@dataclass(frozen=True)
class SimSettings:
    """The simulation: ``gravity`` on (-9.81 m/s^2 along -z) or off; ``torsional`` friction
    at the object's contacts (``condim`` 4; off: point contacts, env class doc); the physics
    ``timestep`` [s] and ``frame_skip`` substeps per policy step (policy period
    ``dt = frame_skip * timestep``, :attr:`dt`); the MuJoCo constraint ``solver``
    (``"pgs"`` or ``"newton"``); ``max_setpoint_step``, the servo setpoints' change per
    policy step at a full action [rad] (``q^max`` of the thesis)."""

    gravity: bool = True
    torsional: bool = True
    timestep: float = TIMESTEP
    frame_skip: int = FRAME_SKIP
    solver: str = "pgs"
    max_setpoint_step: float = 0.05

    def __post_init__(self) -> None:
        if not isinstance(self.gravity, (bool, np.bool_)):
            raise FourFingerError(f"gravity must be True or False, got {self.gravity!r}")
        object.__setattr__(self, "gravity", bool(self.gravity))
        object.__setattr__(self, "torsional", bool(self.torsional))
        for name in ("max_setpoint_step", "timestep"):
            _weight(self, name)
        if self.max_setpoint_step <= 0 or self.timestep <= 0:
            raise FourFingerError("max_setpoint_step and timestep must be > 0")
        _whole(self, "frame_skip")
        if self.solver not in SOLVERS:
            raise FourFingerError(
                f"unknown solver {self.solver!r}; choose one of {', '.join(SOLVERS)}"
            )

    @property
    def dt(self) -> float:
        """The policy period ``frame_skip * timestep`` [s]."""
        return self.frame_skip * self.timestep


@dataclass(frozen=True)
class StartSettings:
    """Where episodes start (env module doc, "Starting State", "Failure replay", "Turned cube
    starts"): the start-grasp set ``grasps`` (``"train"`` or ``"test"``, held out) of
    ``n_grasps`` cached grasps made with the ``grip`` (``"nominal"`` or ``"firm"``:
    :data:`envs.four_finger.GRIPS`); ``replay_prob``, the probability that a reset restarts a
    start this env dropped; ``turned_prob``, the probability that a reset starts from a cube
    turned >= 22.5 degrees (the cube only)."""

    grasps: str = "train"
    n_grasps: int = 256
    grip: str = "nominal"
    replay_prob: float = 0.0
    turned_prob: float = 0.0

    def __post_init__(self) -> None:
        _probability(self, "replay_prob")
        _probability(self, "turned_prob")
        _whole(self, "n_grasps")
        if self.grasps not in GRASP_SETS:
            raise FourFingerError(f"grasps must be one of {list(GRASP_SETS)}, got {self.grasps!r}")
        if self.grip not in GRIPS:
            raise FourFingerError(f"grip must be one of {list(GRIPS)}, got {self.grip!r}")

    def for_object(self, object: str) -> StartSettings:
        """``self`` once its starts fit ``object`` (turned starts are the cube's); else
        :class:`FourFingerError`."""
        if self.turned_prob > 0 and object != "cube":
            raise FourFingerError(f"turned_prob is for the cube, not the {object}")
        return self


@dataclass(frozen=True)
class ObservationSettings:
    """What the policy observes (env module doc, "Observation Space"): the last ``history``
    frames, oldest first, and with ``privileged`` the critic's privileged state after them
    (the object's pose and velocity and the episode's physics)."""

    history: int = 1
    privileged: bool = False

    def __post_init__(self) -> None:
        _whole(self, "history")
        object.__setattr__(self, "privileged", bool(self.privileged))


@dataclass(frozen=True)
class RenderSettings:
    """``render()``'s image, ``width`` x ``height`` [px], from the ``camera`` ``"side"``
    (45 degrees around, 20 degrees down) or ``"top"``."""

    width: int = 480
    height: int = 480
    camera: str = "side"

    def __post_init__(self) -> None:
        if self.camera not in ("side", "top"):
            raise FourFingerError(f"camera must be 'side' or 'top', got {self.camera!r}")


def apply_overrides(groups: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``groups`` (name -> settings dataclass) with each of ``overrides`` (field name ->
    value) set in the group that has that field (a group without overrides is kept as it
    is); TypeError for a name no group has. A field name belongs to one group only."""
    where = {f.name: g for g, s in groups.items() for f in dataclasses.fields(s)}
    unknown = sorted(set(overrides) - set(where))
    if unknown:
        raise TypeError(f"unexpected keyword argument(s) {', '.join(map(repr, unknown))}")
    changed: dict[str, dict[str, Any]] = {}
    for k, v in overrides.items():
        changed.setdefault(where[k], {})[k] = v
    return {
        g: dataclasses.replace(s, **changed[g]) if g in changed else s for g, s in groups.items()
    }
