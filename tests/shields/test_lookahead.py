"""shields.lookahead / shields.LookaheadShield: the perfect-model yardstick (issue 30).

Its one-step simulation is what the env then does, bit for bit; it never lets through an
action its own simulation marks unsafe and never changes a safe one; a shield call leaves
the env's state untouched; a shielded env is deterministic under a seed. Also the shield
options the study trains in (shields.make_shield) and the QP's drop criteria."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import envs  # noqa: F401  (registers ihm/FourFingerRotate-v0)
from envs.four_finger import FourFingerRotate, PhysicsSample
from shields import (
    SHIELDS,
    GraspShield,
    Lookahead,
    LookaheadShield,
    ShieldError,
    ShieldLimits,
    drop_limits,
    make_shield,
)
from shields.lookahead import LOOKAHEAD_STATUSES

FULL = mujoco.mjtState.mjSTATE_INTEGRATION  # every state bit: the warm start and ctrl too


def full_state(env: FourFingerRotate) -> np.ndarray:
    s = np.empty(mujoco.mj_stateSize(env.model, FULL))
    mujoco.mj_getState(env.model, env.data, s, FULL)
    return s


def shield_for(env: FourFingerRotate, **kw: object) -> Lookahead:
    return Lookahead(
        env.model, max_setpoint_step=env.max_setpoint_step, frame_skip=env.frame_skip, **kw
    )


def random_states(env: FourFingerRotate, n: int, seed: int = 0, most: int = 6):
    """(state index, action): cached grasps after up to ``most`` random steps, with random
    actions."""
    rng = np.random.default_rng(seed)
    for g in range(n):
        env.reset(options={"grasp": g})
        for _ in range(int(rng.integers(0, most))):
            _, _, term, _, _ = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
            if term:
                break
        yield g, rng.uniform(-1, 1, 12)


def test_simulation_is_the_env_step_bit_for_bit() -> None:
    env = FourFingerRotate()
    la = shield_for(env)
    for _, a in random_states(env, 5, seed=1):
        la.load(env.data)
        sim = la.simulate(env.data, a)
        qpos, qvel = sim.qpos.copy(), sim.qvel.copy()
        env.step(a.astype(np.float64))
        assert np.array_equal(qpos, env.data.qpos)
        assert np.array_equal(qvel, env.data.qvel)


@pytest.mark.parametrize("limits", ["thesis", "drop"])
def test_never_passes_an_action_its_simulation_marks_unsafe(limits: str) -> None:
    env = FourFingerRotate()
    lim = ShieldLimits() if limits == "thesis" else drop_limits(env)
    la = shield_for(env, limits=lim, horizon=1 if limits == "thesis" else 3)
    check = shield_for(env, limits=lim, horizon=la.horizon)  # a second judge, fresh state
    seen = set()
    n, most = (12, 6) if limits == "thesis" else (16, 30)
    for _, a in random_states(env, n, seed=2, most=most):
        before = full_state(env)
        res = la(env.data, a, home_ctrl=env.grasps.ctrl[0])
        seen.add(res.status)
        assert res.status in LOOKAHEAD_STATUSES
        assert np.array_equal(before, full_state(env))
        # the verdict of the returned action, judged again from scratch
        again = check(env.data, res.action)
        if res.status in ("safe", "corrected", "home"):
            assert again.status == "safe", (res.status, again.reason)
        if res.status == "safe":
            assert res.action is not a and np.array_equal(res.action, a)  # bit for bit
            assert res.correction == 0.0 and res.sims >= 1
        else:
            assert res.reason in ("drop", "box", "tilt", "contacts")
            assert check(env.data, a).status != "safe"  # the agent's action was unsafe
        if res.status == "corrected":
            assert 0.0 <= res.scale < 1.0
            np.testing.assert_array_equal(res.action, res.scale * a)
        if res.status == "fallback":  # nothing it tried was safe, the zero action included
            assert check(env.data, np.zeros(12)).status != "safe"
    assert "safe" in seen and len(seen) >= 2, seen
    if limits == "thesis":
        assert "corrected" in seen, seen


def test_safe_action_unchanged_inside_the_wrapper() -> None:
    env = LookaheadShield(gym.make("ihm/FourFingerRotate-v0"), limits=None, horizon=1)
    env.reset(seed=0)
    zero = np.zeros(12, dtype=np.float32)  # holding still a settled grasp is safe
    _, _, _, _, info = env.step(zero)
    assert info["shield_status"] == "safe" and not info["shield_intervened"]
    assert np.array_equal(info["executed_action"], zero.astype(np.float64))
    for key in ("shield_correction", "shield_subset", "shield_solve_time_s", "shield_scale",
                "shield_sims", "shield_reason", "shield_step_seconds",
                "shield_episode_interventions", "shield_episode_seconds"):  # fmt: skip
        assert key in info


def test_shield_call_leaves_the_env_untouched() -> None:
    env = LookaheadShield(gym.make("ihm/FourFingerRotate-v0"), horizon=3)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(5):
        u = env.unwrapped
        before = full_state(u)
        obs_before = u.observe().copy()
        ctrl_before = u.data.ctrl.copy()
        a, _ = env.shield(rng.uniform(-1, 1, 12))
        assert np.array_equal(before, full_state(u))
        assert np.array_equal(ctrl_before, u.data.ctrl)
        assert np.array_equal(obs_before, u.observe())
        env.step(a)


def test_deterministic_under_a_seed() -> None:
    def run(seed: int) -> tuple[list[bool], list[str], np.ndarray]:
        env = make_shield(gym.make("ihm/FourFingerRotate-v0"), "lookahead")
        env.reset(seed=seed)
        env.action_space.seed(seed)
        flags, statuses = [], []
        for _ in range(80):
            _, _, term, _, info = env.step(env.action_space.sample())
            flags.append(info["shield_intervened"])
            statuses.append(info["shield_status"])
            if term:
                env.reset()
        return flags, statuses, env.unwrapped.data.qpos.copy()

    a, b, c = run(4), run(4), run(5)
    assert a[0] == b[0] and a[1] == b[1] and np.array_equal(a[2], b[2])
    assert any(a[0])  # random actions on a grasp: the shield intervenes
    assert not np.array_equal(a[2], c[2])


def test_lookahead_keeps_a_random_policy_from_dropping_in_a_training_episode() -> None:
    """Against the env's own termination: 64-step episodes of uniform random actions from
    the same start grasps drop without the shield and not, or less often, with it."""

    def drops(shield: str) -> int:
        env = make_shield(gym.make("ihm/FourFingerRotate-v0"), shield)
        rng = np.random.default_rng(0)
        n = 0
        for ep in range(6):
            env.reset(seed=ep)
            for _ in range(64):
                _, _, term, _, _ = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
                if term:
                    n += 1
                    break
        return n

    bare, shielded = drops("none"), drops("lookahead")
    assert bare >= 2 and shielded < bare, (bare, shielded)


def test_make_shield_and_bad_options() -> None:
    base = gym.make("ihm/FourFingerRotate-v0")
    assert make_shield(base, "none") is base
    assert isinstance(make_shield(gym.make("ihm/FourFingerRotate-v0"), "qp"), GraspShield)
    la = make_shield(gym.make("ihm/FourFingerRotate-v0"), "lookahead")
    assert isinstance(la, LookaheadShield) and la.lookahead.horizon > 1
    assert not la.lookahead.limits.contacts and not la.lookahead.limits.tilt  # the sphere
    cube = make_shield(gym.make("ihm/FourFingerRotate-v0", object="cube"), "lookahead")
    assert cube.lookahead.limits.tilt  # a cube's tilt is a failure
    with pytest.raises(ShieldError, match="unknown shield"):
        make_shield(base, "magic")
    assert set(SHIELDS) >= {"none", "qp", "qp-drift", "lookahead", "lookahead-qp"}
    env = FourFingerRotate()
    for kw, msg in (
        ({"frame_skip": 0}, "frame_skip"),
        ({"bisections": -1}, "bisections"),
        ({"horizon": 0}, "horizon"),
        ({"limits": ShieldLimits(relax_contacts=True)}, "relax_contacts"),
    ):
        args = {"max_setpoint_step": 0.05, "frame_skip": 25, **kw}
        with pytest.raises(ShieldError, match=msg):
            Lookahead(env.model, **args)
    la = shield_for(env)
    env.reset(seed=0)
    with pytest.raises(ShieldError, match="shape"):
        la(env.data, np.zeros(3))
    with pytest.raises(ShieldError, match="NaN"):
        la(env.data, np.full(12, np.nan))
    for bad in ("contacts", "friction", "tilt"):
        with pytest.raises(ShieldError, match=bad):
            ShieldLimits(**{bad: 1})


def test_latency_is_refused() -> None:
    lat = PhysicsSample(latency=1)
    env = LookaheadShield(gym.make("ihm/FourFingerRotate-v0", physics=lat))
    env.reset(seed=0)
    with pytest.raises(ShieldError, match="latency"):
        env.step(np.zeros(12, dtype=np.float32))


def test_horizon_applies_when_the_contact_criterion_is_waived() -> None:
    """With contacts on and no force-closure set before the step, only the termination
    counts, on the action's step and on each held step of the horizon."""
    env = FourFingerRotate()
    la = shield_for(env, horizon=3)
    waived = 0
    for _, a in random_states(env, 16, seed=6, most=30):
        if la.closure_now(env.data):
            continue
        waived += 1
        res = la(env.data, a)
        if res.status == "safe":
            assert res.sims == 3  # the action's step and both held steps were simulated
        else:
            assert res.reason == "drop"
    assert waived >= 1
