"""Start-state sampling of the four-finger rotation env (issue 29). Failure replay: a start
whose episode dropped the object comes back, with its physics read back from the MjModel, at
the stated rate; ``replay_prob=0`` changes nothing. Turned cube starts: the cube's turn from
the hand's square, read from MuJoCo's ``xmat``, and the rate of turned starts."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from envs.four_finger import FourFingerError, FourFingerRotate, Randomization
from envs.four_finger.env import REPLAY_SIZE, TURNED, cube_turn
from envs.four_finger.physics import DROP_Z
from train.rotation import RotateConfig, make_env, parse_config

ZERO = np.zeros(12, np.float32)


def _drop(env: FourFingerRotate) -> bool:
    """Put the object below the drop height and step: the episode ends as a drop."""
    adr = env.model.jnt_qposadr[env.model.joint("object").id]
    env.data.qpos[adr + 2] = DROP_Z - 0.02
    env.data.qvel[:] = 0.0
    return env.step(ZERO)[2]


def test_a_dropped_start_comes_back_with_its_physics() -> None:
    """``replay_prob=1``: the reset after a drop restarts the same grasp with the same
    physics sample (friction and mass read back from the MjModel); it leaves the buffer, so
    the reset after an episode that held draws afresh."""
    env = FourFingerRotate("sphere", randomize=Randomization(), replay_prob=1.0)
    b = env.physics.obj_body
    _, info = env.reset(seed=3)
    s0, friction0 = env.scaler.current, env.model.pair_friction.copy()
    mass0 = env.model.body_mass[b]
    assert _drop(env)
    _, again = env.reset()
    assert again["grasp"] == info["grasp"] and env.scaler.current == s0
    np.testing.assert_array_equal(env.model.pair_friction, friction0)
    assert env.model.body_mass[b] == mass0
    assert not env._failed  # the replayed start left the buffer
    assert not env.step(ZERO)[2]  # this time it holds
    draws = []
    for _ in range(5):
        env.reset()
        draws.append(env.scaler.current)
        assert not env.step(ZERO)[2]
    assert s0 not in draws and len({d.friction for d in draws}) == 5


def test_replay_rate_and_buffer_size() -> None:
    """Every episode dropped: with ``replay_prob=0.5`` about half the resets restart a
    remembered start (400 resets, 3 sigma); the buffer keeps the last ``REPLAY_SIZE``."""
    env = FourFingerRotate("sphere", randomize=Randomization(), replay_prob=0.5)
    env.reset(seed=0)
    seen, replays = [], 0
    for _ in range(400):
        assert _drop(env)
        seen.append(env.scaler.current)
        env.reset()
        replays += env.scaler.current in seen
    assert abs(replays / 400 - 0.5) < 3 * np.sqrt(0.25 / 400)
    rare = FourFingerRotate("sphere", randomize=Randomization(), replay_prob=1e-12)
    rare.reset(seed=0)
    for _ in range(REPLAY_SIZE + 10):
        _drop(rare)
        rare.reset()
    assert len(rare._failed) == REPLAY_SIZE


def test_no_replay_leaves_the_draws_unchanged() -> None:
    """``replay_prob=0`` (the default): dropping every episode or none, the same seed gives
    the same grasps and physics."""
    runs = []
    for drop in (True, False):
        env = FourFingerRotate("sphere", randomize=Randomization())
        _, info = env.reset(seed=5)
        seq = [(info["grasp"], env.scaler.current)]
        for _ in range(8):
            assert _drop(env) if drop else not env.step(ZERO)[2]
            _, info = env.reset()
            seq.append((info["grasp"], env.scaler.current))
        assert not env._failed
        runs.append(seq)
    assert runs[0] == runs[1]


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_replay_prob_outside_unit_interval_is_refused(bad: float) -> None:
    with pytest.raises(FourFingerError, match="replay_prob"):
        FourFingerRotate("sphere", replay_prob=bad)
    with pytest.raises(SystemExit):
        parse_config(["--replay-prob", str(bad)])


def test_cli_replays_in_training_envs_only() -> None:
    """``--replay-prob`` reaches the training envs; validation envs never replay."""
    cfg = parse_config(["--replay-prob", "0.3"])
    assert cfg.starts.replay_prob == 0.3 and RotateConfig().starts.replay_prob == 0.0
    assert make_env(cfg)().unwrapped.starts.replay_prob == 0.3
    assert make_env(cfg, train=False)().unwrapped.starts.replay_prob == 0.0


@pytest.mark.parametrize("deg", [0.0, 10.0, 30.0, 44.0, 60.0, 100.0, -170.0])
def test_cube_turn_is_the_yaw_modulo_a_quarter_turn(deg: float) -> None:
    """A cube yawed by ``deg`` about z (and tipped a little about x first) is turned by
    ``deg`` folded into [-45, 45] degrees."""
    yaw, tip = math.radians(deg), 0.1
    q_yaw = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    q_tip = np.array([math.cos(tip / 2), math.sin(tip / 2), 0.0, 0.0])
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, q_yaw, q_tip)
    want = math.remainder(yaw, math.pi / 2)
    assert cube_turn(q) == pytest.approx(want, abs=1e-9)


@pytest.mark.slow
def test_turned_starts_read_back_from_mujoco_at_the_stated_rate() -> None:
    """``turned_prob=1``: every start's cube, its x axis read from ``data.xmat``, is turned
    at least 22.5 degrees from the hand's square; ``0.5``: about half the starts plus half
    the cache's own share of turned ones (400 resets, 3 sigma)."""
    env = FourFingerRotate("cube", grip="firm", turned_prob=1.0)
    env.reset(seed=1)
    b = env.physics.obj_body
    for _ in range(20):
        env.reset()
        x_axis = env.data.xmat[b].reshape(3, 3)[:, 0]
        turn = math.remainder(math.atan2(x_axis[1], x_axis[0]), math.pi / 2)
        assert abs(turn) >= TURNED - 0.02  # the start is not perfectly level
    half = FourFingerRotate("cube", grip="firm", turned_prob=0.5)
    share = len(half._turned) / len(half.grasps)
    assert 0.05 < share < 0.5  # turned starts are the minority of settled grasps
    half.reset(seed=2)
    n = 400
    hits = sum(half.reset()[1]["grasp"] in set(half._turned.tolist()) for _ in range(n))
    p = 0.5 + 0.5 * share
    assert abs(hits / n - p) < 3 * math.sqrt(p * (1 - p) / n)


def test_turned_starts_are_refused_for_round_objects_and_bad_rates() -> None:
    with pytest.raises(FourFingerError, match="turned_prob is for the cube"):
        FourFingerRotate("cylinder", turned_prob=0.5)
    with pytest.raises(FourFingerError, match="turned_prob"):
        FourFingerRotate("cube", turned_prob=1.5)
    with pytest.raises(SystemExit):
        parse_config(["--turned-prob", "0.5"])  # the default object is the sphere
    cfg = parse_config(["--object", "cube", "--turned-prob", "0.5"])
    assert make_env(cfg)().unwrapped.starts.turned_prob == 0.5
    assert make_env(cfg, train=False)().unwrapped.starts.turned_prob == 0.0
