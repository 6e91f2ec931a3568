"""Static resistance: the largest load a grasp holds in MuJoCo, found by holding it.

:func:`ihm.resistance.simulated_resistance` ramps a load and reads the resistance off the
ramp (the slip rule, or with ``stop_rule="distance"`` the load at which the object has moved
``max_shift`` or turned ``max_turn``). With MuJoCo's soft friction a saturated contact does
not let go at once. The object keeps sliding slowly while its normal forces grow at nearly
constant penetration, so a ramp that reads the load at a displacement counts that slide, and
its figure depends on the ramp rate. On the settled Barrett scenes of
:mod:`ihm.experiments.barrett` the distance rule at 1 N/s read 1.1-4x the static limit
below: on ``barrett_cube`` 2.149 N against 1.894-1.913 N for a force along +z, and on
``barrett_box`` in the xz-plane 0.69-1.65 N against 0.27-0.66 N; the same directions read
20-45 % lower at 0.25 N/s (``docs/notebook/2026-11-29-model-vs-mujoco.md``).

:func:`static_resistance` asks the rate-free question instead: is a constant load held?
A load ``L`` along the unit direction ``w`` is *held* when, starting from the settled
state, after ``settle_s`` of rest (the reference pose is taken then), a ramp from 0 to
``L w`` over ``ramp_s`` and ``hold_s`` at ``L w``:

* the object never moves more than ``max_shift`` [m] from its reference position (centre
  of mass) nor turns more than ``max_turn`` [rad] (checked every :data:`CHECK_S` and at
  the end);
* it touches no body it did not touch at the reference pose (``stop_on_new_contact``);
* optionally (``rest_s > 0``; off by default), it has come to rest: over the last
  ``rest_s`` of the hold it moved less than ``rest_shift`` [m] and ``rest_turn`` [rad].
  Off, a load under which the object creeps slowly but stays within the limits for the
  whole trial is held. That is the right answer on the analytic pinch
  (``assets/analytic/pinch.xml``, impratio 100, no noslip pass), whose contacts creep
  steadily below breakaway: the default finds 2.207-2.227 N against ``2 mu tau / L`` =
  2.222 N, while ``rest_s = 0.5`` (0.01 mm per 0.5 s) calls the 0.05 mm creep at 1.85 N
  "moving" and finds 1.846 N. On ``barrett_cube`` the check changes nothing; on
  ``barrett_box``, whose object creeps 0.01-0.05 mm per 0.5 s under loads it holds for 6 s
  (object +x, no preload, 1-2.5 N), it reads 0.58-1.0 of the default (median per map).

The static resistance is the largest held load, found by bisection on ``[0, cap]``: the
cap is tried first (held: ``capped``), then the midpoint of the bracket (held, not held)
until its width is at most ``max(rtol * held, cap_tol * cap)``; ``value`` is the bracket's
held end. :func:`hold_trial` runs one trial.

Bisection assumes that a held load's smaller loads are held too; the bracket is the
crossing the bisection found. Near the limit that need not be so where the object
stick-slips: on ``barrett_box`` (no preload, force along object +z) 0.25 and 0.29 N are
held and 0.275 N is not; along 120° in the xz-plane the bisection's 0.391 N is held and
0.371 N is not. And where a held object creeps, the figure depends on ``hold_s``: on
``barrett_box`` (no preload, object +x) 2.9 N crept 0.28 mm in 2.5 s, then broke away at
3 s. Over the ``barrett_box`` maps a 6 s hold reads 0.72-0.98 of the 2.3 s value (median
per map); on ``barrett_cube`` the two are equal (``python -m ihm.experiments.holds``).

Every trial starts from the same state: ``mj_getState``/``mj_setState`` with
``mjSTATE_INTEGRATION`` (positions, velocities, controls, applied forces, warm start, time)
and, with a :class:`ihm.ratchet.Ratchet`, its stops as they were. When
:func:`static_resistance` returns, ``data`` and the ratchet's stops are back in that state.

Units: loads are ``s * w`` with ``w`` the direction normalised so that its larger block
(force or torque) has unit norm; ``value`` and ``bracket`` are in N per unit direction for a
direction with a force part, N m for a pure torque. The force acts through the body's
centre of mass, world axes (``data.xfrc_applied``, as in :mod:`ihm.resistance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stability import GraspError
from stability.options import check_ranges, finite

from .ratchet import Ratchet
from .resistance import advance, touching_bodies, unit_direction

__all__ = ["CHECK_S", "Hold", "HoldOptions", "HoldTrial", "hold_trial", "static_resistance"]

#: how often a trial checks the shift and turn limits and new contacts [s]
CHECK_S = 0.01

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


@dataclass(frozen=True)
class HoldOptions:
    """How :func:`static_resistance` tries a load and when the bisection ends (module doc).

    cap : the largest load tried [N or N m per unit direction].
    ramp_s : time to ramp the load from 0 to the trial load [s] (0: applied at once).
    hold_s : time the trial load is then held [s].
    settle_s : rest before the ramp [s]; the reference pose is taken after it.
    max_shift : largest displacement of the centre of mass from the reference [m].
    max_turn : largest rotation from the reference orientation [rad].
    rest_s : the final window of the hold over which the object must be at rest [s]
        (0, the default: no rest check; at most ``hold_s``).
    rest_shift, rest_turn : most displacement [m] and rotation [rad] over that window.
    rtol : bisection tolerance relative to the held load (0.01: 1 %).
    cap_tol : bisection tolerance relative to the cap (1e-3: 0.1 % of the cap); the
        bisection ends when the bracket is at most ``max(rtol * held, cap_tol * cap)`` wide.
    stop_on_new_contact : a trial is not held once the body touches a body it did not touch
        at the reference pose.

    Invalid values raise :class:`stability.GraspError` when the options are made.
    """

    cap: float = 100.0
    ramp_s: float = 0.2
    hold_s: float = 2.3
    settle_s: float = 0.1
    max_shift: float = 0.002
    max_turn: float = 0.05
    rest_s: float = 0.0
    rest_shift: float = 1e-5
    rest_turn: float = 2e-4
    rtol: float = 0.01
    cap_tol: float = 1e-3
    stop_on_new_contact: bool = True

    def __post_init__(self) -> None:
        def real(v: object) -> bool:
            return (
                isinstance(v, int | float | np.number)
                and not isinstance(v, bool | np.bool_)
                and finite(v)
            )

        def pos(v: object) -> bool:
            return real(v) and v > 0  # type: ignore[operator]

        def nonneg(v: object) -> bool:
            return real(v) and v >= 0  # type: ignore[operator]

        check_ranges(self, {
            **{k: (pos(getattr(self, k)), "a finite number > 0")
               for k in ("cap", "hold_s", "max_shift", "max_turn", "rest_shift", "rest_turn")},
            **{k: (nonneg(getattr(self, k)), "a finite number >= 0")
               for k in ("ramp_s", "settle_s")},
            "rest_s": (nonneg(self.rest_s) and real(self.hold_s) and self.rest_s <= self.hold_s,
                       f"a finite number in [0, hold_s = {self.hold_s!r}]"),
            "rtol": (real(self.rtol) and 0 < self.rtol < 1, "in (0, 1)"),
            "cap_tol": (real(self.cap_tol) and 0 < self.cap_tol < 1, "in (0, 1)"),
            "stop_on_new_contact": (isinstance(self.stop_on_new_contact, bool | np.bool_),
                                    "True or False"),
        })  # fmt: skip


@dataclass(frozen=True)
class HoldTrial:
    """One trial of :func:`static_resistance`: the ``load`` tried [N or N m per unit
    direction], whether it was ``held``, why not (``reason``: "shift", "turn", "moving"
    (not at rest at the end), "new contact: <bodies>"; "" when held), and the displacement
    ``shift`` [m] and rotation ``turn`` [rad] from the reference pose when it ended."""

    load: float
    held: bool
    reason: str
    shift: float
    turn: float


@dataclass(frozen=True)
class Hold:
    """Result of :func:`static_resistance` (module doc).

    value : the largest load held [N or N m per unit direction]: the cap when ``capped``.
    capped : the cap was held.
    bracket : (held, not held) loads at the end of the bisection; ``(cap, inf)`` when capped.
    trials : every trial, in the order run.
    reason : why the bracket's upper load was not held (:class:`HoldTrial` reasons), "cap"
        when capped.
    """

    value: float
    capped: bool
    bracket: tuple[float, float]
    trials: tuple[HoldTrial, ...]
    reason: str


def _moved(
    pa: NDArray[np.float64], qa: NDArray[np.float64], pb: NDArray[np.float64],
    qb: NDArray[np.float64],
) -> tuple[float, float]:  # fmt: skip
    """Displacement [m] and rotation angle [rad] from pose a to pose b."""
    rot = np.zeros(3)
    mujoco.mju_subQuat(rot, qb, qa)
    return math.hypot(*(pb - pa)), math.hypot(*rot)


@dataclass
class _Start:
    """The state every trial starts from: MuJoCo's integration state and the ratchet's
    stops (None without a ratchet)."""

    state: NDArray[np.float64]
    stops: NDArray[np.float64] | None

    def restore(self, model: mujoco.MjModel, data: mujoco.MjData, ratchet: Ratchet | None) -> None:
        mujoco.mj_setState(model, data, self.state, _STATE)
        if ratchet is not None and self.stops is not None:
            ratchet.stops = self.stops
        mujoco.mj_forward(model, data)


def _trial(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    ratchet: Ratchet | None,
    bid: int,
    w: NDArray[np.float64],
    load: float,
    opts: HoldOptions,
) -> HoldTrial:
    """Try ``load * w`` on body ``bid`` from the current state (module doc)."""
    dt = float(model.opt.timestep)
    data.xfrc_applied[bid] = 0.0
    advance(model, data, ratchet, int(round(opts.settle_s / dt)))
    touching = touching_bodies(model, data, bid)
    p0, q0 = data.xipos[bid].copy(), data.xquat[bid].copy()
    n_ramp = int(round(opts.ramp_s / dt))
    n = n_ramp + max(1, int(round(opts.hold_s / dt)))
    rest_from = n - int(round(opts.rest_s / dt))
    every = max(1, int(round(CHECK_S / dt)))
    pa, qa = p0, q0
    shift = turn = 0.0
    for i in range(1, n + 1):
        frac = 1.0 if i >= n_ramp else i / n_ramp
        data.xfrc_applied[bid] = frac * load * w
        advance(model, data, ratchet, 1)
        if i == rest_from:
            pa, qa = data.xipos[bid].copy(), data.xquat[bid].copy()
        if i % every and i != n:
            continue
        shift, turn = _moved(p0, q0, data.xipos[bid], data.xquat[bid])
        reason = ""
        if shift > opts.max_shift or not np.isfinite(shift):
            reason = "shift"
        elif turn > opts.max_turn:
            reason = "turn"
        elif opts.stop_on_new_contact:
            new = touching_bodies(model, data, bid) - touching
            if new:
                reason = "new contact: " + ", ".join(sorted(model.body(b).name for b in new))
        if reason:
            return HoldTrial(float(load), False, reason, shift, turn)
    if opts.rest_s > 0:
        ds, dr = _moved(pa, qa, data.xipos[bid], data.xquat[bid])
        if ds >= opts.rest_shift or dr >= opts.rest_turn:
            return HoldTrial(float(load), False, "moving", shift, turn)
    return HoldTrial(float(load), True, "", shift, turn)


def _checked(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    direction: ArrayLike,
    ratchet: Ratchet | None,
    body: str,
    options: HoldOptions | None,
) -> tuple[HoldOptions, NDArray[np.float64], int, _Start]:
    """The options (defaults when None), the unit direction, the body's id and the start
    state, after the arguments' checks (:class:`stability.GraspError`)."""
    opts = HoldOptions() if options is None else options
    if not isinstance(opts, HoldOptions):
        raise GraspError(f"options must be HoldOptions, got {type(opts).__name__}")
    w = unit_direction(direction)
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0:
        raise GraspError(f"no body named {body!r}")
    if ratchet is not None and (ratchet.model is not model or ratchet.data is not data):
        raise GraspError("ratchet was built on another model or data than the ones passed")
    state = np.empty(mujoco.mj_stateSize(model, _STATE))
    mujoco.mj_getState(model, data, state, _STATE)
    return opts, w, bid, _Start(state, None if ratchet is None else ratchet.stops.copy())


