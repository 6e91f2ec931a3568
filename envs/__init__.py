"""Gymnasium environments of the project.

``import envs`` registers ``ihm/IslandsBridges-v0`` (``gym.make("ihm/IslandsBridges-v0")``,
200 steps per episode).
"""

import gymnasium

from envs.geometry import Box, Disc
from envs.islands_bridges import IslandsBridges

__all__ = ["Box", "Disc", "IslandsBridges"]

if "ihm/IslandsBridges-v0" not in gymnasium.registry:
    gymnasium.register(
        id="ihm/IslandsBridges-v0",
        entry_point="envs.islands_bridges:IslandsBridges",
        max_episode_steps=200,
    )
