"""train.vec.ChunkedVecEnv and train.pipeline.PipelinedPPO: the same transitions as
DummyVecEnv and SB3's PPO over the same thunks."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium.wrappers import TimeLimit
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import CallbackList
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from train import rotation
from train.pipeline import PipelinedPPO
from train.seeding import RunSeeds
from train.vec import ChunkedVecEnv, _chunks, make_vec_env


def test_chunks_cover_every_env_once() -> None:
    for n in range(1, 20):
        for k in range(1, n + 1):
            chunks = _chunks(n, k)
            assert [i for c in chunks for i in c] == list(range(n))
            sizes = [len(c) for c in chunks]
            assert len(chunks) == k and max(sizes) - min(sizes) <= 1


@pytest.mark.parametrize("parts", [1, 2])
def test_chunked_steps_like_dummy_with_resets_and_routing(parts: int) -> None:
    """5 rotation envs (episodes of 8 steps, so auto-resets happen), 2 workers of 3 + 2 envs
    (with 2 parts: worker 0 holds envs 0, 2, 3 and worker 1 envs 1, 4): observations,
    rewards, dones, infos and terminal observations equal DummyVecEnv's, step by step;
    attribute and method calls reach the right env."""
    cfg = rotation.RotateConfig(episode_steps=8)
    thunks = [rotation.make_env(cfg, s) for s in RunSeeds(3).envs("train", 5)]
    a, b = DummyVecEnv(thunks), ChunkedVecEnv(thunks, n_workers=2, parts=parts)
    try:
        assert sorted(len(c) for c in b.chunks) == [2, 3]
        assert sorted(i for c in b.chunks for i in c) == list(range(5))
        if parts == 2:
            assert [list(p) for p in b.parts] == [[0, 1], [2, 3, 4]]
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
        b.set_attr("object", "cube", [1, 4])
        objects = b.env_method("get_wrapper_attr", "object")
        assert objects == ["sphere", "cube", "sphere", "sphere", "cube"]
        assert b.env_is_wrapped(TimeLimit, [0, 3]) == [True, True]
        assert b.env_is_wrapped(Monitor) == a.env_is_wrapped(Monitor) == [False] * 5
    finally:
        b.close()
        a.close()
    assert all(not p.is_alive() for p in b.processes)


def test_make_vec_env_and_bad_workers() -> None:
    cfg = rotation.RotateConfig()
    thunks = [rotation.make_env(cfg)] * 2
    assert isinstance(make_vec_env(thunks, 0), DummyVecEnv)
    assert isinstance(make_vec_env(thunks[:1], 2), DummyVecEnv)
    with pytest.raises(ValueError, match="n_workers"):
        ChunkedVecEnv(thunks, n_workers=0)
    with pytest.raises(ValueError, match="parts"):
        ChunkedVecEnv(thunks, n_workers=1, parts=3)


def test_part_steps_queue_like_dummy() -> None:
    """Part steps, a second one queued before the first is collected, give DummyVecEnv's
    transitions; misuse of the queue raises."""
    cfg = rotation.RotateConfig(episode_steps=8)
    thunks = [rotation.make_env(cfg, s) for s in RunSeeds(4).envs("train", 4)]
    a, b = DummyVecEnv(thunks), ChunkedVecEnv(thunks, n_workers=2, parts=2)
    try:
        a.seed(1)
        b.seed(1)
        np.testing.assert_array_equal(a.reset(), b.reset())
        with pytest.raises(RuntimeError, match="pending"):
            b.step_part_wait()
        rng = np.random.default_rng(2)
        for _ in range(12):
            act = rng.uniform(-1, 1, (4, 12)).astype(np.float32)
            oa, ra, da, _ = a.step(act)
            b.step_part_async(0, act[:2])
            b.step_part_async(1, act[2:])  # queued behind part 0's step
            with pytest.raises(RuntimeError, match="pending"):
                b.step_async(act)
            with pytest.raises(RuntimeError, match="pending"):
                b.get_attr("dt")
            o0, r0, d0, _ = b.step_part_wait()
            o1, r1, d1, _ = b.step_part_wait()
            np.testing.assert_array_equal(oa, np.concatenate([o0, o1]))
            np.testing.assert_array_equal(ra, np.concatenate([r0, r1]))
            np.testing.assert_array_equal(da, np.concatenate([d0, d1]))
        b.step_part_async(1, act[2:])  # left pending: close() collects it
    finally:
        b.close()
        a.close()
    assert all(not p.is_alive() for p in b.processes)


def _rollout(
    pipelined: bool, training: bool, norm_obs: bool = True
) -> tuple[dict[str, np.ndarray], VecNormalize]:
    """One 12-step rollout of 8 rotation envs (8-step episodes: timeouts bootstrap), small
    nets, same initial weights and sampling seed: SB3's PPO on DummyVecEnv or PipelinedPPO on
    ChunkedVecEnv(parts=2)."""
    cfg = rotation.RotateConfig(episode_steps=8)
    thunks = [rotation.make_env(cfg, s) for s in RunSeeds(3).envs("train", 8)]
    venv = ChunkedVecEnv(thunks, n_workers=2, parts=2) if pipelined else DummyVecEnv(thunks)
    venv.seed(5)
    vec = VecNormalize(venv, training=training, norm_obs=norm_obs)
    if norm_obs:  # statistics far from the identity
        vec.obs_rms.mean[:] = np.linspace(-0.1, 0.1, 56)
        vec.obs_rms.var[:] = np.linspace(0.5, 4.0, 56)
    vec.ret_rms.var = np.float64(3.0)
    torch.manual_seed(0)
    cls = PipelinedPPO if pipelined else PPO
    net = {"net_arch": {"pi": [32, 32], "vf": [32, 32]}}
    model = cls("MlpPolicy", vec, n_steps=12, batch_size=48, policy_kwargs=net, device="cpu")
    model._setup_learn(96, None)
    torch.manual_seed(1)
    cb = CallbackList([])
    cb.init_callback(model)
    assert model.collect_rollouts(vec, cb, model.rollout_buffer, 12)
    b = model.rollout_buffer
    keys = ("observations", "actions", "rewards", "episode_starts", "values", "log_probs")
    out = {k: getattr(b, k).copy() for k in keys}
    out["returns"] = b.returns.copy()
    out["last_obs"] = np.asarray(model._last_obs).copy()
    out["vec_returns"] = vec.returns.copy()
    out["old_reward"] = np.asarray(vec.old_reward).copy()
    out["old_obs"] = np.asarray(vec.old_obs).copy()
    vec.close()
    return out, vec


@pytest.mark.slow
def test_pipelined_ppo_collects_what_sb3_collects() -> None:
    """With frozen normalisation the pipelined rollout buffer equals SB3's collect_rollouts:
    observations, actions, episode starts and log-probabilities bit for bit; rewards (with
    the batched timeout bootstraps), values and returns to float rounding. With training
    normalisation the first step is the same, the statistics count the same samples, and
    updating them part by part is the same estimator as all at once (the later steps
    differ: part A's observations are normalised before part B's newest samples arrive)."""
    sync, _ = _rollout(False, training=False)
    pipe, _ = _rollout(True, training=False)
    assert sync["episode_starts"][1:].sum() >= 8  # every env timed out and restarted
    for k in ("observations", "actions", "episode_starts", "log_probs", "last_obs", "old_obs"):
        np.testing.assert_array_equal(sync[k], pipe[k], err_msg=k)
    for k in ("rewards", "values", "returns"):
        np.testing.assert_allclose(sync[k], pipe[k], rtol=0, atol=1e-5, err_msg=k)
    # reward statistics updated part by part (observations not normalised: same actions)
    sync_r, vrs = _rollout(False, training=True, norm_obs=False)
    pipe_r, vrp = _rollout(True, training=True, norm_obs=False)
    for k in ("observations", "actions", "episode_starts", "vec_returns", "old_reward"):
        np.testing.assert_array_equal(sync_r[k], pipe_r[k], err_msg=k)
    assert vrs.ret_rms.count == vrp.ret_rms.count
    np.testing.assert_allclose(vrs.ret_rms.var, vrp.ret_rms.var, rtol=1e-9)
    # part B's rewards are normalised after the whole step's update, as in SB3; part A's
    # before part B's newest returns arrive (a slightly different scale)
    np.testing.assert_allclose(sync_r["rewards"][:, 4:], pipe_r["rewards"][:, 4:], atol=1e-5)
    sync_t, vs = _rollout(False, training=True)
    pipe_t, vp = _rollout(True, training=True)
    np.testing.assert_array_equal(sync_t["observations"][0], pipe_t["observations"][0])
    assert vs.obs_rms.count == vp.obs_rms.count and vs.ret_rms.count == vp.ret_rms.count
    x = np.random.default_rng(0).normal(size=(8, 56))
    whole, halves = RunningMeanStd(shape=(56,)), RunningMeanStd(shape=(56,))
    whole.update(x)
    halves.update(x[:4])
    halves.update(x[4:])
    np.testing.assert_allclose(whole.mean, halves.mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(whole.var, halves.var, rtol=1e-9)
