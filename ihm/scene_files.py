"""What :mod:`ihm.scenes` reads off a scene's MJCF file apart from the physics: whether a
scene argument is a file's path or one of our names, the name its outputs carry, its
``<custom>`` elements, its free bodies (the candidates for the grasped object) and the
commands it settles with by default (the conventions: :mod:`ihm.scenes`)."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stability import GraspError

__all__ = [
    "SceneError",
    "as_forces",
    "check_free_body",
    "custom_numeric",
    "custom_text",
    "default_preload",
    "free_bodies",
    "is_scene_file",
    "scene_label",
    "seat_forces",
    "start_commands",
]


class SceneError(GraspError):
    """Unknown scene, a malformed scene file, or a grasp that does not settle."""


def is_scene_file(scene: str) -> bool:
    """Whether ``scene`` is an MJCF file's path (it ends in ``.xml`` or holds a path
    separator) rather than the name of a scene in ``assets/scenes``."""
    return scene.endswith(".xml") or any(sep and sep in scene for sep in (os.sep, os.altsep))


def scene_label(scene: str) -> str:
    """The scene's name in output file names and titles: a file's stem, or the name."""
    return Path(scene).stem if is_scene_file(scene) else scene


def custom_numeric(model: mujoco.MjModel, name: str) -> NDArray[np.float64] | None:
    """The data of ``<custom><numeric name=...>``, or None without such an element."""
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    if i < 0:
        return None
    adr, size = model.numeric_adr[i], model.numeric_size[i]
    return np.array(model.numeric_data[adr : adr + size], dtype=float)


def custom_text(model: mujoco.MjModel, name: str) -> str | None:
    """The data of ``<custom><text name=...>``, or None without such an element."""
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, name)
    if i < 0:
        return None
    adr, size = model.text_adr[i], model.text_size[i]
    return bytes(model.text_data[adr : adr + size]).split(b"\0", 1)[0].decode()


def free_bodies(model: mujoco.MjModel) -> list[str]:
    """Names of the bodies with a free joint, in body order (unnamed ones as ``#id``)."""
    ids = [int(model.jnt_bodyid[j]) for j in range(model.njnt)
           if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]  # fmt: skip
    return [model.body(b).name or f"#{b}" for b in ids]


def check_free_body(model: mujoco.MjModel, body: str, name: str) -> None:
    """:class:`SceneError` naming the free bodies of scene ``name``'s ``model`` unless
    ``body`` is one of them."""
    free = free_bodies(model)
    if body not in free:
        raise SceneError(f"scene {name!r} has no free body named {body!r} (its free bodies: "
                         f"{', '.join(free) or 'none'})")  # fmt: skip


def as_forces(value: ArrayLike, nu: int) -> NDArray[np.float64]:
    """``value`` as a float array; :class:`SceneError` if it is not numbers (``nu``: how
    many the message asks for)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"actuator forces must be {nu} numbers, got {value!r}") from exc


def seat_forces(seat: ArrayLike, nu: int, name: str) -> NDArray[np.float64]:
    """The seated protocol's commands (:func:`ihm.scenes.load_scene`'s ``seat``) as (nu,)
    actuator forces; :class:`SceneError` for another length."""
    seat_c = as_forces(seat, nu).reshape(-1)
    if seat_c.shape != (nu,):
        raise SceneError(f"seat for scene {name!r} needs {nu} actuator forces, "
                         f"got shape {seat_c.shape}")  # fmt: skip
    return seat_c


def default_preload(model: mujoco.MjModel) -> NDArray[np.float64]:
    """The scene's default commanded actuator forces (``ihm_preload``), shape (nu,)."""
    f = custom_numeric(model, "ihm_preload")
    if f is None:
        raise SceneError("scene has no <numeric name='ihm_preload'> (default actuator forces)")
    if f.shape != (model.nu,):
        raise SceneError(f"ihm_preload has {f.size} values for {model.nu} actuators")
    return f


def start_commands(
    model: mujoco.MjModel, data: mujoco.MjData, preload: ArrayLike | None, name: str
) -> tuple[NDArray[np.float64], str]:
    """The commands scene ``name`` settles with and their kind (``command`` of
    :func:`ihm.scenes.settle`): ``preload``, else the scene's ``ihm_preload``, as actuator
    forces in each actuator's unit (``"force"``); a scene without ``ihm_preload`` settles
    with the controls ``data.ctrl`` of its start state (``"ctrl"``: the ``init``
    keyframe's, zeros without one), as MuJoCo would simulate the file."""
    if preload is None and custom_numeric(model, "ihm_preload") is None:
        return data.ctrl.copy(), "ctrl"
    f_c = default_preload(model) if preload is None else as_forces(preload, model.nu)
    if f_c.shape != (model.nu,):
        raise SceneError(
            f"preload for scene {name!r} needs {model.nu} actuator forces "
            f"(actuators: {', '.join(model.actuator(i).name for i in range(model.nu))}), "
            f"got shape {f_c.shape}"
        )
    return f_c, "force"
