"""Simulated resistance: how large a load the object takes in MuJoCo before it slips.

The thesis measured resistible forces with a load cell pulling on the grasped object; we
pull in MuJoCo. :func:`simulated_resistance` applies a load ``s * w`` to the object
(``data.xfrc_applied``: a force [N] through the object's centre of mass and a torque
[N m], world axes; ``w`` a unit wrench direction of 6 entries, force first) with ``s``
growing linearly at ``rate`` per second after ``settle_s`` of rest. It runs the model as
it is: the solver settings (cone, ``impratio``, timestep, integrator, solver, noslip) are
the model's own, never changed here, and are stated in :attr:`Resistance.conditions`.

Creep and breakaway. MuJoCo's friction is a soft constraint: a held object creeps at a
speed roughly proportional to the tangential load (set by ``impratio``, the contact
``solref`` and the noslip pass), so its displacement over a ramp grows like
``s**2 / rate``. A threshold on the displacement alone (``stop_rule="distance"``: the load
at 2 mm) therefore measures creep, and moves 3-5x with ``impratio`` and the ramp rate where
the creep is fast. A real slip is different: the contacts stop holding and the object's
speed jumps by orders of magnitude within milliseconds. The *slip rule* looks for that
jump:

* ``u`` is the object's speed over the last ``SLIP_WINDOW_S`` (10 ms) in units of the
  hard limits per second: ``max(|dp| / max_shift, |dtheta| / max_turn) / window`` [1/s];
* the creep reference at ramp time ``t`` is the mean speed over ``[t/4, t/2]`` (same
  units, at least ``SLIP_FLOOR``). Creep that grows with the load keeps ``u`` within a
  few times it (8/3 for a speed proportional to the load), at any rate and ``impratio``;
* a slip starts where ``u > slip_factor * reference`` (default 30), and lasts until
  ``u`` falls below a ``SLIP_DROP``-th (1/10) of its peak since it started;
* a slip that reaches the hard end of the run (``max_shift`` or ``max_turn``) is the
  *breakaway*: ``reason == "slip"`` and :attr:`Resistance.value` is the load at which it
  started (held just before), independent of how fast the creep was. A slip that stops
  again (stick-slip: a finger re-locks, the grasp reseats) is counted in
  :attr:`Resistance.slips` and its displacement becomes part of the creep.

``max_shift`` (2 mm) and ``max_turn`` (0.05 rad) stay the hard end of every run: where
creep alone reaches them first, the run ends with ``reason`` "shift" or "turn" and
``value`` is the load then (creep-limited: that figure does move with ``impratio`` and
the rate). :attr:`Resistance.creep_shift` / ``creep_turn`` is the displacement before
breakaway (or at the end of a run without one) and :attr:`Resistance.creep_rate` its
ratio to ``value`` [m per unit load].

The rate check (``check_rate=True``, the default) repeats the ramp from a copy of the
state taken before it (``copy.copy(data)``; a :class:`ihm.ratchet.Ratchet` is copied onto
that state with its stops as they were) at ``rate / RATE_CHECK_FACTOR`` (4x slower) and
issues a :class:`RateDependenceWarning` when the two answers differ by more than
``rate_tol`` (20 %) of ``value``; both are kept in :attr:`Resistance.rate_check`.

On the analytic pinch (tests/ihm/test_resistance.py) the slip rule's breakaway stays within
1.2 % of ``2 mu tau / L`` = 2.2222 N at impratio 100 and 10, at 1 and 0.25 N/s, where the
distance rule's load at 2 mm comes 1.5-5 % late.

A new contact also ends the run (``stop_on_new_contact``, default on): when the object
touches a body it did not touch at rest (the palm, a finger that was open), the grasp the
prediction was made for no longer exists, whatever the new contact can hold; ``value`` is
then the slip's start if the object was slipping into it. The reason the run ended is
:attr:`Resistance.reason`.
"""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stability import GraspError

from .ratchet import Ratchet

__all__ = [
    "RATE_CHECK_FACTOR",
    "RateDependenceWarning",
    "Resistance",
    "simulated_resistance",
    "solver_conditions",
    "touching_bodies",
]

#: window of the object's speed in the slip rule [s]
SLIP_WINDOW_S = 0.01
#: a slip ends when the speed falls below its peak divided by this
SLIP_DROP = 10.0
#: floor of the creep reference speed [1/s: max_shift or max_turn per second]
SLIP_FLOOR = 1e-3
#: the creep reference must span this many speed windows before a slip can be called
#: (so none in the first 16 windows, 0.16 s, of the ramp)
SLIP_MIN_SPAN = 4
#: the rate check repeats the ramp this many times slower
RATE_CHECK_FACTOR = 4.0


