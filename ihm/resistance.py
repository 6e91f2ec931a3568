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
from dataclasses import dataclass, field, replace
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
    "ResistanceOptions",
    "advance",
    "simulated_resistance",
    "solver_conditions",
    "touching_bodies",
    "unit_direction",
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


@dataclass(frozen=True)
class ResistanceOptions:
    """How :func:`simulated_resistance` ramps the load and when a run ends (module doc).

    rate : load growth [units of s per second]; None: 1 for a direction with a force
        part, 0.05 for a pure torque.
    cap : largest load tried (the solvers' cap, 100 by default) [N or N m per unit
        direction].
    max_shift, max_turn : the hard end of the run [m], [rad]; also the units of the slip
        rule's speeds.
    settle_s : rest before the ramp [s] (the reference pose is taken after it).
    stop_on_new_contact : end the run when the body touches a body it did not touch after
        ``settle_s`` (module doc).
    slip_factor : a slip starts where the speed exceeds this times the creep reference.
    stop_rule : ``"slip"`` (default: the slip rule, module doc) or ``"distance"``
        (``value`` is the largest load held before the object moved ``max_shift`` or
        turned ``max_turn``, creep included; the thesis experiments in
        :mod:`ihm.experiments` and the simulated maps of :mod:`ihm.sim_maps` use it, so
        that their documented figures stay reproducible).
    check_rate : repeat the ramp :data:`RATE_CHECK_FACTOR` times slower from a copy of the
        state and warn (:class:`RateDependenceWarning`) if the answers differ by more than
        ``rate_tol`` (relative to ``value``). Costs up to 4x the ramp's time again.
    rate_tol : that relative tolerance.

    Invalid values raise :class:`stability.GraspError` when the options are made.
    """

    rate: float | None = None
    cap: float = 100.0
    max_shift: float = 0.002
    max_turn: float = 0.05
    settle_s: float = 0.1
    stop_on_new_contact: bool = True
    slip_factor: float = 30.0
    stop_rule: str = "slip"
    check_rate: bool = True
    rate_tol: float = 0.2

    def __post_init__(self) -> None:
        nums = {"rate": self.rate, "cap": self.cap, "max_shift": self.max_shift,
                "max_turn": self.max_turn, "settle_s": self.settle_s,
                "slip_factor": self.slip_factor, "rate_tol": self.rate_tol}  # fmt: skip
        for key, v in nums.items():
            if key == "rate" and v is None:
                continue  # the default rate, chosen by the direction
            if (
                not isinstance(v, (int, float, np.number))
                or isinstance(v, bool)
                or not np.isfinite(v)
            ):
                raise GraspError(f"{key} must be a finite number, got {v!r}")
        rate, cap, max_shift, max_turn = self.rate, self.cap, self.max_shift, self.max_turn
        if not ((rate is None or rate > 0) and cap > 0 and max_shift > 0 and max_turn > 0
                and self.settle_s >= 0):  # fmt: skip
            raise GraspError("rate, cap, max_shift and max_turn must be > 0, settle_s >= 0, got "
                             f"rate={rate!r}, cap={cap!r}, max_shift={max_shift!r}, "
                             f"max_turn={max_turn!r}, settle_s={self.settle_s!r}")  # fmt: skip
        if not self.slip_factor > 1:
            raise GraspError(f"slip_factor must be > 1, got {self.slip_factor!r}")
        if self.stop_rule not in ("slip", "distance"):
            raise GraspError(f"stop_rule must be 'slip' or 'distance', got {self.stop_rule!r}")
        if not self.rate_tol > 0:
            raise GraspError(f"rate_tol must be > 0, got {self.rate_tol!r}")
        if not isinstance(self.check_rate, (bool, np.bool_)):
            raise GraspError(f"check_rate must be True or False, got {self.check_rate!r}")


def unit_direction(direction: ArrayLike) -> NDArray[np.float64]:
    """``direction`` as 6 floats scaled so that its largest block (force or torque) has
    unit norm; :class:`stability.GraspError` if it is not 6 finite numbers or is zero."""
    w = np.asarray(direction, dtype=float).reshape(-1)
    if w.shape != (6,) or not np.isfinite(w).all():
        raise GraspError(f"direction must be 6 finite numbers (force, torque), got {direction!r}")
    scale = max(np.linalg.norm(w[:3]), np.linalg.norm(w[3:]))
    if scale == 0:
        raise GraspError("direction must not be zero")
    return w / scale


