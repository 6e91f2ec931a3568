"""MuJoCo glue: thesis scenes, contact extraction to :class:`stability.Grasp`, viewers.

>>> import ihm
>>> model, data = ihm.load_scene("barrett_box")          # doctest: +SKIP
>>> grasp = ihm.grasp_from_mujoco(model, data)            # doctest: +SKIP
>>> grasp.equilibrium_residuals()                         # doctest: +SKIP

Importing it changes nothing outside it (no environment variable): the offscreen renderer
picks its OpenGL backend when it is created (:mod:`ihm.render`: ``MUJOCO_GL``, else EGL on
Linux).
"""

from .contacts import (
    HandOptions,
    MujocoSource,
    SceneGrasp,
    grasp_from_mujoco,
    hand_coordinates,
    transmission,
)
from .scenes import (
    SceneError,
    SettleInfo,
    SettleOptions,
    available_scenes,
    load_scene,
    scene_about,
    settle,
)

__all__ = [
    "HandOptions",
    "MujocoSource",
    "SceneError",
    "SceneGrasp",
    "SettleInfo",
    "SettleOptions",
    "available_scenes",
    "grasp_from_mujoco",
    "hand_coordinates",
    "load_scene",
    "scene_about",
    "settle",
    "transmission",
]
