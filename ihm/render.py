"""Offscreen pictures of a settled grasp: the scene, its contacts and contact forces.

:func:`render_png` renders with :class:`mujoco.Renderer` and adds, per contact
of a :class:`~ihm.contacts.SceneGrasp`, a sphere at the contact point and an
arrow for the force of the hand on the object: from the contact point along
``forces_world()``, length ``force_scale * |c|`` [m]. The arrows point into
the object, so they are drawn over the scene: opaque where nothing hides
them, blended half-and-half with the scene where the object or a finger
does (an "x-ray" look that keeps the depth cue). Where no geom is drawn and
the scene has no skybox, the background is a light grey.

Offscreen OpenGL: MuJoCo chooses its GL backend from ``MUJOCO_GL`` when
``mujoco`` is first imported. :func:`render_png` uses ``MUJOCO_GL`` as it is
at call time, and ``egl`` on Linux when it is unset (headless machines have
no display for GLFW); ``python -m ihm`` sets ``MUJOCO_GL=egl`` before it
imports MuJoCo. A context that cannot be created raises :class:`RenderError`
saying which backend was tried and how to fix it.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from .contacts import SceneGrasp

__all__ = ["ARROW_RGBA", "POINT_RGBA", "RenderError", "render_png", "scene_center_radius"]

ARROW_RGBA = np.array([1.0, 0.1, 0.05, 1.0], dtype=np.float32)
"""Colour of the contact-force arrows (red; emissive, so lighting only brightens it)."""
POINT_RGBA = np.array([1.0, 0.85, 0.0, 1.0], dtype=np.float32)
"""Colour of the contact-point spheres (yellow; emissive)."""
BACKGROUND_RGB = np.array([236, 238, 242], dtype=np.uint8)
"""Background where nothing is drawn and the scene has no skybox."""
XRAY = 0.7
"""Weight of a hidden arrow over the scene in front of it."""

_GL_MODULES = {"egl": "mujoco.egl", "osmesa": "mujoco.osmesa", "glfw": "mujoco.glfw"}


class RenderError(RuntimeError):
    """The offscreen OpenGL context cannot be created, or the picture cannot be written."""


def _gl_backend() -> str:
    """The GL backend to use: ``MUJOCO_GL`` now, else ``egl`` on Linux, else ``glfw``."""
    env = os.environ.get("MUJOCO_GL", "").strip().lower()
    if env:
        return env
    return "egl" if sys.platform.startswith("linux") else "glfw"


def _fix_hint(backend: str) -> str:
    if backend == "egl":
        return (
            "install the EGL runtime (Debian/Ubuntu: apt-get install libegl1 libgl1; "
            "an NVIDIA GPU needs its driver's libEGL_nvidia), or try MUJOCO_GL=osmesa "
            "(apt-get install libosmesa6) or MUJOCO_GL=glfw with a display"
        )
    if backend == "osmesa":
        return (
            "install OSMesa (Debian/Ubuntu: apt-get install libosmesa6) and PyOpenGL, "
            "or try MUJOCO_GL=egl (apt-get install libegl1)"
        )
    return (
        "GLFW needs a display (set DISPLAY, or run under xvfb-run); on a headless "
        "machine set MUJOCO_GL=egl (apt-get install libegl1) or MUJOCO_GL=osmesa"
    )


@contextlib.contextmanager
def _gl_context_class(backend: str) -> Iterator[None]:
    """Make :class:`mujoco.Renderer` use ``backend`` while the context is created.

    MuJoCo fixes its ``GLContext`` class when ``mujoco`` is imported; when that
    choice differs from ``backend`` (``MUJOCO_GL`` was unset or changed since),
    the renderer module's ``gl_context.GLContext`` is swapped for the
    backend's own class during the ``with`` block.
    """
    renderer_module = sys.modules[mujoco.Renderer.__module__]
    gl_context = getattr(renderer_module, "gl_context", None)
    chosen = getattr(gl_context, "_MUJOCO_GL", None)
    if gl_context is None or chosen == backend or backend not in _GL_MODULES:
        yield
        return
    if backend in ("egl", "osmesa"):
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    cls = importlib.import_module(_GL_MODULES[backend]).GLContext
    saved = gl_context.GLContext
    gl_context.GLContext = cls
    try:
        yield
    finally:
        gl_context.GLContext = saved


def make_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    backend = _gl_backend()
    try:
        with _gl_context_class(backend):
            return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # GL errors surface as ImportError, OSError, RuntimeError, ...
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RenderError(
            f"cannot create an offscreen OpenGL context with MUJOCO_GL={backend} "
            f"({type(exc).__name__}: {first}); {_fix_hint(backend)}"
        ) from exc


def _object_body(model: mujoco.MjModel, grasp: SceneGrasp | None) -> int:
    if grasp is not None and len(grasp.object_geoms):
        return int(model.geom_bodyid[grasp.object_geoms[0]])
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")


def scene_center_radius(
    model: mujoco.MjModel, data: mujoco.MjData, obj: int = -1
) -> tuple[NDArray[np.float64], float]:
    """A point to look at and the radius of the hand and object around it [m].

    The geoms framed are those of every body but the world (so no floor or
    table), planes excluded; the point is halfway between body ``obj`` (if
    given) and the centre of their bounding box, and the radius that of the
    smallest sphere about it holding each geom's bounding sphere (``geom_rbound``).
    """
    keep = (
        (model.geom_bodyid != 0)
        & (model.geom_type != mujoco.mjtGeom.mjGEOM_PLANE)
        & (model.geom_rbound > 0)
    )
    if not keep.any():
        return np.asarray(model.stat.center, dtype=float).copy(), float(model.stat.extent)
    pos, rb = data.geom_xpos[keep], model.geom_rbound[keep]
    center = 0.5 * ((pos - rb[:, None]).min(axis=0) + (pos + rb[:, None]).max(axis=0))
    if obj >= 0:
        center = 0.5 * (center + data.xpos[obj])
    radius = float(np.max(np.linalg.norm(pos - center, axis=1) + rb))
    return center, radius


def _camera(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    grasp: SceneGrasp | None,
    camera: str | int | mujoco.MjvCamera | None,
) -> str | int | mujoco.MjvCamera:
    """``camera`` if given; the scene's camera ``overview``; else a free camera on the object."""
    if camera is not None:
        if (
            isinstance(camera, str)
            and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0
        ):
            names = [model.camera(i).name for i in range(model.ncam)]
            raise RenderError(f"no camera named {camera!r}; cameras: {', '.join(names) or 'none'}")
        return camera
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "overview") >= 0:
        return "overview"
    obj = _object_body(model, grasp)
    center, radius = scene_center_radius(model, data, obj)
    cam = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, cam)
    cam.lookat[:] = center
    half_fovy = np.deg2rad(model.vis.global_.fovy) / 2
    cam.distance = 1.05 * radius / np.sin(half_fovy)
    cam.azimuth = _side_azimuth(grasp) if grasp is not None and grasp.m else 135.0
    cam.elevation = -25.0
    return cam