def _check_ratchet(
    model: mujoco.MjModel, data: mujoco.MjData, ratchet: Ratchet | None, check_rate: bool
) -> None:
    """A :class:`Ratchet` must be on ``model`` and ``data``; the rate check needs a
    :class:`Ratchet` (it copies it), not another stepper."""
    if isinstance(ratchet, Ratchet) and (ratchet.model is not model or ratchet.data is not data):
        raise GraspError("ratchet was built on another model or data than the ones passed")
    if check_rate and ratchet is not None and not isinstance(ratchet, Ratchet):
        raise GraspError(
            "check_rate=True repeats the ramp on a copy of the state and needs an "
            f"ihm.ratchet.Ratchet to copy, got {type(ratchet).__name__}; pass check_rate=False"
        )


def _conditions(
    model: mujoco.MjModel, rate: float, opts: ResistanceOptions, ratchet: Ratchet | None
) -> dict[str, Any]:
    """:attr:`Resistance.conditions`: the model's solver settings and the run's options."""
    return {
        **solver_conditions(model),
        "rate": float(rate),
        "cap": float(opts.cap),
        "max_shift": float(opts.max_shift),
        "max_turn": float(opts.max_turn),
        "settle_s": float(opts.settle_s),
        "ratchet": ratchet is not None,
        "stop_on_new_contact": bool(opts.stop_on_new_contact),
        "stop_rule": "distance: the largest load held before max_shift or max_turn"
        if opts.stop_rule == "distance"
        else (
            f"slip: {SLIP_WINDOW_S * 1e3:g} ms speed > {opts.slip_factor:g} x the mean speed "
            f"over [t/4, t/2] (floor {SLIP_FLOOR:g}), in max_shift/s or max_turn/s, until it "
            f"falls below 1/{SLIP_DROP:g} of its peak; a slip reaching max_shift or max_turn "
            "is the breakaway; else the run ends at max_shift, max_turn, a new contact or "
            "the cap"
        ),
        "slip_factor": float(opts.slip_factor),
    }


def simulated_resistance(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    direction: ArrayLike,
    *,
    ratchet: Ratchet | None = None,
    body: str = "object",
    options: ResistanceOptions | None = None,
) -> Resistance:
    """Ramp a load along ``direction`` on ``body`` until it slips (module doc).

    Parameters
    ----------
    model, data : a settled scene (``data`` is advanced in place; ``model`` is not changed
        except by ``ratchet``'s stops).
    direction : wrench direction (fx, fy, fz, tx, ty, tz), world axes, normalised here so
        that its largest block (force or torque) has unit norm.
    ratchet : a :class:`ihm.ratchet.Ratchet` on ``model`` and ``data``, updated every step
        (nonbackdrivable joints).
    body : the loaded body (a free body: the object).
    options : the ramp and its end (:class:`ResistanceOptions`: rate, cap, hard limits,
        slip rule, rate check); its defaults when None.
    """
    opts = ResistanceOptions() if options is None else options
    w = unit_direction(direction)
    if opts.rate is None:
        rate = 1.0 if np.linalg.norm(w[:3]) > 0 else 0.05
    else:
        rate = float(opts.rate)
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0:
        raise GraspError(f"no body named {body!r}")
    _check_ratchet(model, data, ratchet, opts.check_rate)
    conditions = _conditions(model, rate, opts, ratchet)
    start = copy.copy(data) if opts.check_rate else None
    stops0 = ratchet.stops.copy() if opts.check_rate and ratchet is not None else None
    res = replace(_ramp(model, data, w, bid, rate, ratchet, opts), conditions=conditions)
    if start is None:
        return res
    slow = _slow_repeat(model, start, w, bid, rate, ratchet, stops0, opts)
    return replace(res, rate_check=_rate_check(res, slow, rate, opts.rate_tol))


def _slow_repeat(
    model: mujoco.MjModel,
    start: mujoco.MjData,
    w: NDArray[np.float64],
    bid: int,
    rate: float,
    ratchet: Ratchet | None,
    stops0: NDArray[np.float64] | None,
    opts: ResistanceOptions,
) -> Resistance:
    """The ramp again at ``rate / RATE_CHECK_FACTOR`` from ``start`` (the state before the
    first ramp); a ratchet is copied onto ``start`` with its stops ``stops0`` as they were
    then, and the caller's ratchet keeps the stops the first ramp left."""
    twin = None
    if ratchet is not None:
        stops_end = ratchet.stops.copy()
        twin = copy.copy(ratchet)
        twin.data = start
        twin.stops = stops0
    try:
        return _ramp(model, start, w, bid, rate / RATE_CHECK_FACTOR, twin, opts)
    finally:
        if ratchet is not None:
            ratchet.stops = stops_end


