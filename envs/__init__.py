"""Gymnasium environments of the project.

``import envs`` registers one id per map of the islands-and-bridges world, 200 steps per
episode, e.g. ``gym.make("ihm/IslandsBridges-v0", reward="sparse")``:

- ``ihm/IslandsBridges-v0``: the five-island map, the ring plus the dead-end island I4 reached
  by the spur B4 (``SPUR_ISLANDS``/``SPUR_BRIDGES``, the default map of ``IslandsBridges()``;
  the first shipped map);
- ``ihm/IslandsBridgesRing-v0``: the four-island ring (``RING_ISLANDS``/``RING_BRIDGES``).

and the four-finger in-hand rotation task of thesis ch. 7 (:mod:`envs.four_finger`),
64 steps per episode as in the thesis: ``gym.make("ihm/FourFingerRotate-v0", object="sphere")``,
and the same task with the object drawn per episode,
``gym.make("ihm/FourFingerRotateMixed-v0", objects=("sphere", "cylinder", "cube"))``.
"""

import gymnasium

from envs.four_finger import FourFingerError, FourFingerRotate
from envs.geometry import Box, Disc
from envs.islands_bridges import (
    DEFAULT_BRIDGES,
    DEFAULT_ISLANDS,
    RING_BRIDGES,
    RING_ISLANDS,
    SPUR_BRIDGES,
    SPUR_ISLANDS,
    IslandsBridges,
)

__all__ = [
    "DEFAULT_BRIDGES",
    "DEFAULT_ISLANDS",
    "RING_BRIDGES",
    "RING_ISLANDS",
    "SPUR_BRIDGES",
    "SPUR_ISLANDS",
    "Box",
    "Disc",
    "FourFingerError",
    "FourFingerRotate",
    "IslandsBridges",
]

for _id, _kwargs in (
    ("ihm/IslandsBridges-v0", {"islands": SPUR_ISLANDS, "bridges": SPUR_BRIDGES}),
    ("ihm/IslandsBridgesRing-v0", {"islands": RING_ISLANDS, "bridges": RING_BRIDGES}),
):
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="envs.islands_bridges:IslandsBridges",
            max_episode_steps=200,
            kwargs=_kwargs,
        )

for _id, _entry in (
    ("ihm/FourFingerRotate-v0", "envs.four_finger:FourFingerRotate"),
    ("ihm/FourFingerRotateMixed-v0", "envs.four_finger:MixedObjectRotate"),
):
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_entry, max_episode_steps=64)