def _side_azimuth(grasp: SceneGrasp) -> float:
    """Azimuth [deg] of a camera that sees the squeeze from the side.

    The horizontal direction least aligned with the contact normals (smallest
    eigenvector of ``sum n n^T`` over their xy parts) keeps the fingers from
    hiding the contacts; turned 30 deg for depth, on the side nearer azimuth 135.
    """
    n = grasp.frames_world()[:, 0, :2]
    w, v = np.linalg.eigh(n.T @ n)
    az = np.degrees(np.arctan2(v[1, 0], v[0, 0])) + 30.0
    opposite = az + 180.0
    dist = [abs((a - 135.0 + 180.0) % 360.0 - 180.0) for a in (az, opposite)]
    return float((az if dist[0] <= dist[1] else opposite) % 360.0)


def _add_geom(scene: mujoco.MjvScene) -> mujoco.MjvGeom | None:
    if scene.ngeom >= scene.maxgeom:
        return None
    g = scene.geoms[scene.ngeom]
    scene.ngeom += 1
    return g


def _draw_contacts(
    scene: mujoco.MjvScene,
    grasp: SceneGrasp,
    force_scale: float,
    point_radius: float,
    arrow_width: float,
) -> None:
    """Append a sphere per contact point and an arrow per contact force to ``scene``."""
    eye = np.eye(3).reshape(-1)
    for p, f in zip(grasp.points_world(), grasp.forces_world(), strict=True):
        g = _add_geom(scene)
        if g is None:
            return
        mujoco.mjv_initGeom(
            g, mujoco.mjtGeom.mjGEOM_SPHERE, np.full(3, point_radius), p, eye, POINT_RGBA
        )
        g.emission = 1.0  # emissive: shading cannot darken it
        tip = p + force_scale * f
        if np.linalg.norm(tip - p) < 1e-6:
            continue
        g = _add_geom(scene)
        if g is None:
            return
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), p, eye, ARROW_RGBA)
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_ARROW, arrow_width, p, tip)
        g.emission = 1.0


@contextlib.contextmanager
def _visual_settings(model: mujoco.MjModel, width: int, height: int) -> Iterator[None]:
    """Visual settings for the picture, restored afterwards (``model.vis`` only).

    The offscreen buffer must hold the image; a model without lights gets a
    brighter headlight than MuJoCo's default (ambient 0.1, diffuse 0.4).
    """
    glob, head = model.vis.global_, model.vis.headlight
    saved = (glob.offwidth, glob.offheight, head.ambient.copy(), head.diffuse.copy())
    glob.offwidth, glob.offheight = max(glob.offwidth, width), max(glob.offheight, height)
    if model.nlight == 0:
        head.ambient[:] = np.maximum(head.ambient, 0.35)
        head.diffuse[:] = np.maximum(head.diffuse, 0.6)
    try:
        yield
    finally:
        glob.offwidth, glob.offheight = saved[:2]
        head.ambient[:], head.diffuse[:] = saved[2], saved[3]