def _rate_check(res: Resistance, slow: Resistance, rate: float, rate_tol: float) -> dict[str, Any]:
    """:attr:`Resistance.rate_check` of the ramp ``res`` at ``rate`` and its slow repeat;
    warns (:class:`RateDependenceWarning`) when they differ by more than ``rate_tol`` of
    ``res.value`` (relative)."""
    slow_rate = float(rate) / RATE_CHECK_FACTOR
    diff = abs(slow.value - res.value)
    rel = diff / abs(res.value) if res.value != 0 else (0.0 if diff == 0 else float("inf"))
    if rel > rate_tol:
        warnings.warn(
            f"simulated resistance depends on the ramp rate: {res.value:.4g} at {rate:g}/s "
            f"({res.reason}), {slow.value:.4g} at {slow_rate:g}/s ({slow.reason}): "
            f"{rel:.0%} apart, more than rate_tol {rate_tol:.0%}",
            RateDependenceWarning,
            stacklevel=3,
        )
    return {
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


def advance(model: mujoco.MjModel, data: mujoco.MjData, ratchet: Ratchet | None, n: int) -> None:
    """``n`` physics steps, through the ratchet when there is one (none for ``n <= 0``)."""
    if n <= 0:
        return
    if ratchet is None:
        mujoco.mj_step(model, data, nstep=n)
    else:
        ratchet.step(n)


class _Motion:
    """The object's motion during a ramp, from its rest pose ``p0``, ``q0``: its
    displacement [m], rotation [rad], and speeds over windows of ``win`` steps in units of
    the hard limits per second (``max(|dp| / max_shift, |dtheta| / max_turn) / seconds``).
    Keeps the poses of the last ``win + 1`` steps (a ring) and one every ``win`` steps
    (the grid the creep reference is read on)."""

    def __init__(
        self, p0: NDArray, q0: NDArray, dt: float, max_shift: float, max_turn: float
    ) -> None:
        self.p0, self.q0 = p0, q0
        self.max_shift, self.max_turn = max_shift, max_turn
        self.win = max(1, int(round(SLIP_WINDOW_S / dt)))  # steps per speed window, trace row
        self.span = self.win * dt  # [s]
        self.ring_p = np.tile(p0, (self.win + 1, 1))  # poses of the last win + 1 steps
        self.ring_q = np.tile(q0, (self.win + 1, 1))
        self.grid_p, self.grid_q = [p0], [q0]  # poses every win steps from the ramp's start
        self._rot = np.zeros(3)

    def speed(self, pa: NDArray, qa: NDArray, pb: NDArray, qb: NDArray, seconds: float) -> float:
        """Mean speed from pose a to pose b over ``seconds`` [1/s]."""
        mujoco.mju_subQuat(self._rot, qb, qa)
        return (max(math.hypot(*(pb - pa)) / self.max_shift,
                    math.hypot(*self._rot) / self.max_turn) / seconds)  # fmt: skip

    def moved(self, p: NDArray, q: NDArray) -> tuple[float, float]:
        """Displacement [m] and rotation angle [rad] of pose ``p``, ``q`` from rest."""
        mujoco.mju_subQuat(self._rot, q, self.q0)
        return math.hypot(*(p - self.p0)), math.hypot(*self._rot)

    def window_start(self, k: int) -> tuple[NDArray, NDArray]:
        """The pose ``win`` steps before step ``k`` (the rest pose before the ramp)."""
        old = (k - self.win) % (self.win + 1)
        return self.ring_p[old], self.ring_q[old]

    def push(self, k: int, p: NDArray, q: NDArray) -> None:
        """Keep the pose of step ``k`` in the ring."""
        self.ring_p[k % (self.win + 1)] = p
        self.ring_q[k % (self.win + 1)] = q

    def creep_reference(self, p: NDArray, q: NDArray) -> float | None:
        """Add a grid pose; the creep reference speed, the mean over grid points
        ``[g/4, g/2]`` (at least :data:`SLIP_FLOOR`), once that spans
        :data:`SLIP_MIN_SPAN` windows (else None)."""
        self.grid_p.append(p.copy())
        self.grid_q.append(q.copy())
        g = len(self.grid_p) - 1
        a, b = g // 4, g // 2
        if b - a < SLIP_MIN_SPAN:
            return None
        gp, gq = self.grid_p, self.grid_q
        return max(self.speed(gp[a], gq[a], gp[b], gq[b], (b - a) * self.span), SLIP_FLOOR)


@dataclass
class _SlipRule:
    """The slip rule's state (module doc): a slip starts at a speed above ``factor`` times
    the creep reference ``ref`` and ends below its peak over :data:`SLIP_DROP`. ``start``:
    the step before the slip's first window (-1: not slipping); ``shift``, ``turn``: the
    displacement [m], [rad] there; ``slips``: slips that ended."""

    factor: float
    ref: float = math.inf
    start: int = -1
    peak: float = 0.0
    shift: float = 0.0
    turn: float = 0.0
    slips: int = 0

    def starts(self, u: float) -> bool:
        """No slip yet, and speed ``u`` [1/s] starts one."""
        return self.start < 0 and u > self.factor * self.ref

    def begin(self, start: int, u: float, shift: float, turn: float) -> None:
        self.start, self.peak = start, u
        self.shift, self.turn = shift, turn

    def follow(self, u: float) -> None:
        """A slip under way ends when ``u`` falls below its peak over :data:`SLIP_DROP`."""
        if self.start >= 0:
            self.peak = max(self.peak, u)
            if u < self.peak / SLIP_DROP:
                self.start, self.slips = -1, self.slips + 1


def _stop_reason(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    bid: int,
    moved: tuple[float, float],
    opts: ResistanceOptions,
    touching: set[int],
) -> str:
    """Why the run ends at this step ("" if it goes on): the hard limits on the
    displacement ``moved`` ([m], [rad]) or a body touched that was not at rest."""
    shift, turn = moved
    if shift > opts.max_shift or not np.isfinite(shift):
        return "shift"
    if turn > opts.max_turn:
        return "turn"
    if opts.stop_on_new_contact:
        new = touching_bodies(model, data, bid) - touching
        if new:
            return "new contact: " + ", ".join(sorted(model.body(b).name for b in new))
    return ""


def _ramp(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    w: NDArray[np.float64],
    bid: int,
    rate: float,
    ratchet: Ratchet | None,
    opts: ResistanceOptions,
) -> Resistance:
    """One ramp at ``rate`` with the slip rule (module doc): ``settle_s`` of rest, then the
    load ``s w`` on body ``bid`` grows until a stop reason or the cap. The distance rule is
    the slip rule that never calls a slip."""
    dt = model.opt.timestep
    cap = float(opts.cap)
    data.xfrc_applied[bid] = 0.0
    advance(model, data, ratchet, int(round(float(opts.settle_s) / dt)))
    touching = touching_bodies(model, data, bid)
    motion = _Motion(data.xipos[bid].copy(), data.xquat[bid].copy(), dt,
                     float(opts.max_shift), float(opts.max_turn))  # fmt: skip
    slip = _SlipRule(math.inf if opts.stop_rule == "distance" else float(opts.slip_factor))
    trace = []
    held = 0.0
    shift = turn = 0.0
    k = 0
    reason = ""
    for k in range(1, int(np.ceil(cap / rate / dt)) + 1):
        s = min(cap, rate * k * dt)
        data.xfrc_applied[bid] = s * w
        advance(model, data, ratchet, 1)
        pos, quat = data.xipos[bid], data.xquat[bid]
        shift, turn = motion.moved(pos, quat)
        pa, qa = motion.window_start(k)
        u = motion.speed(pa, qa, pos, quat, motion.span)
        if slip.starts(u):
            slip.begin(max(0, k - motion.win), u, *motion.moved(pa, qa))
        else:
            slip.follow(u)
        motion.push(k, pos, quat)
        if k % motion.win == 0:
            trace.append((s, shift, turn, u))
            ref = motion.creep_reference(pos, quat)
            slip.ref = slip.ref if ref is None else ref
        reason = _stop_reason(model, data, bid, (shift, turn), opts, touching)
        if reason:
            break
        held = s
    data.xfrc_applied[bid] = 0.0
    return _resistance(np.array(trace, dtype=float).reshape(-1, 4), held, (shift, turn),
                       reason or "cap", slip, rate, dt, k)  # fmt: skip


def _resistance(
    trace: NDArray[np.float64],
    held: float,
    moved: tuple[float, float],
    reason: str,
    slip: _SlipRule,
    rate: float,
    dt: float,
    k: int,
) -> Resistance:
    """The :class:`Resistance` of a ramp at ``rate`` [per second] in steps of ``dt`` [s]
    that ended for ``reason`` at step ``k`` with the displacement ``moved`` ([m], [rad]):
    the load at the slip's start where a slip was under way (breakaway), else the last
    load ``held``."""
    shift, turn = moved
    slipping = slip.start >= 0 and reason != "cap"
    if slipping:
        value = rate * slip.start * dt
        creep_shift, creep_turn = slip.shift, slip.turn
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
        trace=trace,
        reason=reason,
        breakaway=bool(slipping),
        creep_shift=float(creep_shift),
        creep_turn=float(creep_turn),
        creep_rate=float(creep_rate),
        slips=slip.slips,
    )


def touching_bodies(model: mujoco.MjModel, data: mujoco.MjData, bid: int) -> set[int]:
    """Bodies in contact with body ``bid`` (penetrating: ``dist < 0``)."""
    if data.ncon == 0:
        return set()
    con = data.contact  # all data.ncon contacts, as arrays
    b1, b2 = model.geom_bodyid[con.geom1], model.geom_bodyid[con.geom2]
    pen = con.dist < 0
    return set(b2[pen & (b1 == bid)].tolist()) | set(b1[pen & (b2 == bid)].tolist())
