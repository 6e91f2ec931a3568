"""``ihm/FourFingerRotateMixed-v0`` (:class:`envs.four_finger.MixedObjectRotate`): the object
drawn per episode, the full-range physics draw, and the start grasps of every object."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the env ids)
from envs.four_finger import (
    TRAIN_OBJECTS,
    FourFingerError,
    MixedObjectRotate,
    Randomization,
    StartSettings,
)

SMALL = StartSettings(n_grasps=8)


@pytest.fixture(scope="module")
def mixed() -> MixedObjectRotate:
    env = MixedObjectRotate(starts=SMALL)
    yield env
    env.close()


def test_the_object_is_drawn_per_episode_and_reproducibly(mixed) -> None:
    """Every training object is drawn (each about a third of 60 resets), the same seed draws
    the same sequence, ``options["object"]`` picks one, and the spaces are every object's."""

    def draws(seed: int) -> list[str]:
        _, info = mixed.reset(seed=seed)
        return [info["object"]] + [mixed.reset()[1]["object"] for _ in range(59)]

    a = draws(5)
    assert draws(5) == a and draws(6) != a
    counts = {o: a.count(o) for o in TRAIN_OBJECTS}
    assert all(10 <= c <= 30 for c in counts.values()), counts
    obs, info = mixed.reset(options={"object": "cube", "grasp": 3})
    assert info["object"] == "cube" and info["grasp"] == 3 and mixed.current == "cube"
    assert mixed.observation_space.contains(obs)
    _, _, _, _, info = mixed.step(np.zeros(12, dtype=np.float32))
    assert info["object"] == "cube"
    with pytest.raises(FourFingerError, match="options\\['object'\\]"):
        mixed.reset(options={"object": "teapot"})
    with pytest.raises(FourFingerError, match="distinct"):
        MixedObjectRotate(("sphere", "sphere"))


def test_object_weights_set_the_draw() -> None:
    """``set_object_weights``: an object of weight 0 is never drawn, the others in
    proportion; weights that do not name every object, or are all zero, are refused."""
    env = MixedObjectRotate(starts=SMALL)
    env.set_object_weights({"sphere": 0.0, "cylinder": 1.0, "cube": 3.0})
    env.reset(seed=0)
    a = [env.reset()[1]["object"] for _ in range(200)]
    assert "sphere" not in a and 0.6 < a.count("cube") / 200 < 0.9
    for bad in ({"sphere": 1.0}, {"sphere": 0.0, "cylinder": 0.0, "cube": 0.0}):
        with pytest.raises(FourFingerError, match="object weights"):
            env.set_object_weights(bad)
    env.close()


def test_gym_make_builds_the_mixed_env() -> None:
    env = gym.make("ihm/FourFingerRotateMixed-v0", objects=("sphere", "cube"), starts=SMALL)
    _, info = env.reset(seed=0)
    assert info["object"] in ("sphere", "cube") and env.spec.max_episode_steps == 64
    env.close()


def test_full_range_draw_reads_back_from_mujoco(mixed) -> None:
    """After ``set_randomization(Randomization())`` each reset draws physics within the full
    ranges, and the drawn object's MuJoCo model carries them: its contact pairs' friction,
    its mass and the servo gains are the nominal values times the draw."""
    mixed.set_randomization(Randomization())
    r = Randomization()
    seen = set()
    for k in range(12):
        _, info = mixed.reset(seed=100 + k) if k == 0 else mixed.reset()
        env = mixed.env
        s, sc, m = env.scaler.current, env.scaler, env.model
        seen.add(info["object"])
        assert r.friction[0] <= s.friction <= r.friction[1]
        assert r.mass[0] <= s.mass <= r.mass[1]
        assert all(r.gain[0] <= g <= r.gain[1] for g in s.gain)
        p = sc.obj_pairs
        np.testing.assert_allclose(m.pair_friction[p, 0], sc.friction0[p, 0] * s.friction)
        np.testing.assert_allclose(m.pair_friction[p, 2], sc.friction0[p, 2] * s.torsional)
        np.testing.assert_allclose(m.body_mass[sc.obj_body], 0.1 * s.mass, rtol=1e-9)
        np.testing.assert_allclose(m.actuator_gainprm[:, 0], sc.kp0 * np.asarray(s.gain))
    assert seen == set(TRAIN_OBJECTS)


@pytest.mark.parametrize("obj", TRAIN_OBJECTS)
def test_start_grasps_hold_with_zero_actions(obj) -> None:
    """Each object's first start grasps, drawn through the mixed env, hold for 40 policy
    steps (2 s) with the hand still."""
    env = MixedObjectRotate(starts=SMALL)
    for i in range(3):
        env.reset(seed=i, options={"object": obj, "grasp": i})
        for _ in range(40):
            _, _, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
            assert not terminated, f"{obj} grasp {i} dropped"
    env.close()


def test_the_privileged_critic_reads_the_object() -> None:
    """With ``privileged=True`` the observation ends with the object's one-hot code (the
    critic's only; the actor's frames are the drawn env's own), inside the space."""
    from envs.four_finger import N_OBS, N_PRIVILEGED, ObservationSettings

    env = MixedObjectRotate(
        starts=SMALL, observation=ObservationSettings(history=2, privileged=True)
    )
    assert env.observation_space.shape == (2 * N_OBS + N_PRIVILEGED + 3,)
    for k, obj in enumerate(TRAIN_OBJECTS):
        obs, _ = env.reset(seed=k, options={"object": obj, "grasp": 0})
        assert env.observation_space.contains(obs)
        np.testing.assert_array_equal(obs[-3:], np.eye(3)[k])
        own = env.envs[obj]._stacked(env.envs[obj]._sensed(), first=True)
        np.testing.assert_array_equal(obs[: 2 * N_OBS], own[: 2 * N_OBS])
        obs, *_ = env.step(np.zeros(12, dtype=np.float32))
        np.testing.assert_array_equal(obs[-3:], np.eye(3)[k])
    env.close()
