"""train.evaluation.run_episodes, the one evaluation loop: episodes per env, batching, resets
with seeds, the step limit and an episode's own stop (on a counting toy env)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from train.evaluation import one_by_one, run_episodes


class Counter(gym.Env):
    """Observation: [env id, step]; terminates after ``length`` steps."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,))
    action_space = gym.spaces.Box(-1, 1, (1,))

    def __init__(self, ident: int, length: int) -> None:
        self.ident, self.length = ident, length
        self.seeds: list[int | None] = []

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        self.seeds.append(seed)
        self.t = 0
        return np.array([self.ident, 0.0]), {"seed": seed}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.t += 1
        return np.array([self.ident, self.t]), 1.0, self.t >= self.length, False, {}


class Steps:
    """Counts an episode's steps; stops it early at ``stop_at``."""

    def __init__(self, env: gym.Env, obs: Any, info: dict, stop_at: int = 0) -> None:
        self.env, self.n, self.stop_at, self.seed = env, 0, stop_at, info["seed"]

    def step(self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict) -> bool:
        self.n += 1
        return self.n == self.stop_at

    def result(self) -> dict[str, Any]:
        return {"env": self.env.ident, "steps": self.n, "seed": self.seed}


def test_episodes_per_env_batches_and_order() -> None:
    envs = [Counter(0, 3), Counter(1, 2), Counter(2, 5)]
    batches: list[list[float]] = []

    def act(batch: np.ndarray) -> np.ndarray:
        batches.append(batch[:, 0].tolist())
        return np.zeros((len(batch), 1))

    res = run_episodes(envs, 7, act, Steps)
    # env i runs (7 + i) // 3 episodes: 2, 2, 3
    assert [sum(r["env"] == i for r in res) for i in range(3)] == [2, 2, 3]
    assert batches[0] == [0, 1, 2] and batches[-1] == [2]  # running envs, in env order
    assert [r["env"] for r in res[:2]] == [1, 0]  # in the order the episodes ended
    assert all(r["steps"] == envs[r["env"]].length for r in res)
    assert all(s is None for e in envs for s in e.seeds)  # plain resets
    assert run_episodes(envs, 0, act, Steps) == []


def test_seeds_step_limit_and_early_stop() -> None:
    env = Counter(0, 10)
    res = run_episodes(
        [env], 3, one_by_one(lambda o: np.zeros(1)), Steps,
        reset_seed=lambda i, ep: 100 + ep, max_steps=4,
    )  # fmt: skip
    assert [r["seed"] for r in res] == [100, 101, 102] and env.seeds == [100, 101, 102]
    assert [r["steps"] for r in res] == [4, 4, 4]
    stop = run_episodes([Counter(0, 10)], 2, one_by_one(lambda o: np.zeros(1)),
                        lambda e, o, i: Steps(e, o, i, stop_at=2))  # fmt: skip
    assert [r["steps"] for r in stop] == [2, 2]
    with pytest.raises(ValueError, match="max_steps"):
        run_episodes([env], 1, one_by_one(lambda o: np.zeros(1)), Steps, max_steps=0)
