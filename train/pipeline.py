"""PPO whose rollout collection overlaps the policy's forward passes with the physics.

SB3 collects a rollout step by step: the training process computes the actions and
values of all envs, then waits while the workers step them. On two cores that leaves the
workers idle during every forward pass (about 2 ms for the thesis' two 4 x 512 networks
on 16 observations) and the training process idle during the physics.
:class:`PipelinedPPO` changes two things, neither of which changes what is computed:

- it splits the envs into parts (``ChunkedVecEnv(parts=2)``) and keeps the workers busy:
  while they step part A, the training process post-processes part B's last step and
  computes B's next actions, and B's step is queued behind A's;
- it runs only the actor during the rollout; the critic's values ``V(s_t)``, the final
  ``V(s_T)`` and the timeout bootstraps are computed at the end in one batch (the policy
  does not change during a rollout), where a large matrix product is far cheaper per
  observation than 384 small ones.

Each env still gets its action from its own latest observation and the same policy, and
the actions are sampled in the same order as SB3's (part A's envs, then part B's, step by
step), so with a frozen ``VecNormalize`` (or none) the rollout buffer equals SB3's
``collect_rollouts`` over the same envs: bit for bit, except the values, which agree to
float rounding (batched products round differently; ``tests/train/test_vec.py``). Torch's
Gaussian sampler fills blocks of 16, so the same draws need each part's action count
(envs x 12) to be a multiple of 16, as with 16 envs in 2 parts. With a training
``VecNormalize`` the running statistics are updated part by part, so part A's
observations and rewards are normalised with statistics that lack part B's newest
samples: the same estimators, updated in a different order (tested: same counts, the
same reward statistics and returns when observations are not normalised).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from train.vec import ChunkedVecEnv

__all__ = ["PipelinedPPO"]


def _pipeline(env: VecEnv) -> tuple[ChunkedVecEnv, VecNormalize | None] | None:
    """(stepper, normaliser) when ``env`` is a ChunkedVecEnv with >= 2 parts, optionally
    under one plain VecNormalize (not a subclass: its step_wait is re-done part by part);
    else None (plain SB3 collection)."""
    if isinstance(env, VecNormalize) and type(env) is not VecNormalize:
        return None
    norm = env if isinstance(env, VecNormalize) else None
    inner = env.venv if norm is not None else env
    if isinstance(inner, ChunkedVecEnv) and len(inner.parts) >= 2:
        return inner, norm
    return None


class _Parts:
    """The rollout's envs in the parts of a ``ChunkedVecEnv``, each with one step queued in
    the workers at a time: :meth:`send` queues part ``p``'s sampled actions (clipped to the
    action space) and keeps them with their log-probabilities in :attr:`queued`;
    :meth:`receive` collects part ``p``'s step, normalised as ``VecNormalize.step_wait``
    would, part by part (module doc)."""

    def __init__(self, venv: ChunkedVecEnv, norm: VecNormalize | None, space: spaces.Box) -> None:
        self.venv, self.norm = venv, norm
        self.slices = [slice(p.start, p.stop) for p in venv.parts]
        self.n_envs = venv.num_envs
        self.low, self.high = space.low, space.high
        self.queued: list[tuple[np.ndarray, th.Tensor]] = []
        self.zeros = th.zeros(self.n_envs)  # the values the buffer gets until the critic runs

    def send(self, p: int, action: tuple[np.ndarray, th.Tensor]) -> None:
        """Queue part ``p``'s step with ``action`` (its actions and their log-probabilities)."""
        self.queued.append(action)
        self.venv.step_part_async(p, np.clip(action[0], self.low, self.high))

    def receive(self, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Part ``p``'s step (observations, rewards, dones, infos), normalised."""
        obs, rews, dones, infos = self.venv.step_part_wait()
        norm = self.norm
        if norm is None:
            return obs, rews, dones, infos
        sl, n_envs = self.slices[p], self.n_envs
        if norm.old_obs is None or len(norm.old_obs) != n_envs:
            norm.old_obs = np.zeros((n_envs, *obs.shape[1:]), dtype=obs.dtype)
        if norm.old_reward is None or len(norm.old_reward) != n_envs:
            norm.old_reward = np.zeros(n_envs, dtype=rews.dtype)
        norm.old_obs[sl] = obs  # the raw data, as VecNormalize.step_wait keeps them
        norm.old_reward[sl] = rews
        if norm.training and norm.norm_obs:
            norm.obs_rms.update(obs)
        obs = norm.normalize_obs(obs)
        if norm.training:
            ret = norm.returns[sl] * norm.gamma + rews
            norm.returns[sl] = ret
            norm.ret_rms.update(ret)
        rews = norm.normalize_reward(rews)
        for i, done in enumerate(dones):
            if done and "terminal_observation" in infos[i]:
                infos[i]["terminal_observation"] = norm.normalize_obs(
                    infos[i]["terminal_observation"]
                )
        norm.returns[sl][dones] = 0
        return obs, rews, dones, infos

    def drain(self) -> None:
        """Collect the queued steps, so that the normaliser sees them."""
        for p in range(len(self.queued)):
            self.receive(p)


class PipelinedPPO(PPO):
    """SB3 PPO with pipelined rollout collection over a ``ChunkedVecEnv`` with >= 2 parts
    (module doc); any other env, gSDE, squashed or non-Box actions and non-Box
    observations fall back to SB3's ``collect_rollouts``."""

    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: RolloutBuffer,
        n_rollout_steps: int,
    ) -> bool:
        pipe = _pipeline(env)
        if (
            pipe is None
            or self.use_sde
            or self.policy.squash_output
            or not isinstance(self.action_space, spaces.Box)
            or not isinstance(self.observation_space, spaces.Box)
        ):
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        parts = _Parts(*pipe, self.action_space)
        for p, sl in enumerate(parts.slices):  # prologue: every part's first step queued
            parts.send(p, self._act(self._last_obs[sl]))
        truncated: list[tuple[int, int, np.ndarray]] = []  # (step, env, terminal obs)
        for n_steps in range(n_rollout_steps):
            last = n_steps + 1 >= n_rollout_steps
            step = (env, parts, callback, rollout_buffer, n_steps, last, truncated)
            if not self._rollout_step(*step):
                return False
        values = self._rollout_values(rollout_buffer, truncated)
        dones = self._last_episode_starts
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _act(self, obs: np.ndarray) -> tuple[np.ndarray, th.Tensor]:
        """Sampled actions and their log-probabilities for the observations ``obs`` of one
        part (the actor only: values are computed for the whole rollout at the end, in one
        batch)."""
        x = obs_as_tensor(obs, self.device)
        with th.no_grad():
            features = BasePolicy.extract_features(
                self.policy, x, self.policy.pi_features_extractor
            )
            latent = self.policy.mlp_extractor.forward_actor(features)
            dist = self.policy._get_action_dist_from_latent(latent)
            a = dist.get_actions(deterministic=False)
            lp = dist.log_prob(a)
        return a.cpu().numpy().reshape((-1, *self.action_space.shape)), lp

    def _rollout_step(
        self,
        env: VecEnv,
        parts: _Parts,
        callback: BaseCallback,
        rollout_buffer: RolloutBuffer,
        n_steps: int,
        last: bool,
        truncated: list[tuple[int, int, np.ndarray]],
    ) -> bool:
        """Step ``n_steps`` of the rollout: collect every part's queued step and, unless it
        is the ``last``, queue the part's next step from its new observations (behind the
        other parts'); record the transitions, the timeouts to bootstrap in ``truncated``.
        False when a callback stops training (the queued steps are collected first; the
        envs are then two steps ahead of ``_last_obs``, SB3's one, which only matters if
        ``learn()`` went on after a callback stopped it)."""
        n_envs = parts.n_envs
        new_obs = np.empty_like(self._last_obs)
        values = None  # computed after the rollout (SB3 sets them per step)
        rewards = np.empty(n_envs, dtype=np.float32)
        dones = np.empty(n_envs, dtype=bool)
        infos: list[dict[str, Any]] = [{}] * n_envs
        current, parts.queued = parts.queued, []
        for p, sl in enumerate(parts.slices):
            new_obs[sl], rewards[sl], dones[sl], infos[sl] = parts.receive(p)
            if not last:
                parts.send(p, self._act(new_obs[sl]))
        actions = np.concatenate([c[0] for c in current])
        log_probs = th.cat([c[1] for c in current])
        clipped_actions = np.clip(actions, parts.low, parts.high)
        self.num_timesteps += n_envs
        callback.update_locals(locals())
        if not callback.on_step():
            parts.drain()
            return False
        self._update_info_buffer(infos, dones)
        for idx, done in enumerate(dones):  # timeouts: bootstrapped after the rollout
            info = infos[idx]
            if done and info.get("terminal_observation") is not None:
                if info.get("TimeLimit.truncated", False):
                    truncated.append((n_steps, idx, info["terminal_observation"]))
        rollout_buffer.add(
            self._last_obs,  # type: ignore[arg-type]
            actions,
            rewards,
            self._last_episode_starts,  # type: ignore[arg-type]
            parts.zeros,  # values: filled in by _rollout_values
            log_probs,
        )
        self._last_obs = new_obs
        self._last_episode_starts = dones
        return True

    def _rollout_values(
        self, buf: RolloutBuffer, truncated: list[tuple[int, int, np.ndarray]]
    ) -> th.Tensor:
        """The critic on the whole rollout at once: the buffer's values ``V(s_t)``, the
        timeouts' bootstraps ``gamma V(s_T)`` added to their rewards, and the returned values
        of the last observations."""
        with th.no_grad():
            flat = buf.observations.reshape(-1, *buf.obs_shape)
            v = self.policy.predict_values(obs_as_tensor(flat, self.device))
            buf.values[:] = v.cpu().numpy().reshape(buf.values.shape)
            values = self.policy.predict_values(obs_as_tensor(self._last_obs, self.device))
            if truncated:
                term = np.stack([t[2] for t in truncated])
                tv = self.policy.predict_values(obs_as_tensor(term, self.device)).cpu().numpy()
                for (step, idx, _), value in zip(truncated, tv[:, 0], strict=True):
                    buf.rewards[step, idx] += self.gamma * value
        return values
