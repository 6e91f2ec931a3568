"""Tests of the islands-and-bridges environment (issue 4)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs
from envs import Box, Disc, IslandsBridges
from envs.islands_bridges import (
    DEFAULT_BRIDGES,
    DEFAULT_ISLANDS,
    RING_BRIDGES,
    RING_ISLANDS,
    SPUR_BRIDGES,
    SPUR_ISLANDS,
    _map_title,
    draw_map,
)

ENV_ID = "ihm/IslandsBridges-v0"  # the five-island map with the dead-end island I4
RING_ID = "ihm/IslandsBridgesRing-v0"  # the four-island ring
#: (id, islands, bridges) of every registered map
MAPS = ((ENV_ID, SPUR_ISLANDS, SPUR_BRIDGES), (RING_ID, RING_ISLANDS, RING_BRIDGES))


def _no_warnings(fn, *args, **kwargs) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn(*args, **kwargs)
    assert not caught, [f"{w.category.__name__}: {w.message}" for w in caught]


@pytest.mark.parametrize("env_id", [ENV_ID, RING_ID])
@pytest.mark.parametrize("reward", ["dense", "sparse"])
def test_gymnasium_check_env_no_warnings(reward, env_id):
    # through gym.make so that the checker also tests the render modes via env.spec
    env = gym.make(env_id, reward=reward).unwrapped
    _no_warnings(gym_check_env, env)
    env = gym.make(env_id, reward=reward, render_mode="rgb_array").unwrapped
    _no_warnings(gym_check_env, env)


@pytest.mark.parametrize("reward", ["dense", "sparse"])
def test_sb3_check_env_no_warnings(reward):
    _no_warnings(sb3_check_env, IslandsBridges(reward=reward), warn=True)


def _rollout(seed: int, actions: np.ndarray, reward: str = "dense"):
    env = gym.make(ENV_ID, reward=reward)
    obs, info = env.reset(seed=seed)
    trace = [("reset", obs, info)]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        trace.append(("step", obs, r, term, trunc, info))
        if term or trunc:
            obs, info = env.reset()
            trace.append(("reset", obs, info))
    return trace


@pytest.mark.parametrize("reward", ["dense", "sparse"])
def test_same_seed_same_rollout(reward):
    actions = np.random.default_rng(7).uniform(-1, 1, size=(300, 2)).astype(np.float32)
    a, b = _rollout(3, actions, reward), _rollout(3, actions, reward)
    assert len(a) == len(b) and sum(t[0] == "reset" for t in a) > 2  # episodes did end
    for ta, tb in zip(a, b, strict=True):
        assert ta[0] == tb[0]
        np.testing.assert_array_equal(ta[1], tb[1])
        assert ta[2:] == tb[2:]
    c = _rollout(4, actions, reward)
    assert not np.array_equal(a[0][1], c[0][1])


def _env_at(start, goal, **kwargs) -> IslandsBridges:
    env = IslandsBridges(**kwargs)
    env.reset(seed=0, options={"start": start, "goal": goal})
    return env


@pytest.mark.parametrize("reward", ["dense", "sparse"])
def test_step_onto_goal_succeeds(reward):
    # I0 is Disc((0.4, 0.4), 0.3): start 0.15 left of the goal, one full step right
    env = _env_at((0.25, 0.4), (0.4, 0.4), reward=reward)
    obs, r, term, trunc, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
    np.testing.assert_allclose(obs, [0.35, 0.4, 0.4, 0.4], atol=1e-7)
    assert term and not trunc
    assert info["is_success"] and not info["failure"]
    assert info["distance_to_goal"] == pytest.approx(0.05)
    assert info["distance_to_edge"] == pytest.approx(0.3 - 0.05)
    assert r == (1.0 if reward == "sparse" else pytest.approx(-0.05))
    assert r == info["reward_goal"]


@pytest.mark.parametrize("reward", ["dense", "sparse"])
def test_step_off_bridge_fails(reward):
    # B0 is Box((0.6, 0.35), (1.35, 0.45)): from its middle line, a full step north falls off
    env = _env_at((0.8, 0.4), (1.6, 1.55), reward=reward)
    obs, r, term, trunc, info = env.step(np.array([0.0, 1.0], dtype=np.float32))
    assert term and not trunc
    assert info["failure"] and not info["is_success"]
    assert info["distance_to_edge"] == pytest.approx(-0.05)
    assert info["distance_to_edge"] < 0
    d = np.hypot(1.6 - 0.8, 1.55 - 0.5)
    assert info["distance_to_goal"] == pytest.approx(d)
    # no failure penalty: the reward is the plain goal term
    assert r == (0.0 if reward == "sparse" else pytest.approx(-d))
    assert obs in env.observation_space


def test_dense_reward_is_minus_distance_and_sparse_zero_while_walking():
    rng = np.random.default_rng(0)
    for reward in ("dense", "sparse"):
        env = IslandsBridges(reward=reward)
        env.reset(seed=1)
        for _ in range(50):
            before = env.state.copy()
            a = rng.uniform(-0.3, 0.3, size=2).astype(np.float32)
            _, r, term, _, info = env.step(a)
            np.testing.assert_allclose(env.state, before + 0.1 * a.astype(float))
            d = float(np.linalg.norm(env.state - env.goal))
            assert info["distance_to_goal"] == pytest.approx(d)
            assert r == (pytest.approx(-d) if reward == "dense" else float(info["is_success"]))
            assert term == (info["failure"] or info["is_success"])
            assert info["failure"] == (env.safe_distance(env.state) < 0)
            if term:
                env.reset()


def test_action_clipped_and_predict():
    # (1.0, 0.4) is on B0 (and, on the v0 map, where the spur B4 leaves it): 0.05 from the edge
    env = _env_at((1.0, 0.4), (1.6, 1.55), max_step=0.05)
    assert env.action_scale == 0.05
    np.testing.assert_allclose(env.predict([1.0, 0.4], [3.0, -0.5]), [1.05, 0.375])
    env.step(np.array([3.0, 0.0]))  # out of the action space, clipped to 1
    np.testing.assert_allclose(env.state, [1.05, 0.4])
    assert env.safe_distance([1.0, 0.4]) == pytest.approx(0.05)
    assert env.safe_distance([0.8, 0.6]) == pytest.approx(0.3 - np.hypot(0.4, 0.2))  # I0
    assert env.safe_pieces == DEFAULT_ISLANDS + DEFAULT_BRIDGES


def test_sparse_goal_within_eps_but_off_map_is_failure():
    # goal near I1's south edge (y = 0.15); step south within goal_eps of it but off the map
    env = _env_at((1.6, 0.2), (1.6, 0.16), reward="sparse", goal_eps=0.1)
    _, r, term, _, info = env.step(np.array([0.0, -0.8], dtype=np.float32))
    assert term and info["failure"] and not info["is_success"] and r == 0.0


@pytest.mark.parametrize(("env_id", "islands", "bridges"), MAPS)
def test_start_and_goal_on_different_islands_in_safe_region(env_id, islands, bridges):
    env = gym.make(env_id).unwrapped
    seen = set()
    for seed in range(300):
        obs, info = env.reset(seed=seed)
        s, g = obs[:2].astype(float), obs[2:].astype(float)
        assert env.safe_distance(env.state) >= 0 and env.safe_distance(env.goal) >= 0
        i, j = info["start_island"], info["goal_island"]
        assert i >= 0 and j >= 0 and i != j
        assert islands[i].signed_distance(env.state) >= 0
        assert islands[j].signed_distance(env.goal) >= 0
        assert np.linalg.norm(env.state - env.goal) > env.goal_eps
        np.testing.assert_allclose(s, env.state, atol=1e-6)
        np.testing.assert_allclose(g, env.goal, atol=1e-6)
        seen.add(i)
    assert seen == set(range(len(islands)))


def test_same_island_allowed_when_asked():
    env = IslandsBridges(different_islands=False)
    same = 0
    for seed in range(200):
        _, info = env.reset(seed=seed)
        same += info["start_island"] == info["goal_island"]
        assert np.linalg.norm(env.state - env.goal) > env.goal_eps
    assert same > 0


def test_maps_are_fixed():
    ring_islands = (
        Disc(center=(0.4, 0.4), radius=0.3),
        Box(lo=(1.3, 0.15), hi=(1.9, 0.65)),
        Disc(center=(1.6, 1.55), radius=0.3),
        Box(lo=(0.1, 1.2), hi=(0.7, 1.8)),
    )
    ring_bridges = (
        Box(lo=(0.6, 0.35), hi=(1.35, 0.45)),
        Box(lo=(1.55, 0.6), hi=(1.65, 1.3)),
        Box(lo=(0.35, 0.65), hi=(0.45, 1.25)),
        Box(lo=(0.65, 1.5), hi=(1.35, 1.6)),
    )
    # the four-island ring
    assert RING_ISLANDS == ring_islands and RING_BRIDGES == ring_bridges
    # v0 (the first shipped map): the ring plus the dead-end island I4 and its spur B4
    assert SPUR_ISLANDS == (*ring_islands, Disc(center=(1.0, 1.0), radius=0.2))
    assert SPUR_BRIDGES == (*ring_bridges, Box(lo=(0.95, 0.35), hi=(1.05, 0.85)))
    # the default map is the v0 map: IslandsBridges() is gym.make("ihm/IslandsBridges-v0")
    assert DEFAULT_ISLANDS == SPUR_ISLANDS and DEFAULT_BRIDGES == SPUR_BRIDGES
    env = IslandsBridges()
    assert env.islands == SPUR_ISLANDS and env.bridges == SPUR_BRIDGES
    v0 = gym.make(ENV_ID).unwrapped
    assert (v0.islands, v0.bridges) == (env.islands, env.bridges)
    for attr in ("reward_mode", "max_step", "goal_eps", "different_islands", "action_scale"):
        assert getattr(v0, attr) == getattr(env, attr)
    assert v0.observation_space == env.observation_space
    assert v0.action_space == env.action_space
    for islands, bridges in ((RING_ISLANDS, RING_BRIDGES), (SPUR_ISLANDS, SPUR_BRIDGES)):
        for b in bridges:  # bridges are narrow
            lo, hi = b.bounds()
            assert min(hi - lo) == pytest.approx(0.1)
        # islands are disjoint, each bridge's ends lie on land (the map is connected)
        for k, p in enumerate(islands):
            for q in islands[k + 1 :]:
                assert not _overlap(p, q)
        other = islands + bridges
        for b in bridges:
            assert sum(_overlap(b, q) for q in other if q is not b) >= 2
    # the ring: each island touches exactly two bridges; on the spur map I4 touches one
    for k, isl in enumerate(SPUR_ISLANDS):
        touching = sum(_overlap(isl, b) for b in SPUR_BRIDGES)
        assert touching == (1 if k == 4 else 2)  # B4 touches I4 and B0 only
    # the ring: each island touches exactly two bridges
    for isl in RING_ISLANDS:
        assert sum(_overlap(isl, b) for b in RING_BRIDGES) == 2
    # the documentation names the same coordinates and both ids
    doc = IslandsBridges.__doc__
    assert "Disc((1.6, 1.55), 0.3)" in doc
    assert "``Box((0.65, 1.5), (1.35, 1.6))`` (I3-I2)" in doc
    assert "I4 ``Disc((1.0, 1.0), 0.2)``" in doc
    assert "B4 ``Box((0.95, 0.35), (1.05, 0.85))``" in doc
    assert ENV_ID in doc and RING_ID in doc


def test_map_ids_are_registered():
    # one id per map: v0 the five-island map, Ring-v0 the ring; the old spur id is gone
    for env_id, islands, bridges in MAPS:
        env = gym.make(env_id, reward="sparse")
        assert env.unwrapped.islands == islands and env.unwrapped.bridges == bridges
        assert env.unwrapped.reward_mode == "sparse" and env.spec.max_episode_steps == 200
        assert gym.spec(env_id).kwargs == {"islands": islands, "bridges": bridges}
    assert "ihm/IslandsBridgesSpur-v0" not in gym.registry
    with pytest.raises(gym.error.Error):
        gym.make("ihm/IslandsBridgesSpur-v0")
    ids = sorted(i for i in gym.registry if i.startswith("ihm/IslandsBridges"))
    assert ids == [ENV_ID, RING_ID]
    assert gym.make(ENV_ID).unwrapped.safe_distance((1.0, 1.0)) == pytest.approx(0.2)  # I4
    assert gym.make(RING_ID).unwrapped.safe_distance((1.0, 1.0)) < 0  # sea inside the ring
    # separate names, no "-v1": Gymnasium does not flag v0 as out of date
    for env_id, _, _ in MAPS:
        _no_warnings(gym.make, env_id)


def _overlap(p, q) -> bool:
    # sample q densely and ask p (enough for the default map's sizes)
    lo, hi = q.bounds()
    xs = np.stack(np.meshgrid(*np.linspace(lo, hi, 81).T), axis=-1).reshape(-1, 2)
    xs = xs[q.signed_distance(xs) > 1e-9]
    return bool(np.any(p.signed_distance(xs) > 1e-9))


def test_custom_map():
    islands = [Box(lo=(0, 0), hi=(1, 1)), Disc(center=(3, 0.5), radius=0.5)]
    bridges = [Box(lo=(0.9, 0.45), hi=(2.6, 0.55))]
    env = IslandsBridges(islands=islands, bridges=bridges)
    np.testing.assert_allclose(env.observation_space.low, [-0.1, -0.1, 0, 0])
    np.testing.assert_allclose(env.observation_space.high, [3.6, 1.1, 3.5, 1])
    assert env.safe_pieces == tuple(islands + bridges)
    # islands without bridges: bridges=None means none
    assert IslandsBridges(islands=islands).bridges == ()


def test_render_shows_agent_and_goal():
    env = IslandsBridges(islands=RING_ISLANDS, bridges=RING_BRIDGES, render_mode="rgb_array")
    env.reset(seed=0, options={"start": (0.4, 0.4), "goal": (1.6, 1.55)})
    img = env.render()
    lo, hi, w, h, ppu = env._frame()
    assert img.dtype == np.uint8 and img.shape == (h, w, 3) and h > 100 and w > 100

    def pixel(x, y):
        return tuple(img[int((hi[1] - y) * ppu), int((x - lo[0]) * ppu)])

    assert pixel(0.4, 0.4) == (220, 30, 30)  # agent, red
    assert pixel(1.6, 1.55) == (30, 80, 220)  # goal, blue
    assert pixel(1.0, 0.4) == (236, 216, 165)  # land (B0)
    assert pixel(1.0, 1.0) == (205, 222, 235)  # sea (the ring's middle)
    assert pixel(0.8, 0.6) == (205, 222, 235)  # sea
    env.step(np.array([1.0, 0.0]))
    assert pixel(0.5, 0.4) != (220, 30, 30)  # the frame follows the agent
    assert tuple(env.render()[int((hi[1] - 0.4) * ppu), int((0.5 - lo[0]) * ppu)]) == (
        220,
        30,
        30,
    )
    with pytest.warns(UserWarning, match="render_mode=None"):
        assert IslandsBridges().render() is None
    # the default (v0) map has land in the ring's middle: the dead-end island I4
    env = IslandsBridges(render_mode="rgb_array")
    env.reset(seed=0, options={"start": (0.4, 0.4), "goal": (1.6, 1.55)})
    lo2, hi2, _, _, ppu2 = env._frame()
    assert np.array_equal(lo2, lo) and np.array_equal(hi2, hi) and ppu2 == ppu  # same frame
    img = env.render()  # pixel() reads the new image
    assert pixel(1.0, 1.0) == (236, 216, 165)  # land (I4)
    assert pixel(0.8, 0.6) == (205, 222, 235)  # sea


def test_draw_map(tmp_path):
    png = b"\x89PNG\r\n\x1a\n"
    out = draw_map(tmp_path / "map.png")  # the default, v0 map
    assert out.exists() and out.read_bytes()[:8] == png
    out = draw_map(tmp_path / "ring.png", RING_ISLANDS, RING_BRIDGES, title="ring", goal=None)
    assert out.exists() and out.read_bytes()[:8] == png
    # the default title names the map's id
    assert _map_title(SPUR_ISLANDS, SPUR_BRIDGES).startswith("IslandsBridges-v0 map")
    assert _map_title(RING_ISLANDS, RING_BRIDGES).startswith("IslandsBridgesRing-v0 map")
    assert _map_title(RING_ISLANDS, ()).startswith("custom map")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"reward": "shaped"}, "reward must be 'dense' or 'sparse'"),
        ({"max_step": 0.0}, "max_step must be finite and > 0"),
        ({"max_step": -0.1}, "max_step must be finite and > 0"),
        ({"goal_eps": 0}, "goal_eps must be finite and > 0"),
        ({"islands": []}, "the map is empty"),
        ({"islands": [Disc((0, 0), 1)]}, "at least two islands"),
        ({"render_mode": "human"}, "render_mode must be None or one of"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        IslandsBridges(**kwargs)


def test_bad_reset_options_and_pieces():
    env = IslandsBridges()
    with pytest.raises(ValueError, match="outside the safe region"):
        env.reset(options={"start": (0.8, 0.6)})
    with pytest.raises(TypeError, match="envs.Disc or envs.Box"):
        IslandsBridges(islands=[(0, 0, 1)])
    with pytest.raises(RuntimeError, match="reset"):
        IslandsBridges().step(np.zeros(2))


@pytest.mark.parametrize("env_id", [ENV_ID, RING_ID])
def test_gym_make_registration_and_time_limit(env_id):
    assert set(envs.__all__) >= {"IslandsBridges", "Disc", "Box", "RING_ISLANDS", "SPUR_ISLANDS"}
    env = gym.make(env_id, reward="sparse")
    assert env.spec.max_episode_steps == 200
    assert isinstance(env.unwrapped, IslandsBridges) and env.unwrapped.reward_mode == "sparse"
    env.reset(seed=0, options={"start": (0.4, 0.4), "goal": (1.6, 1.55)})
    steps, trunc, term = 0, False, False
    while not (term or trunc):  # the zero step is always safe: only the time limit ends it
        _, _, term, trunc, _ = env.step(np.zeros(2, dtype=np.float32))
        steps += 1
    assert trunc and not term and steps == 200


def test_float_paths_equal_the_numpy_definitions_bit_for_bit():
    """step() and reset() compute in floats; each value equals its numpy definition exactly:
    the island draw equals ``Generator.choice(n, p=p)`` from the same generator state, the
    distances ``np.linalg.norm`` and ``signed_distance``, the next state ``predict``."""
    from envs.islands_bridges import _dist

    env = IslandsBridges()
    env.reset(seed=0)
    n = len(env.islands)
    for exclude in (None, *range(n)):
        p = env._island_p.copy()
        if exclude is not None:
            p[exclude] = 0.0
            p /= p.sum()
        for seed in range(300):
            ours = np.random.Generator(np.random.PCG64(seed))
            ref = np.random.Generator(np.random.PCG64(seed))
            env._np_random = ours
            assert env._choose_island(exclude) == int(ref.choice(n, p=p))
            assert ours.bit_generator.state == ref.bit_generator.state  # one draw each
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    for _ in range(3000):
        x, y, gx, gy = rng.uniform(-0.2, 2.1, 4)
        # bit-equal on this machine; approx in case a BLAS reduces with a fused multiply-add
        ref = float(np.linalg.norm(np.array([x, y]) - (gx, gy)))
        assert _dist(x, y, gx, gy) == pytest.approx(ref, rel=1e-15, abs=0)
        assert env._depth(x, y) == env.safe_distance((x, y))
        s = env.state.copy()
        a = rng.uniform(-1.5, 1.5, 2)
        obs, _, terminated, _, info = env.step(a)
        assert np.array_equal(env.state, env.predict(s, a))
        assert info["distance_to_edge"] == env.safe_distance(env.state)
        assert info["distance_to_goal"] == pytest.approx(
            float(np.linalg.norm(env.state - env.goal)), rel=1e-15, abs=0
        )
        assert np.array_equal(obs, np.concatenate([env.state, env.goal]).astype(np.float32))
        if terminated:
            env.reset()