class RateDependenceWarning(UserWarning):
    """The simulated resistance changed by more than ``rate_tol`` when the ramp was
    repeated :data:`RATE_CHECK_FACTOR` times slower (:func:`simulated_resistance`)."""


@dataclass
class Resistance:
    """Result of :func:`simulated_resistance` (module doc)."""

    value: float  # breakaway load, or the largest load s held [N or N m per unit direction]
    capped: bool  # the object held the cap
    shift: float  # centre-of-mass displacement when the run stopped [m]
    turn: float  # rotation angle when the run stopped [rad]
    seconds: float  # simulated time of the ramp [s]
    trace: NDArray[np.float64] = field(repr=False)  # rows (s, shift, turn, u) every 10 ms
    reason: str = ""  # "slip", "cap", "shift", "turn" or "new contact: <body>"
    breakaway: bool = False  # value is where a slip started (reason "slip", or a new contact)
    creep_shift: float = 0.0  # displacement before breakaway (else at the end) [m]
    creep_turn: float = 0.0  # rotation before breakaway (else at the end) [rad]
    creep_rate: float = 0.0  # creep_shift / value [m per unit of s]; nan where value is 0
    slips: int = 0  # slips that stopped again before the end (stick-slip)
    conditions: dict[str, Any] = field(default_factory=dict)  # solver settings, run options
    rate_check: dict[str, Any] | None = None  # the slower repeat (check_rate=True)


