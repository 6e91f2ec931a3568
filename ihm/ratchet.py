"""Nonbackdrivable joints in simulation: a ratchet made of a joint limit that follows the joint.

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
ratchet the finger swings open (tests/test_resistance.py). Coupled joints (the Barrett
distal joints, tied to the proximal by an equality) are held through their coupling and
need no ratchet of their own.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

__all__ = ["Ratchet", "RatchetError", "actuated_joints"]


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


class Ratchet:
    """One-sided joint limits that follow the joints in their closing direction.

    Parameters
    ----------
    model, data : the simulation (the model's limits of ``joints`` are changed in place;
        :meth:`release` restores them).
    joints : joint ids or names (hinge or slide joints).
    sign : +1 (default): closing = increasing joint position; -1: decreasing.
    timeconst : limit stiffness time constant [s]; default ``2 * model.opt.timestep``.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        joints: Sequence[int | str],
        *,
        sign: int = 1,
        timeconst: float | None = None,
    ) -> None:
        if sign not in (1, -1):
            raise RatchetError(f"sign must be +1 or -1, got {sign!r}")
        ids = []
        for j in joints:
            jid = (
                mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)
                if isinstance(j, str)
                else int(j)
            )
            if not 0 <= jid < model.njnt:
                raise RatchetError(f"unknown joint {j!r}")
            hinge_or_slide = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
            if int(model.jnt_type[jid]) not in hinge_or_slide:
                raise RatchetError(f"joint {model.joint(jid).name!r} is not a hinge or slide joint")
            ids.append(jid)
        if not ids:
            raise RatchetError("a ratchet needs at least one joint")
        self.model, self.data, self.sign = model, data, sign
        self.joints = np.array(ids)
        self.qadr = model.jnt_qposadr[self.joints]
        self._saved = (
            model.jnt_limited[self.joints].copy(),
            model.jnt_range[self.joints].copy(),
            model.jnt_solref[self.joints].copy(),
            model.jnt_solimp[self.joints].copy(),
            model.jnt_margin[self.joints].copy(),
        )
        tc = 2.0 * model.opt.timestep if timeconst is None else float(timeconst)
        model.jnt_limited[self.joints] = 1
        model.jnt_solref[self.joints] = [tc, 1.0]
        model.jnt_solimp[self.joints] = [0.99, 0.999, 0.001, 0.5, 2.0]
        model.jnt_margin[self.joints] = 0.0
        big = 1e6
        for k, j in enumerate(self.joints):
            q = float(data.qpos[self.qadr[k]])
            model.jnt_range[j] = [q, big] if sign > 0 else [-big, q]
        self.update()

    @property
    def stops(self) -> NDArray[np.float64]:
        """Current stop positions (the limit each joint cannot open past) [rad or m]."""
        col = 0 if self.sign > 0 else 1
        return self.model.jnt_range[self.joints, col].copy()

    def update(self) -> None:
        """Move each stop to the joint's position where the joint has closed past it."""
        q = self.data.qpos[self.qadr]
        r = self.model.jnt_range
        if self.sign > 0:
            r[self.joints, 0] = np.maximum(r[self.joints, 0], q)
        else:
            r[self.joints, 1] = np.minimum(r[self.joints, 1], q)

    def step(self, nstep: int = 1) -> None:
        """``nstep`` physics steps, the stops updated after each."""
        for _ in range(nstep):
            mujoco.mj_step(self.model, self.data)
            self.update()

    def release(self) -> None:
        """Restore the joints' own limits (the ratchet is then inactive)."""
        lim, rng, ref, imp, mar = self._saved
        m = self.model
        m.jnt_limited[self.joints], m.jnt_range[self.joints] = lim, rng
        m.jnt_solref[self.joints], m.jnt_solimp[self.joints] = ref, imp
        m.jnt_margin[self.joints] = mar
