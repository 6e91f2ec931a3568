"""The one evaluation loop: a policy over episodes of several envs at once.

:func:`run_episodes` steps ``k`` envs side by side, env ``i`` running ``(n + i) // k`` of
``n`` episodes (so short episodes are not over-counted), and asks the policy for the
actions of all running envs in one batch. What an episode measures is an
:class:`Episode`, made after each reset and fed every step:

- :class:`SuccessEpisode`: success, failure, return, length and shield interventions, with
  the islands world's cycle stop; :func:`evaluate_success` (the islands trainer's
  evaluation, :mod:`train.islands_ppo`, and the islands benchmark, :mod:`train.islands`);
- :class:`RotationEpisode`: the four-finger rotation speed (turned angle about +z over the
  episode's duration; a drop ends an episode and counts its time so far), the drop and the
  shield interventions; :func:`evaluate_rotation` (the rotation trainer's periodic
  evaluations, :mod:`train.rotation`), :func:`train.policy.evaluate` (shipped policies from
  seeded start grasps) and the shield benchmark's episodes
  (:mod:`train.bench.shield_effect`, which adds slip and contact measures).

The policy is a function from a batch of observations to one action per row:
:func:`model_actions` for an SB3 model, :func:`one_by_one` for an ``obs -> action``
function (a loaded policy, random actions).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

__all__ = [
    "Episode",
    "RotationEpisode",
    "SuccessEpisode",
    "evaluate_rotation",
    "evaluate_success",
    "model_actions",
    "one_by_one",
    "run_episodes",
]

BatchAct = Callable[[np.ndarray], Any]
"""A batch of observations (one row per env) -> a sequence of actions, one per row."""


class Episode(Protocol):
    """What one episode measures: made by a factory ``(env, obs, info)`` after the reset."""

    def step(
        self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> bool:
        """Record one step; True ends the episode early (it ends anyway when ``terminated``
        or ``truncated``, or at the loop's ``max_steps``)."""
        ...

    def result(self) -> dict[str, Any]:
        """The episode's measures."""
        ...


def run_episodes(
    envs: Sequence[gym.Env],
    n_episodes: int,
    act: BatchAct,
    episode: Callable[[gym.Env, Any, dict[str, Any]], Episode],
    *,
    reset_seed: Callable[[int, int], int | None] | None = None,
    reset_options: Callable[[int, int], dict[str, Any] | None] | None = None,
    max_steps: int | None = None,
) -> list[dict[str, Any]]:
    """``n_episodes`` episodes over ``envs``; the :meth:`Episode.result` of each, in the order
    they ended.

    Env ``i`` of ``k`` runs ``(n_episodes + i) // k`` episodes, resetting as soon as one ends
    (``env.reset()``, or ``env.reset(seed=reset_seed(i, j))`` for its ``j``-th episode when
    ``reset_seed`` gives a seed; ``reset(options=reset_options(i, j))`` when that is given).
    Each round, ``act`` gets the observations of the envs still
    running, stacked in env order. An episode ends when the env terminates or truncates, when
    its :class:`Episode` says so, or after ``max_steps`` steps.
    """
    if max_steps is not None and max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    k = len(envs)
    targets = [(n_episodes + i) // k for i in range(k)] if k else []
    counts = [0] * k
    obs: list[Any] = [None] * k
    episodes: list[Any] = [None] * k
    steps = [0] * k
    results: list[dict[str, Any]] = []

    def start(i: int) -> None:
        seed = reset_seed(i, counts[i]) if reset_seed is not None else None
        options = reset_options(i, counts[i]) if reset_options is not None else None
        obs[i], info = envs[i].reset(seed=seed, options=options)
        episodes[i] = episode(envs[i], obs[i], info)
        steps[i] = 0

    for i in range(k):
        if targets[i] > 0:
            start(i)
    while True:
        active = [i for i in range(k) if counts[i] < targets[i]]
        if not active:
            break
        actions = act(np.stack([obs[i] for i in active]))
        for j, i in enumerate(active):
            obs[i], reward, terminated, truncated, info = envs[i].step(actions[j])
            steps[i] += 1
            stop = episodes[i].step(obs[i], reward, terminated, truncated, info)
            if not (stop or terminated or truncated or steps[i] == max_steps):
                continue
            results.append(episodes[i].result())
            counts[i] += 1
            if counts[i] < targets[i]:
                start(i)
    return results


def model_actions(
    model: Any,
    deterministic: bool = True,
    normalize: Callable[[np.ndarray], np.ndarray] | None = None,
) -> BatchAct:
    """An SB3 model's actions for a batch of observations, passed through ``normalize``
    first (:func:`train.sb3.normalizer`)."""

    def act(batch: np.ndarray) -> np.ndarray:
        if normalize is not None:
            batch = normalize(batch)
        actions, _ = model.predict(batch, deterministic=deterministic)
        return actions

    return act


def one_by_one(act: Callable[[np.ndarray], Any]) -> BatchAct:
    """A batch policy from an ``obs -> action`` function, called once per row."""
    return lambda batch: [act(o) for o in batch]


def _mean(xs: Sequence[Any]) -> float:
    return float(np.mean(xs)) if len(xs) else float("nan")


class SuccessEpisode:
    """Success, failure (``info["is_success"]``, ``info["failure"]`` at the end), return,
    length and shield interventions (``info["shield_intervened"]``) of an episode.

    ``stop_cycles`` (for envs that expose ``unwrapped.state`` and have a time limit): an
    episode whose state repeats has entered a cycle, which it can only leave by truncation,
    so it is completed without stepping on: not a success, not a failure, length = the time
    limit, return and shield interventions those of the cycle repeated up to the limit
    (:func:`evaluate_success` says when that is exact).
    """

    def __init__(self, env: gym.Env, stop_cycles: bool = False) -> None:
        self.env = env
        self.can_stop = (
            stop_cycles
            and hasattr(env.unwrapped, "state")
            and env.spec is not None
            and env.spec.max_episode_steps is not None
        )
        self.rewards: list[float] = []  # per step
        self.shielded: list[bool] = []
        # state -> steps taken when there
        self.seen = {self._state(): 0} if self.can_stop else {}
        self.success = self.failure = self.cycle = False

    def _state(self) -> bytes:
        return np.asarray(self.env.unwrapped.state).tobytes()

    def step(
        self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> bool:
        self.rewards.append(float(reward))
        self.shielded.append(bool(info.get("shield_intervened", False)))
        if terminated or truncated:
            self.success = bool(info.get("is_success", False))
            self.failure = bool(info.get("failure", False))
            return True
        if not self.can_stop:
            return False
        t = len(self.rewards)
        first = self.seen.setdefault(self._state(), t)
        if first == t:
            return False
        self.first = first  # steps first+1 .. t form a cycle
        self.cycle = True
        return True

    def result(self) -> dict[str, Any]:
        """``success``, ``failure``, ``return``, ``length``, ``interventions``, ``cycle``."""
        t = len(self.rewards)
        if not self.cycle:
            ret, length, n_int = float(np.sum(self.rewards)), t, sum(self.shielded)
        else:  # repeat the cycle up to the time limit
            limit = int(self.env.spec.max_episode_steps)  # type: ignore[union-attr]
            period = t - self.first
            cyc_r, cyc_s = self.rewards[self.first :], self.shielded[self.first :]
            rest = range(limit - t)
            ret = float(np.sum(self.rewards + [cyc_r[m % period] for m in rest]))
            length = limit
            n_int = sum(self.shielded) + sum(cyc_s[m % period] for m in rest)
        return {
            "success": self.success,
            "failure": self.failure,
            "return": ret,
            "length": length,
            "interventions": n_int,
            "cycle": self.cycle,
        }


def evaluate_success(
    model: Any,
    eval_envs: Sequence[gym.Env],
    n_episodes: int,
    *,
    deterministic: bool = True,
    normalize: Callable[[np.ndarray], np.ndarray] | None = None,
    stop_cycles: bool = True,
) -> dict[str, float]:
    """Success rate of the policy over ``n_episodes`` episodes on the plain envs ``eval_envs``.

    The envs run side by side (:func:`run_episodes`); the policy is queried for all running
    envs at once, on observations passed through ``normalize`` (:func:`train.sb3.normalizer`).
    Build ``eval_envs`` with :func:`train.islands_ppo.make_eval_envs` (shielded or not); the
    shield is part of each env.

    ``stop_cycles`` (deterministic policy only; :class:`SuccessEpisode`) stops an episode
    whose state repeats. This is exact for an env and shield that are deterministic
    functions of ``state`` (and the episode's goal) and a policy that maps equal observations
    to equal actions (the islands world; the simple shield's zero step is such a fixed
    point), and saves running frozen episodes to the limit. One caveat: the policy is queried
    on batches whose size changes as envs finish, and a CPU matrix product may round one row
    differently in a batch of another size; a cycle that a last-bit difference would break
    is then stopped. Tests compare both ways on trained and scripted policies.

    Returns ``episodes``, ``successes``, ``failures``, ``success_rate``, ``failure_rate``
    (``info["failure"]``), ``mean_return``, ``mean_length``, ``intervention_rate`` (fraction
    of steps where the shield changed the action; 0 without a shield) and ``cycles_stopped``.
    """
    if not eval_envs and n_episodes > 0:
        raise ValueError("evaluate needs at least one env")
    stop = stop_cycles and deterministic
    eps = run_episodes(
        eval_envs,
        n_episodes,
        model_actions(model, deterministic, normalize),
        lambda env, obs, info: SuccessEpisode(env, stop),
    )
    succ = [e["success"] for e in eps]
    fail = [e["failure"] for e in eps]
    steps = sum(e["length"] for e in eps)
    interventions = sum(e["interventions"] for e in eps)
    return {
        "episodes": len(eps),
        "successes": int(np.sum(succ)),
        "failures": int(np.sum(fail)),
        "success_rate": _mean(succ),
        "failure_rate": _mean(fail),
        "mean_return": _mean([e["return"] for e in eps]),
        "mean_length": _mean([e["length"] for e in eps]),
        "intervention_rate": interventions / steps if steps else 0.0,
        "cycles_stopped": sum(e["cycle"] for e in eps),
    }


class RotationEpisode:
    """An episode of the four-finger rotation env: steps, net turn about +z
    (``info["net_turn"]``: the unwrapped z twist of the object's orientation relative to its
    start, :func:`envs.four_finger.z_twist`), the summed per-step rotation about +z (the
    reward's, ``info["rotation_angle"]``), speeds = angle / (steps * dt) [rad/s], dropped
    (the env terminated) and shield interventions (``info["shield_intervened"]``);
    ``shield_seconds`` keeps a shield's wall time per step (``info["shield_step_seconds"]``,
    empty without a shield) for those who report it."""

    def __init__(self, env: gym.Env, obs: Any = None, info: dict[str, Any] | None = None) -> None:
        self.dt = float(env.unwrapped.dt)
        self.steps = self.interventions = 0
        self.angle = self.net = 0.0
        self.dropped = False
        self.shield_seconds: list[float] = []

    def step(
        self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> bool:
        self.steps += 1
        self.angle = float(info["rotation_angle"])
        self.net = float(info.get("net_turn", self.angle))
        self.dropped = bool(terminated)
        self.interventions += bool(info.get("shield_intervened", False))
        if "shield_step_seconds" in info:
            self.shield_seconds.append(float(info["shield_step_seconds"]))
        return False

    def result(self) -> dict[str, Any]:
        """``steps``, ``speed_rad_s`` (net turn), ``summed_rad_s`` (summed rotation),
        ``dropped``, ``interventions``."""
        t = self.steps * self.dt
        return {
            "steps": self.steps,
            "speed_rad_s": self.net / t,
            "summed_rad_s": self.angle / t,
            "dropped": self.dropped,
            "interventions": self.interventions,
        }


def evaluate_rotation(
    model: Any,
    eval_envs: Sequence[gym.Env],
    n_episodes: int,
    normalize: Callable[[np.ndarray], np.ndarray] | None = None,
    deterministic: bool = True,
) -> dict[str, float]:
    """Mean net-turn speed [rad/s] (``speed_rad_s``; ``summed_rad_s``: the summed per-step
    rotation's) and drop rate of the policy over ``n_episodes`` episodes.

    The envs run side by side (:func:`run_episodes`), all queried in one batch; each
    episode ends at the env's time limit or at a drop (:class:`RotationEpisode`).
    ``intervention_rate``: the fraction of steps in which a shield changed the action
    (``info["shield_intervened"]``; 0 without a shield).
    """
    eps = run_episodes(
        eval_envs, n_episodes, model_actions(model, deterministic, normalize), RotationEpisode
    )
    speeds = [e["speed_rad_s"] for e in eps]
    n_steps = sum(e["steps"] for e in eps)
    return {
        "episodes": len(eps),
        "speed_rad_s": float(np.mean(speeds)) if speeds else float("nan"),
        "speed_median_rad_s": float(np.median(speeds)) if speeds else float("nan"),
        "summed_rad_s": _mean([e["summed_rad_s"] for e in eps]),
        "drop_rate": _mean([e["dropped"] for e in eps]),
        "intervention_rate": sum(e["interventions"] for e in eps) / n_steps
        if n_steps
        else float("nan"),
    }