def solver_conditions(model: mujoco.MjModel) -> dict[str, Any]:
    """The model's solver settings that set MuJoCo's friction creep: cone ("pyramidal" or
    "elliptic"), impratio, timestep [s], integrator, solver, noslip iterations and
    tolerance."""
    o = model.opt

    def name(enum: Any, value: int, prefix: str) -> str:
        return enum(int(value)).name.removeprefix(prefix).lower()

    return {
        "cone": name(mujoco.mjtCone, o.cone, "mjCONE_"),
        "impratio": float(o.impratio),
        "timestep": float(o.timestep),
        "integrator": name(mujoco.mjtIntegrator, o.integrator, "mjINT_"),
        "solver": name(mujoco.mjtSolver, o.solver, "mjSOL_"),
        "noslip_iterations": int(o.noslip_iterations),
        "noslip_tolerance": float(o.noslip_tolerance),
    }


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
    slip_factor: float = 30.0,
    check_rate: bool = True,
    rate_tol: float = 0.2,
    stop_rule: str = "slip",
) -> Resistance:
    """Ramp a load along ``direction`` on ``body`` until it slips (module doc).

    Parameters
    ----------
    model, data : a settled scene (``data`` is advanced in place; ``model`` is not changed
        except by ``ratchet``'s stops).
    direction : wrench direction (fx, fy, fz, tx, ty, tz), world axes, normalised here so
        that its largest block (force or torque) has unit norm.
    rate : load growth [units of s per second]; default 1 for a force direction, 0.05 for
        a pure torque.
    cap : largest load tried (the solvers' cap, 100 by default).
    max_shift, max_turn : the hard end of the run [m], [rad]; also the units of the slip
        rule's speeds.
    settle_s : rest before the ramp [s] (the reference pose is taken after it).
    ratchet : a :class:`ihm.ratchet.Ratchet` on ``model`` and ``data``, updated every step
        (nonbackdrivable joints).
    stop_on_new_contact : end the run when ``body`` touches a body it did not touch after
        ``settle_s`` (module doc).
    slip_factor : a slip starts where the speed exceeds this times the creep reference.
    check_rate : repeat the ramp :data:`RATE_CHECK_FACTOR` times slower from a copy of the
        state and warn (:class:`RateDependenceWarning`) if the answers differ by more than
        ``rate_tol`` (relative to ``value``). Costs up to 4x the ramp's time again.
    stop_rule : ``"slip"`` (default: the slip rule, module doc) or ``"distance"``
        (``value`` is the largest load held before the object moved ``max_shift`` or
        turned ``max_turn``, creep included; the thesis experiments in
        :mod:`ihm.experiments` and the simulated maps of :mod:`ihm.sim_maps` use it, so
        that their documented figures stay reproducible).
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
    nums = {"rate": rate, "cap": cap, "max_shift": max_shift, "max_turn": max_turn,
            "settle_s": settle_s, "slip_factor": slip_factor, "rate_tol": rate_tol}  # fmt: skip
    for key, v in nums.items():
        if not isinstance(v, (int, float, np.number)) or isinstance(v, bool) or not np.isfinite(v):
            raise GraspError(f"{key} must be a finite number, got {v!r}")
    if not (rate > 0 and cap > 0 and max_shift > 0 and max_turn > 0 and settle_s >= 0):
        raise GraspError("rate, cap, max_shift and max_turn must be > 0, settle_s >= 0, got "
                         f"rate={rate!r}, cap={cap!r}, max_shift={max_shift!r}, "
                         f"max_turn={max_turn!r}, settle_s={settle_s!r}")  # fmt: skip
    if not slip_factor > 1:
        raise GraspError(f"slip_factor must be > 1, got {slip_factor!r}")
    if stop_rule not in ("slip", "distance"):
        raise GraspError(f"stop_rule must be 'slip' or 'distance', got {stop_rule!r}")
    if not rate_tol > 0:
        raise GraspError(f"rate_tol must be > 0, got {rate_tol!r}")
    if not isinstance(check_rate, (bool, np.bool_)):
        raise GraspError(f"check_rate must be True or False, got {check_rate!r}")
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0:
        raise GraspError(f"no body named {body!r}")
    if isinstance(ratchet, Ratchet) and (ratchet.model is not model or ratchet.data is not data):
        raise GraspError("ratchet was built on another model or data than the ones passed")
    if check_rate and ratchet is not None and not isinstance(ratchet, Ratchet):
        raise GraspError(
            "check_rate=True repeats the ramp on a copy of the state and needs an "
            f"ihm.ratchet.Ratchet to copy, got {type(ratchet).__name__}; pass check_rate=False"
        )
    conditions = {
        **solver_conditions(model),
        "rate": float(rate),
        "cap": float(cap),
        "max_shift": float(max_shift),
        "max_turn": float(max_turn),
        "settle_s": float(settle_s),
        "ratchet": ratchet is not None,
        "stop_on_new_contact": bool(stop_on_new_contact),
        "stop_rule": "distance: the largest load held before max_shift or max_turn"
        if stop_rule == "distance"
        else (
            f"slip: {SLIP_WINDOW_S * 1e3:g} ms speed > {slip_factor:g} x the mean speed over "
            f"[t/4, t/2] (floor {SLIP_FLOOR:g}), in max_shift/s or max_turn/s, until it falls "
            f"below 1/{SLIP_DROP:g} of its peak; a slip reaching max_shift or max_turn is the "
            "breakaway; else the run ends at max_shift, max_turn, a new contact or the cap"
        ),
        "slip_factor": float(slip_factor),
    }
    start = copy.copy(data) if check_rate else None
    stops0 = ratchet.stops.copy() if check_rate and ratchet is not None else None
    factor = math.inf if stop_rule == "distance" else float(slip_factor)  # inf: never a slip
    args = (model, w, float(cap), float(max_shift), float(max_turn), float(settle_s), bid,
            bool(stop_on_new_contact), factor)  # fmt: skip
    res = _ramp(data, float(rate), ratchet, *args)
    res.conditions = conditions
    if not check_rate:
        return res
    slow_rate = float(rate) / RATE_CHECK_FACTOR
    twin = None
    if ratchet is not None:
        stops_end = ratchet.stops.copy()
        twin = copy.copy(ratchet)
        twin.data = start
        twin.stops = stops0
    try:
        slow = _ramp(start, slow_rate, twin, *args)
    finally:
        if ratchet is not None:
            ratchet.stops = stops_end
    diff = abs(slow.value - res.value)
    rel = diff / abs(res.value) if res.value != 0 else (0.0 if diff == 0 else float("inf"))
    res.rate_check = {
        "rate": float(rate),
        "value": res.value,
        "reason": res.reason,
        "slow_rate": slow_rate,
        "slow_value": slow.value,
        "slow_reason": slow.reason,
        "relative_difference": rel,
        "rate_tol": float(rate_tol),
        "warned": bool(rel > rate_tol),
    }
    if rel > rate_tol:
        warnings.warn(
            f"simulated resistance depends on the ramp rate: {res.value:.4g} at {rate:g}/s "
            f"({res.reason}), {slow.value:.4g} at {slow_rate:g}/s ({slow.reason}): "
            f"{rel:.0%} apart, more than rate_tol {rate_tol:.0%}",
            RateDependenceWarning,
            stacklevel=2,
        )
    return res


def _ramp(
    data: mujoco.MjData,
    rate: float,
    ratchet: Ratchet | None,
    model: mujoco.MjModel,
    w: NDArray[np.float64],
    cap: float,
    max_shift: float,
    max_turn: float,
    settle_s: float,
    bid: int,
    stop_on_new_contact: bool,
    slip_factor: float,
) -> Resistance:
    """One ramp at ``rate`` with the slip rule (module doc)."""
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
    win = max(1, int(round(SLIP_WINDOW_S / dt)))  # steps per speed window and trace row
    span = win * dt
    ring_p = np.tile(p0, (win + 1, 1))  # poses of the last win + 1 steps
    ring_q = np.tile(q0, (win + 1, 1))
    grid_p, grid_q = [p0], [q0]  # poses every win steps from the ramp's start
    rot = np.zeros(3)

    def speed(pa: NDArray, qa: NDArray, pb: NDArray, qb: NDArray, seconds: float) -> float:
        mujoco.mju_subQuat(rot, qb, qa)
        return max(math.hypot(*(pb - pa)) / max_shift, math.hypot(*rot) / max_turn) / seconds

    def moved(p: NDArray, q: NDArray) -> tuple[float, float]:
        mujoco.mju_subQuat(rot, q, q0)
        return math.hypot(*(p - p0)), math.hypot(*rot)

    steps = int(np.ceil(cap / rate / dt))
    trace = []
    held = 0.0
    shift = turn = 0.0
    ref = np.inf  # creep reference speed [1/s]
    slip_start = -1  # step before the slip's first window; -1: not slipping
    slip_peak = slip_shift = slip_turn = 0.0
    slips = 0
    k = 0
    reason = ""
    for k in range(1, steps + 1):
        s = min(cap, rate * k * dt)
        data.xfrc_applied[bid] = s * w
        advance(1)
        pos, quat = data.xipos[bid], data.xquat[bid]
        shift, turn = moved(pos, quat)
        old = (k - win) % (win + 1)  # the pose win steps ago (the rest pose before that)
        u = speed(ring_p[old], ring_q[old], pos, quat, span)
        if slip_start < 0 and u > slip_factor * ref:
            slip_start, slip_peak = max(0, k - win), u
            slip_shift, slip_turn = moved(ring_p[old], ring_q[old])
        elif slip_start >= 0:
            slip_peak = max(slip_peak, u)
            if u < slip_peak / SLIP_DROP:
                slip_start, slips = -1, slips + 1
        ring_p[k % (win + 1)] = pos
        ring_q[k % (win + 1)] = quat
        if k % win == 0:
            grid_p.append(pos.copy())
            grid_q.append(quat.copy())
            trace.append((s, shift, turn, u))
            g = k // win
            a, b = g // 4, g // 2
            if b - a >= SLIP_MIN_SPAN:
                mean = speed(grid_p[a], grid_q[a], grid_p[b], grid_q[b], (b - a) * span)
                ref = max(mean, SLIP_FLOOR)
        if shift > max_shift or not np.isfinite(shift):
            reason = "shift"
        elif turn > max_turn:
            reason = "turn"
        elif stop_on_new_contact:
            new = touching_bodies(model, data, bid) - touching
            if new:
                reason = "new contact: " + ", ".join(sorted(model.body(b).name for b in new))
        if reason:
            break
        held = s
    data.xfrc_applied[bid] = 0.0
    tr = np.array(trace, dtype=float).reshape(-1, 4)
    if not reason:
        reason = "cap"
    slipping = slip_start >= 0 and reason != "cap"
    if slipping:
        value = rate * slip_start * dt
        creep_shift, creep_turn = slip_shift, slip_turn
        if not reason.startswith("new contact"):
            reason = "slip"
    else:
        value = held
        creep_shift, creep_turn = shift, turn
    creep_rate = creep_shift / value if value > 0 else float("nan")
    return Resistance(
        value=float(value),
        capped=reason == "cap",
        shift=shift,
        turn=turn,
        seconds=k * dt,
        trace=tr,
        reason=reason,
        breakaway=bool(slipping),
        creep_shift=float(creep_shift),
        creep_turn=float(creep_turn),
        creep_rate=float(creep_rate),
        slips=slips,
    )


def touching_bodies(model: mujoco.MjModel, data: mujoco.MjData, bid: int) -> set[int]:
    """Bodies in contact with body ``bid`` (penetrating: ``dist < 0``)."""
    if data.ncon == 0:
        return set()
    con = data.contact  # all data.ncon contacts, as arrays
    b1, b2 = model.geom_bodyid[con.geom1], model.geom_bodyid[con.geom2]
    pen = con.dist < 0
    return set(b2[pen & (b1 == bid)].tolist()) | set(b1[pen & (b2 == bid)].tolist())
