"""Nonbackdrivable joints and transmissions in simulation: a limit that follows the joint.

A real Barrett BH-280 finger is driven through a worm gear: the motor can close it, an
external load cannot open it (thesis sec. 5, "passive reactions"). MuJoCo's motors are
backdrivable. :class:`Ratchet` gives chosen joints a one-sided limit at their current
position, in the opening direction only, and moves that limit with the joint whenever the
joint has closed further (:meth:`Ratchet.update`, called after each ``mj_step``; or
:meth:`Ratchet.step`). So:

* the commanded actuator force can drive the joint closed (the limit only acts in the
  opening direction);
* an external load cannot drive it open beyond the position it last reached: the limit
  carries the load as a constraint force, which is the passive reaction of the thesis.

"Closed" is the direction of positive actuator force (the hands' convention: positive
torque closes); ``sign=-1`` flips it. The limit is made stiff: ``solref`` with time
constant ``2 * timestep`` (the smallest that MuJoCo's ``refsafe`` allows) and damping ratio
1, ``solimp`` 0.99/0.999: on the analytic pinch (``assets/analytic/pinch.xml``, 1 ms) an
opening load of 0.5 N m on an unpowered finger gives way by 1.4e-4 rad, where without the
ratchet the finger swings open (tests/ihm/test_resistance.py). Coupled joints (the Barrett
distal joints, tied to the proximal by an equality) are held through their coupling and
need no ratchet of their own.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

__all__ = ["Ratchet", "RatchetError", "actuated_joints", "actuated_tendons"]


def actuated_tendons(model: mujoco.MjModel) -> list[int]:
    """Tendon ids driven by a tendon-transmission actuator (the tendon gripper's)."""
    return [
        int(model.actuator_trnid[a, 0])
        for a in range(model.nu)
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON
    ]


class RatchetError(GraspError):
    """A ratchet asked of a joint that cannot have one (not a hinge or slide, unknown)."""


def actuated_joints(model: mujoco.MjModel, kind: str = "motor") -> list[int]:
    """Joint ids driven by a joint-transmission actuator with no position feedback
    (``kind="motor"``: gain only, bias 0): the backdrivable ones."""
    out = []
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        if kind == "motor" and np.any(model.actuator_biasprm[a, :3] != 0):
            continue  # a servo (position feedback): not a plain motor
        out.append(int(model.actuator_trnid[a, 0]))
    return out


_FIELDS = {  # kind: model arrays (limited, range, solref, solimp, margin)
    "joint": ("jnt_limited", "jnt_range", "jnt_solref", "jnt_solimp", "jnt_margin"),
    "tendon": (
        "tendon_limited",
        "tendon_range",
        "tendon_solref_lim",
        "tendon_solimp_lim",
        "tendon_margin",
    ),
}


class Ratchet:
    """One-sided limits on joints and tendons that follow them in their closing direction.

    Parameters
    ----------
    model, data : the simulation (the model's limits are changed in place; :meth:`release`
        restores them).
    joints : joint ids or names (hinge or slide joints).
    tendons : tendon ids or names (a nonbackdrivable transmission: the tendon length, e.g.
        the tendon gripper's ``R^T q``, cannot decrease). A tendon's stop follows
        ``data.ten_length``, which ``mj_step`` computes before it integrates: one step late.
    sign : +1 (default): closing = increasing joint position / tendon length; -1: decreasing.
    timeconst : limit stiffness time constant [s]; default ``2 * model.opt.timestep``.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        joints: Sequence[int | str] = (),
        *,
        tendons: Sequence[int | str] = (),
        sign: int = 1,
        timeconst: float | None = None,
    ) -> None:
        if sign not in (1, -1):
            raise RatchetError(f"sign must be +1 or -1, got {sign!r}")
        jids = [self._id(model, mujoco.mjtObj.mjOBJ_JOINT, j, model.njnt, "joint") for j in joints]
        hinge_or_slide = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        for jid in jids:
            if int(model.jnt_type[jid]) not in hinge_or_slide:
                raise RatchetError(f"joint {model.joint(jid).name!r} is not a hinge or slide joint")
        tids = [
            self._id(model, mujoco.mjtObj.mjOBJ_TENDON, t, model.ntendon, "tendon") for t in tendons
        ]
        if not jids and not tids:
            raise RatchetError("a ratchet needs at least one joint or tendon")
        self.model, self.data, self.sign = model, data, sign
        self.joints, self.tendons = np.array(jids, dtype=int), np.array(tids, dtype=int)
        self.qadr = model.jnt_qposadr[self.joints]
        self._ids = {"joint": self.joints, "tendon": self.tendons}
        self._saved = {
            kind: [getattr(model, f)[ids].copy() for f in _FIELDS[kind]]
            for kind, ids in self._ids.items()
        }
        tc = 2.0 * model.opt.timestep if timeconst is None else float(timeconst)
        big = 1e6
        for kind, ids in self._ids.items():
            limited, rng, solref, solimp, margin = (getattr(model, f) for f in _FIELDS[kind])
            limited[ids] = 1
            solref[ids] = [tc, 1.0]
            solimp[ids] = [0.99, 0.999, 0.001, 0.5, 2.0]
            margin[ids] = 0.0
            pos = self._positions(kind)
            for k, i in enumerate(ids):
                rng[i] = [pos[k], big] if sign > 0 else [-big, pos[k]]

    @staticmethod
    def _id(model: mujoco.MjModel, obj: mujoco.mjtObj, x: int | str, n: int, what: str) -> int:
        i = mujoco.mj_name2id(model, obj, x) if isinstance(x, str) else int(x)
        if not 0 <= i < n:
            raise RatchetError(f"unknown {what} {x!r}")
        return i

    def _positions(self, kind: str) -> NDArray[np.float64]:
        if kind == "joint":
            return self.data.qpos[self.qadr]
        return self.data.ten_length[self.tendons]

    @property
    def stops(self) -> NDArray[np.float64]:
        """Current stops, joints then tendons (the positions they cannot open past)."""
        col = 0 if self.sign > 0 else 1
        m = self.model
        return np.concatenate([m.jnt_range[self.joints, col], m.tendon_range[self.tendons, col]])

    @stops.setter
    def stops(self, values: NDArray[np.float64]) -> None:
        """Set the stops (joints then tendons), e.g. to those of another copy of the scene."""
        v = np.asarray(values, dtype=float).reshape(-1)
        if v.shape != (len(self.joints) + len(self.tendons),) or not np.isfinite(v).all():
            raise RatchetError(
                f"stops must be {len(self.joints) + len(self.tendons)} finite numbers, got {v!r}"
            )
        col = 0 if self.sign > 0 else 1
        self.model.jnt_range[self.joints, col] = v[: len(self.joints)]
        self.model.tendon_range[self.tendons, col] = v[len(self.joints) :]

    def update(self) -> None:
        """Move each stop to its joint's (tendon's) position where it has closed past it."""
        for kind, ids in self._ids.items():
            if len(ids) == 0:
                continue
            r = getattr(self.model, _FIELDS[kind][1])
            pos = self._positions(kind)
            if self.sign > 0:
                r[ids, 0] = np.maximum(r[ids, 0], pos)
            else:
                r[ids, 1] = np.minimum(r[ids, 1], pos)

    def step(self, nstep: int = 1) -> None:
        """``nstep`` physics steps, the stops updated after each."""
        for _ in range(nstep):
            mujoco.mj_step(self.model, self.data)
            self.update()

    def release(self) -> None:
        """Restore the joints' and tendons' own limits (the ratchet is then inactive)."""
        for kind, ids in self._ids.items():
            for f, saved in zip(_FIELDS[kind], self._saved[kind], strict=True):
                getattr(self.model, f)[ids] = saved
