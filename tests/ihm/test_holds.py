"""ihm.holds (static resistance by bisection on held loads) on the analytic pinch built in
MuJoCo (``assets/analytic/pinch.xml``): two fingers squeeze a box, breakaway 2 mu tau / L."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from ihm.holds import Hold, HoldOptions, hold_trial, static_resistance
from ihm.ratchet import Ratchet
from stability import GraspError
from stability.examples import PINCH_MAX_Z, PINCH_TORQUE

PINCH = Path(__file__).resolve().parents[2] / "assets" / "analytic" / "pinch.xml"
STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def _pinch() -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = mujoco.MjModel.from_xml_path(str(PINCH))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    d.ctrl[:] = PINCH_TORQUE
    mujoco.mj_step(m, d, nstep=500)
    return m, d


def _state(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    s = np.empty(mujoco.mj_stateSize(m, STATE))
    mujoco.mj_getState(m, d, s, STATE)
    return s


@pytest.mark.parametrize("sign", [1, -1])
def test_pinch_static_resistance_is_the_analytic_one(sign: int) -> None:
    """Along +-z the largest held force is 2 mu tau / L within 3 %; the bracket is as narrow
    as the tolerance asks, its upper end slid out (not held); the state is restored."""
    m, d = _pinch()
    before = _state(m, d)
    opts = HoldOptions(cap=5.0)
    h = static_resistance(m, d, [0, 0, 2.0 * sign, 0, 0, 0], options=opts)  # normalised
    assert isinstance(h, Hold) and not h.capped
    assert h.value == pytest.approx(PINCH_MAX_Z, rel=0.03)
    lo, hi = h.bracket
    assert lo == h.value < hi and hi - lo <= max(opts.rtol * lo, opts.cap_tol * opts.cap)
    assert h.reason == "shift"
    assert h.trials[0].load == 5.0 and not h.trials[0].held
    assert any(t.held and t.load == lo for t in h.trials)
    assert any(not t.held and t.load == hi for t in h.trials)
    np.testing.assert_array_equal(_state(m, d), before)  # restored exactly
    again = static_resistance(m, d, [0, 0, sign, 0, 0, 0], options=opts)
    assert again == h  # every trial starts from the same state: the same answer


def test_one_trial_below_and_above_breakaway() -> None:
    """A single trial: 0.9 of the breakaway is held (the object crept well under 2 mm),
    1.1 of it slides out; the state is restored after each."""
    m, d = _pinch()
    before = _state(m, d)
    below = hold_trial(m, d, [0, 0, 1, 0, 0, 0], 0.9 * PINCH_MAX_Z)
    assert below.held and below.reason == "" and below.shift < 2e-4
    above = hold_trial(m, d, [0, 0, 1, 0, 0, 0], 1.1 * PINCH_MAX_Z)
    assert not above.held and above.reason == "shift" and above.shift > 0.002
    np.testing.assert_array_equal(_state(m, d), before)
    for load in (-1.0, float("inf")):
        with pytest.raises(GraspError, match="load"):
            hold_trial(m, d, [0, 0, 1, 0, 0, 0], load)


def test_pushing_into_a_ratcheted_finger_is_capped() -> None:
    """Along +x into finger 2 with both fingers ratcheted the load is held up to the cap
    (the thesis' passive reaction): one trial, the stops as they were."""
    m, d = _pinch()
    r = Ratchet(m, d, [0, 1])
    stops = r.stops.copy()
    h = static_resistance(m, d, [1, 0, 0, 0, 0, 0], ratchet=r, options=HoldOptions(cap=5.0))
    assert h.capped and h.value == 5.0 and h.bracket == (5.0, math.inf) and h.reason == "cap"
    assert len(h.trials) == 1 and h.trials[0].held and h.trials[0].shift < 0.002
    np.testing.assert_array_equal(r.stops, stops)


def test_rest_check_calls_slow_creep_not_held() -> None:
    """With the rest check (0.01 mm per 0.5 s) the pinch's steady creep below breakaway is
    "moving": the value drops to about 1.85 N (module doc)."""
    m, d = _pinch()
    h = static_resistance(m, d, [0, 0, 1, 0, 0, 0], options=HoldOptions(cap=5.0, rest_s=0.5))
    assert h.reason == "moving" and 1.8 < h.value < 1.9


@pytest.mark.parametrize(
    "kw",
    [
        {"cap": 0.0},
        {"cap": float("nan")},
        {"ramp_s": -0.1},
        {"hold_s": 0.0},
        {"max_shift": -1.0},
        {"max_turn": 0.0},
        {"rest_s": 3.0},
        {"rest_shift": 0.0},
        {"rtol": 0.0},
        {"cap_tol": 1.0},
        {"settle_s": -1.0},
        {"stop_on_new_contact": 1},
        {"hold_s": True},
        {"cap": "10"},
    ],
)
def test_bad_options_raise(kw: dict) -> None:
    with pytest.raises(GraspError):
        HoldOptions(**kw)


def test_bad_arguments_raise() -> None:
    m, d = _pinch()
    for direction in ([0, 0, 0, 0, 0, 0], [1, 0, 0], [np.nan, 0, 0, 0, 0, 0]):
        with pytest.raises(GraspError, match="direction"):
            static_resistance(m, d, direction)
    with pytest.raises(GraspError, match="no body"):
        static_resistance(m, d, [0, 0, 1, 0, 0, 0], body="nope")
    m2, d2 = _pinch()
    with pytest.raises(GraspError, match="ratchet"):
        static_resistance(m, d, [0, 0, 1, 0, 0, 0], ratchet=Ratchet(m2, d2, [0, 1]))
    with pytest.raises(GraspError, match="HoldOptions"):
        static_resistance(m, d, [0, 0, 1, 0, 0, 0], options={"cap": 1.0})  # type: ignore[arg-type]
