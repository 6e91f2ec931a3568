"""train.vec.ChunkedVecEnv: the same transitions as DummyVecEnv over the same thunks."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from train import rotate
from train.seeding import RunSeeds
from train.vec import ChunkedVecEnv, _chunks, make_vec_env


def test_chunks_cover_every_env_once() -> None:
    for n in range(1, 20):
        for k in range(1, n + 1):
            chunks = _chunks(n, k)
            assert [i for c in chunks for i in c] == list(range(n))
            sizes = [len(c) for c in chunks]
            assert len(chunks) == k and max(sizes) - min(sizes) <= 1


def test_chunked_steps_like_dummy_with_resets_and_routing() -> None:
    """5 rotation envs (episodes of 8 steps, so auto-resets happen), 2 workers of 3 + 2 envs:
    observations, rewards, dones, infos and terminal observations equal DummyVecEnv's, step by
    step; attribute and method calls reach the right env."""
    cfg = rotate.RotateConfig(episode_steps=8)
    thunks = [rotate.make_env(cfg, s) for s in RunSeeds(3).envs("train", 5)]
    a, b = DummyVecEnv(thunks), ChunkedVecEnv(thunks, n_workers=2)
    try:
        assert [len(c) for c in b.chunks] == [2, 3] or [len(c) for c in b.chunks] == [3, 2]
        assert b.observation_space == a.observation_space and b.action_space == a.action_space
        a.seed(7)
        b.seed(7)
        np.testing.assert_array_equal(a.reset(), b.reset())
        assert [i["grasp"] for i in a.reset_infos] == [i["grasp"] for i in b.reset_infos]
        rng = np.random.default_rng(0)
        dones = 0
        for _ in range(20):
            act = rng.uniform(-1, 1, (5, 12)).astype(np.float32)
            oa, ra, da, ia = a.step(act)
            ob, rb, db, ib = b.step(act)
            np.testing.assert_array_equal(oa, ob)
            np.testing.assert_array_equal(ra, rb)
            np.testing.assert_array_equal(da, db)
            for x, y in zip(ia, ib, strict=True):
                assert x.keys() == y.keys()
                if "terminal_observation" in x:
                    term = x["terminal_observation"], y["terminal_observation"]
                    np.testing.assert_array_equal(*term)
            dones += int(da.sum())
        assert dones >= 10  # every env finished at least two 8-step episodes
        assert b.get_attr("dt") == [0.05] * 5
        assert b.get_attr("spec", [4])[0].max_episode_steps == 8
        b.set_attr("drop_weight", 3.0, [1, 4])
        assert b.env_method("get_wrapper_attr", "drop_weight") == [0.0, 3.0, 0.0, 0.0, 3.0]
        assert b.env_is_wrapped(TimeLimit, [0, 3]) == [True, True]
        assert b.env_is_wrapped(Monitor) == a.env_is_wrapped(Monitor) == [False] * 5
    finally:
        b.close()
        a.close()
    assert all(not p.is_alive() for p in b.processes)


def test_make_vec_env_and_bad_workers() -> None:
    cfg = rotate.RotateConfig()
    thunks = [rotate.make_env(cfg)] * 2
    assert isinstance(make_vec_env(thunks, 0), DummyVecEnv)
    assert isinstance(make_vec_env(thunks[:1], 2), DummyVecEnv)
    with pytest.raises(ValueError, match="n_workers"):
        ChunkedVecEnv(thunks, n_workers=0)
