"""Simulated resistance: how large a load the object takes in MuJoCo before it moves.

The thesis measured resistible forces with a load cell pulling on the grasped object; we
pull in MuJoCo. :func:`simulated_resistance` applies a load ``s * w`` to the object
(``data.xfrc_applied``: a force [N] through the object's centre of mass and a torque
[N m], world axes; ``w`` a unit wrench direction of 6 entries, force first) with ``s``
growing linearly at ``rate`` per second after ``settle_s`` of rest, and stops when the
object has moved more than ``max_shift`` [m] (centre of mass) or turned more than
``max_turn`` [rad] from where it rested. The answer is the largest ``s`` reached before
that, or ``cap`` (then ``capped``).

What counts as moving: MuJoCo's friction is a soft constraint, so a held object creeps a
little under any tangential load (a speed proportional to the load, set by ``impratio``
and the contact ``solref``). Over a ramp of ``cap / rate`` seconds the creep must stay
below ``max_shift``: the defaults (2 mm, 0.05 rad; ramps of 1 N/s or 0.05 N m/s) keep
it there for the scenes' settings (elliptic cone, impratio 100, timestep 1 ms, no noslip),
while a slip that breaks the grasp runs away within a few ms of the limit. The answer is
therefore the load at breakaway, late by at most ``rate`` x the time to move ``max_shift``
after it (tested on the analytic pinch: within a few percent of ``2 mu tau / L``).

A new contact also ends the run (``stop_on_new_contact``, default on): when the object
touches a body it did not touch at rest (the palm, a finger that was open), the grasp the
prediction was made for no longer exists, whatever the new contact can hold. The reason
the run ended is :attr:`Resistance.reason`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stability import GraspError

from .ratchet import Ratchet

__all__ = ["Resistance", "simulated_resistance", "touching_bodies"]


@dataclass
class Resistance:
    """Result of :func:`simulated_resistance`."""

    value: float  # largest load factor s held [N or N m per unit of the direction]
    capped: bool  # the object held the cap
    shift: float  # centre-of-mass displacement when the run stopped [m]
    turn: float  # rotation angle when the run stopped [rad]
    seconds: float  # simulated time of the ramp [s]
    trace: NDArray[np.float64] = field(repr=False)  # rows (s, shift, turn) every 10 ms
    reason: str = ""  # "cap", "shift", "turn" or "new contact: <body>"


def simulated_resistance(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    direction: ArrayLike,
    *,
    rate: float | None = None,
    cap: float = 100.0,
    max_shift: float = 0.002,
    max_turn: float = 0.05,
    settle_s: float = 0.1,
    ratchet: Ratchet | None = None,
    body: str = "object",
    stop_on_new_contact: bool = True,
) -> Resistance:
    """Ramp a load along ``direction`` on ``body`` until it moves (module doc).

    Parameters
    ----------
    model, data : a settled scene (``data`` is advanced in place).
    direction : wrench direction (fx, fy, fz, tx, ty, tz), world axes, normalised here so
        that its largest block (force or torque) has unit norm.
    rate : load growth [units of s per second]; default 1 for a force direction, 0.05 for
        a pure torque.
    cap : largest load tried (the solvers' cap, 100 by default).
    max_shift, max_turn : what counts as moved [m], [rad].
    settle_s : rest before the ramp [s] (the reference pose is taken after it).
    ratchet : a :class:`ihm.ratchet.Ratchet` updated every step (nonbackdrivable joints).
    stop_on_new_contact : end the run when ``body`` touches a body it did not touch after
        ``settle_s`` (module doc).
    """
    w = np.asarray(direction, dtype=float).reshape(-1)
    if w.shape != (6,) or not np.isfinite(w).all():
        raise GraspError(f"direction must be 6 finite numbers (force, torque), got {direction!r}")
    scale = max(np.linalg.norm(w[:3]), np.linalg.norm(w[3:]))
    if scale == 0:
        raise GraspError("direction must not be zero")
    w = w / scale
    if rate is None:
        rate = 1.0 if np.linalg.norm(w[:3]) > 0 else 0.05
    if not (rate > 0 and cap > 0 and max_shift > 0 and max_turn > 0 and settle_s >= 0):
        raise GraspError("rate, cap, max_shift and max_turn must be > 0, settle_s >= 0")
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0:
        raise GraspError(f"no body named {body!r}")
    dt = model.opt.timestep

    def advance(n: int) -> None:
        if ratchet is None:
            mujoco.mj_step(model, data, nstep=n)
        else:
            ratchet.step(n)

    data.xfrc_applied[bid] = 0.0
    advance(int(round(settle_s / dt)))
    p0 = data.xipos[bid].copy()
    q0 = data.xquat[bid].copy()
    touching = touching_bodies(model, data, bid)
    rot = np.zeros(3)
    steps = int(np.ceil(cap / rate / dt))
    every = max(1, int(round(0.01 / dt)))
    trace = []
    held = 0.0
    shift = turn = 0.0
    k = 0
    for k in range(1, steps + 1):
        s = min(cap, rate * k * dt)
        data.xfrc_applied[bid] = s * w
        advance(1)
        shift = float(np.linalg.norm(data.xipos[bid] - p0))
        mujoco.mju_subQuat(rot, data.xquat[bid], q0)
        turn = float(np.linalg.norm(rot))
        if k % every == 0:
            trace.append((s, shift, turn))
        reason = ""
        if shift > max_shift or not np.isfinite(shift):
            reason = "shift"
        elif turn > max_turn:
            reason = "turn"
        elif stop_on_new_contact:
            new = touching_bodies(model, data, bid) - touching
            if new:
                reason = "new contact: " + ", ".join(sorted(model.body(b).name for b in new))
        if reason:
            data.xfrc_applied[bid] = 0.0
            tr = np.array(trace).reshape(-1, 3)
            return Resistance(held, False, shift, turn, k * dt, tr, reason)
        held = s
    data.xfrc_applied[bid] = 0.0
    return Resistance(held, True, shift, turn, k * dt, np.array(trace).reshape(-1, 3), "cap")


def touching_bodies(model: mujoco.MjModel, data: mujoco.MjData, bid: int) -> set[int]:
    """Bodies in contact with body ``bid`` (penetrating: ``dist < 0``)."""
    out = set()
    for c in data.contact[: data.ncon]:
        b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
        if c.dist < 0 and bid in (b1, b2):
            out.add(int(b2 if b1 == bid else b1))
    return out