def _contact_sizes(
    model: mujoco.MjModel, grasp: SceneGrasp, obj: int, force_scale: float | None
) -> tuple[float, float, float]:
    """(force scale [m/N], point radius [m], arrow width [m]) after the object's size."""
    on_obj = model.geom_bodyid == obj
    radius = float(model.geom_rbound[on_obj].max()) if obj >= 0 and on_obj.any() else 0.05
    if force_scale is not None and not (np.isfinite(force_scale) and force_scale >= 0):
        raise ValueError(f"force_scale must be a finite number >= 0 [m/N], got {force_scale!r}")
    if force_scale is None:
        fmax = float(np.linalg.norm(grasp.forces_world(), axis=1).max())
        force_scale = 0.8 * radius / fmax if fmax > 1e-9 else 0.0
    return force_scale, 0.06 * radius, 0.07 * radius


def _has_skybox(model: mujoco.MjModel) -> bool:
    return bool(np.any(model.tex_type == mujoco.mjtTexture.mjTEXTURE_SKYBOX))


def _render_layers(
    renderer: mujoco.Renderer,
    model: mujoco.MjModel,
    grasp: SceneGrasp | None,
    obj: int,
    force_scale: float | None,
) -> NDArray[np.uint8]:
    """Render the scene already in ``renderer.scene`` and composite the contacts over it."""
    scene = renderer.scene
    n_scene = scene.ngeom
    sizes = _contact_sizes(model, grasp, obj, force_scale) if grasp is not None else None
    if sizes is not None:
        _draw_contacts(scene, grasp, *sizes)
    image = renderer.render().copy()
    if not _has_skybox(model):
        renderer.enable_depth_rendering()
        depth = renderer.render()
        renderer.disable_depth_rendering()
        far = depth >= 0.999 * depth.max()
        image[far] = BACKGROUND_RGB
    if sizes is None or scene.ngeom == n_scene:
        return image
    # the contacts alone, on black: wherever they differ from the full picture,
    # something hides them; blend them over it there
    scene.ngeom = 0
    _draw_contacts(scene, grasp, *sizes)
    skybox = scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX]
    scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
    try:
        overlay = renderer.render()
    finally:
        scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = skybox
    mask = overlay.max(axis=2) > 16
    hidden = mask & (np.abs(overlay.astype(int) - image).sum(axis=2) > 48)
    out = image.astype(np.float32)
    out[hidden] = XRAY * overlay[hidden] + (1 - XRAY) * out[hidden]
    return out.round().astype(np.uint8)


def render_png(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    grasp: SceneGrasp | None,
    path: str | os.PathLike[str],
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int | mujoco.MjvCamera | None = None,
    force_scale: float | None = None,
    contacts: bool = True,
) -> Path:
    """Render the scene at ``data`` with the grasp's contacts and forces to a PNG.

    Parameters
    ----------
    model, data : the scene, after ``mj_forward`` (e.g. from ``ihm.load_scene``).
    grasp : contacts to draw (``ihm.grasp_from_mujoco(model, data)``), or None
        for the scene alone. Per contact: a yellow sphere at the point and a red
        arrow from the point along the force of the hand on the object.
    path : where to write the PNG; parent folders are created.
    width, height : image size [pixels].
    camera : a camera name or id of the model, or an ``MjvCamera``. Default:
        the scene's camera ``overview`` if it has one, else a free camera
        looking at the object from azimuth 135 deg, elevation -25 deg, far
        enough to frame the hand.
    force_scale : arrow length per newton [m/N]. Default: the largest force
        is drawn 0.8 times the object's bounding radius long.
    contacts : draw the contact points and arrows; False renders the same
        view (the grasp still aims the camera) without them.

    Returns the path written. Geom groups 0-3 are shown (MJCF convention:
    2 visual, 3 collision).

    Raises
    ------
    RenderError
        No OpenGL context (the message names ``MUJOCO_GL`` and the fix), an
        unknown camera, or a file that cannot be written.
    """
    if width < 1 or height < 1:
        raise RenderError(f"image size must be positive, got {width} x {height}")
    path = Path(path)
    obj = _object_body(model, grasp)
    with _visual_settings(model, width, height):
        renderer = make_renderer(model, width, height)
        try:
            opt = mujoco.MjvOption()
            mujoco.mjv_defaultOption(opt)
            opt.geomgroup[:4] = 1
            cam = _camera(model, data, grasp, camera)
            renderer.update_scene(data, camera=cam, scene_option=opt)
            pixels = _render_layers(
                renderer,
                model,
                grasp if contacts and grasp is not None and grasp.m else None,
                obj,
                force_scale,
            )
        finally:
            renderer.close()
    try:
        import matplotlib.image

        path.parent.mkdir(parents=True, exist_ok=True)
        matplotlib.image.imsave(path, pixels, format="png")
    except OSError as exc:
        raise RenderError(f"cannot write {path}: {exc}") from exc
    return path
