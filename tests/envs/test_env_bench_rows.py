"""The env benchmark's rows (envs.bench): each level builds its env, with the settings its
row names, and steps it."""

from __future__ import annotations

import numpy as np
import pytest

from envs import bench


@pytest.mark.parametrize("level", [1, 3, 9])  # (10: a 2.5 ms start-grasp cache of its own)
def test_each_row_builds_and_steps_its_env(level: int) -> None:
    env = bench.make(level)
    try:
        env.reset(seed=0)
        obs, *_ = env.step(np.zeros(env.action_space.shape))
        assert np.all(np.isfinite(obs))
        # the policy period stays 50 ms: 1 ms x 50 (rows 1-3), 2 ms x 25
        assert env.model.opt.timestep * env.frame_skip == pytest.approx(0.05)
        assert env.frame_skip == {1: 50, 3: 50, 9: 25}[level]
    finally:
        env.close()