def hold_trial(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    direction: ArrayLike,
    load: float,
    *,
    ratchet: Ratchet | None = None,
    body: str = "object",
    options: HoldOptions | None = None,
) -> HoldTrial:
    """Whether ``body`` holds ``load`` [N or N m per unit direction] along ``direction``
    (one trial of :func:`static_resistance`, module doc; ``options.cap`` is not used).
    Arguments as there; ``data`` and the ratchet's stops are restored on return."""
    if not (isinstance(load, (int, float, np.number)) and np.isfinite(load) and load >= 0):
        raise GraspError(f"load must be a finite number >= 0, got {load!r}")
    opts, w, bid, start = _checked(model, data, direction, ratchet, body, options)
    try:
        start.restore(model, data, ratchet)
        return _trial(model, data, ratchet, bid, w, float(load), opts)
    finally:
        start.restore(model, data, ratchet)


def static_resistance(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    direction: ArrayLike,
    *,
    ratchet: Ratchet | None = None,
    body: str = "object",
    options: HoldOptions | None = None,
) -> Hold:
    """The largest load along ``direction`` that ``body`` holds (module doc).

    Parameters
    ----------
    model, data : a settled scene; every trial starts from ``data``'s state, to which
        ``data`` is restored on return (``model`` is not changed except by ``ratchet``'s
        stops, which are restored too).
    direction : wrench direction (fx, fy, fz, tx, ty, tz), world axes, the force through the
        body's centre of mass; normalised so that its larger block has unit norm.
    ratchet : a :class:`ihm.ratchet.Ratchet` on ``model`` and ``data`` (nonbackdrivable
        joints), stepped with the trials.
    body : the loaded body (a free body: the object).
    options : :class:`HoldOptions`; its defaults when None.
    """
    opts, w, bid, start = _checked(model, data, direction, ratchet, body, options)
    trials: list[HoldTrial] = []

    def attempt(load: float) -> HoldTrial:
        start.restore(model, data, ratchet)
        t = _trial(model, data, ratchet, bid, w, load, opts)
        trials.append(t)
        return t

    cap = float(opts.cap)
    try:
        top = attempt(cap)
        if top.held:
            return Hold(cap, True, (cap, math.inf), tuple(trials), "cap")
        lo, hi, reason = 0.0, cap, top.reason
        while hi - lo > max(opts.rtol * lo, opts.cap_tol * cap):
            mid = 0.5 * (lo + hi)
            t = attempt(mid)
            if t.held:
                lo = mid
            else:
                hi, reason = mid, t.reason
        return Hold(lo, False, (lo, hi), tuple(trials), reason)
    finally:
        start.restore(model, data, ratchet)
