"""Gymnasium environments of the project.

``import envs`` registers ``ihm/IslandsBridges-v0`` (the default ring map) and
``ihm/IslandsBridgesSpur-v0`` (the ring plus a dead-end island), 200 steps per episode:
``gym.make("ihm/IslandsBridges-v0", reward="sparse")``.
"""

import gymnasium

from envs.geometry import Box, Disc
from envs.islands_bridges import IslandsBridges

__all__ = ["Box", "Disc", "IslandsBridges"]

from envs.islands_bridges import SPUR_BRIDGES, SPUR_ISLANDS

for _id, _kwargs in (
    ("ihm/IslandsBridges-v0", {}),
    ("ihm/IslandsBridgesSpur-v0", {"islands": SPUR_ISLANDS, "bridges": SPUR_BRIDGES}),
):
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="envs.islands_bridges:IslandsBridges",
            max_episode_steps=200,
            kwargs=_kwargs,
        )
