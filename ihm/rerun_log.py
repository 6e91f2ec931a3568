"""A settled grasp as a rerun recording (``.rrd``): geoms, contact points, forces.

Entity layout (all static, world frame, metres, +z up):

* ``world/geoms/<body>/<geom>``: one primitive per geom (box, sphere,
  ellipsoid, capsule, cylinder, mesh, plane as a thin square) under its own
  :class:`rerun.Transform3D` (the geom's world pose, ``mat3x3`` from
  ``data.geom_xmat``, so no quaternion order to get wrong);
* ``world/contacts/points``: contact points, labelled with the hand link;
* ``world/contacts/forces``: per contact an arrow from the point along the
  force of the hand on the object, ``vector = force_scale * c`` [m];
* ``world/object``: the object frame (axes), if the grasp is given.

The file is written without spawning a viewer and without network; open it
with ``rerun <file>.rrd``.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from .contacts import SceneGrasp

__all__ = ["log_scene"]

_G = mujoco.mjtGeom
ARROW_RGB = (255, 26, 13)
POINT_RGB = (255, 217, 0)


def _geom_rgba(model: mujoco.MjModel, g: int) -> NDArray[np.uint8]:
    mat = model.geom_matid[g]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]
    return (np.clip(rgba, 0.0, 1.0) * 255).round().astype(np.uint8)


def _geom_name(model: mujoco.MjModel, g: int) -> str:
    return model.geom(g).name or f"geom_{g}"


def _body_name(model: mujoco.MjModel, b: int) -> str:
    return model.body(b).name or f"body_{b}"


def _primitive(model: mujoco.MjModel, g: int, plane_half: float) -> rr.AsComponents | None:
    """The rerun archetype of geom ``g`` in the geom's own frame, or None if unsupported."""
    t = int(model.geom_type[g])
    s = model.geom_size[g]
    rgba = [_geom_rgba(model, g)]
    if t == _G.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[s], colors=rgba, fill_mode="solid")
    if t == _G.mjGEOM_SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[s[0]] * 3], colors=rgba, fill_mode="solid")
    if t == _G.mjGEOM_ELLIPSOID:
        return rr.Ellipsoids3D(half_sizes=[s], colors=rgba, fill_mode="solid")
    if t == _G.mjGEOM_CAPSULE:
        # rerun capsules run from (0, 0, 0) to (0, 0, length); MuJoCo's are centred
        return rr.Capsules3D(
            lengths=[2 * s[1]], radii=[s[0]], translations=[[0.0, 0.0, -s[1]]], colors=rgba
        )
    if t == _G.mjGEOM_CYLINDER:
        return rr.Cylinders3D(lengths=[2 * s[1]], radii=[s[0]], colors=rgba, fill_mode="solid")
    if t == _G.mjGEOM_PLANE:
        hx = s[0] if s[0] > 0 else plane_half
        hy = s[1] if s[1] > 0 else plane_half
        return rr.Boxes3D(half_sizes=[[hx, hy, 1e-4]], colors=rgba, fill_mode="solid")
    if t == _G.mjGEOM_MESH:
        mesh = model.geom_dataid[g]
        va, vn = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        fa, fn = model.mesh_faceadr[mesh], model.mesh_facenum[mesh]
        return rr.Mesh3D(
            vertex_positions=model.mesh_vert[va : va + vn],
            triangle_indices=model.mesh_face[fa : fa + fn],
            albedo_factor=rgba[0],
        )
    return None  # height fields, SDFs


def log_scene(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    grasp: SceneGrasp | None,
    path_rrd: str | os.PathLike[str],
    *,
    app_id: str = "ihm",
    force_scale: float | None = None,
    groups: tuple[int, ...] = (0, 1, 2, 3),
) -> Path:
    """Write the scene at ``data`` and the grasp's contacts to a rerun file.

    Parameters
    ----------
    model, data : the scene, after ``mj_forward``.
    grasp : contacts to log (``ihm.grasp_from_mujoco``), or None for geoms only.
    path_rrd : the ``.rrd`` file to write; parent folders are created.
    app_id : rerun application id.
    force_scale : arrow length per newton [m/N]. Default: the largest force is
        0.8 times the object's bounding radius long (as in :func:`ihm.render.render_png`).
    groups : geom groups to log (MJCF convention: 2 visual, 3 collision).

    Returns the path written. Nothing is spawned or sent over the network.
    """
    path = Path(path_rrd)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(app_id)
    rec.save(path)
    try:
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        keep = model.geom_type != _G.mjGEOM_PLANE
        plane_half = (
            2.0 * float(np.max(model.geom_rbound[keep])) if keep.any() else model.stat.extent
        )
        for g in range(model.ngeom):
            if int(model.geom_group[g]) not in groups or model.geom_rgba[g, 3] == 0:
                continue
            prim = _primitive(model, g, plane_half)
            if prim is None:
                continue
            entity = f"world/geoms/{_body_name(model, model.geom_bodyid[g])}/{_geom_name(model, g)}"
            rec.log(
                entity,
                rr.Transform3D(
                    translation=data.geom_xpos[g], mat3x3=data.geom_xmat[g].reshape(3, 3)
                ),
                static=True,
            )
            rec.log(entity, prim, static=True)
        if grasp is not None and grasp.m:
            _log_contacts(rec, model, grasp, force_scale)
    finally:
        rec.flush()
        rec.disconnect()
    return path


def _log_contacts(
    rec: rr.RecordingStream, model: mujoco.MjModel, grasp: SceneGrasp, force_scale: float | None
) -> None:
    obj = int(model.geom_bodyid[grasp.object_geoms[0]])
    on_obj = model.geom_bodyid == obj
    radius = float(model.geom_rbound[on_obj].max()) if on_obj.any() else 0.05
    forces = grasp.forces_world()
    if force_scale is not None and not (np.isfinite(force_scale) and force_scale >= 0):
        raise ValueError(f"force_scale must be a finite number >= 0 [m/N], got {force_scale!r}")
    if force_scale is None:
        fmax = float(np.linalg.norm(forces, axis=1).max())
        force_scale = 0.8 * radius / fmax if fmax > 1e-9 else 0.0
    links = [_body_name(model, b) for b in grasp.hand_bodies]
    labels = [
        f"{link}: |c| = {np.linalg.norm(c):.3g} N" for link, c in zip(links, forces, strict=True)
    ]
    points = grasp.points_world()
    rec.log(
        "world/object",
        rr.Transform3D(translation=grasp.object_pos, mat3x3=grasp.object_mat),
        rr.TransformAxes3D(axis_length=radius),
        static=True,
    )
    rec.log(
        "world/contacts/points",
        rr.Points3D(points, radii=0.07 * radius, colors=[POINT_RGB], labels=links),
        static=True,
    )
    rec.log(
        "world/contacts/forces",
        rr.Arrows3D(
            origins=points,
            vectors=force_scale * forces,
            radii=0.025 * radius,
            colors=[ARROW_RGB],
            labels=labels,
        ),
        static=True,
    )
