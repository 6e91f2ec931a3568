"""MuJoCo scenes as rerun recordings (``.rrd``): geoms, contact points and forces, scalars.

One code path, :class:`SceneRecorder`, writes both the static picture of a settled grasp
(:func:`log_scene`, ``python -m ihm show --rrd``) and time series of rollouts
(``python -m train.rollout``). Entity layout (world frame, metres, +z up):

* ``world/geoms/<body>/<geom>``: one primitive per geom (box, sphere, ellipsoid,
  capsule, cylinder, mesh, plane as a thin square), logged once (static), under
  its own :class:`rerun.Transform3D`: the geom's world pose ``data.geom_xpos`` and
  ``mat3x3`` from ``data.geom_xmat`` (no quaternion, so no wxyz/xyzw order to get
  wrong). Geoms of bodies welded to the world get one static pose, the others
  one pose per logged time;
* ``world/contacts/points``: contact points, labelled with the body touching the object;
* ``world/contacts/forces``: per contact an arrow from the point along the force
  applied *on the object* (by a hand link, or the palm or floor),
  ``vector = force_scale * c`` [m];
* ``world/object``: the object frame (axes);
* any scalar time series the caller adds (:meth:`SceneRecorder.log_scalars`).

Time: :meth:`SceneRecorder.set_time` sets a sequence timeline ``step`` and a
duration timeline ``sim_time`` [s]; data logged with ``static=True`` hold at every
time. The file is written without spawning a viewer and without network; open it
with ``rerun <file>.rrd``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import mujoco
import numpy as np
import rerun as rr
from numpy.typing import ArrayLike, NDArray

from .contacts import SceneGrasp, contact_frame_force, object_contact_ids

__all__ = ["ObjectContacts", "SceneRecorder", "log_scene", "object_contacts"]

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


def _check_force_scale(force_scale: float | None) -> None:
    if force_scale is not None and not (np.isfinite(force_scale) and force_scale >= 0):
        raise ValueError(f"force_scale must be a finite number >= 0 [m/N], got {force_scale!r}")


def _body_radius(model: mujoco.MjModel, body: int) -> float:
    """Bounding radius of the body's geoms [m] (0.05 m if it has none)."""
    on_body = model.geom_bodyid == body
    return float(model.geom_rbound[on_body].max()) if on_body.any() else 0.05


@dataclass(frozen=True)
class ObjectContacts:
    """The contacts of one body (the object) with the rest of the scene, world frame.

    points : (k, 3) contact positions (``data.contact.pos``) [m]
    forces : (k, 3) force applied on the object at each contact by the other body
        (a hand link, or the palm or floor) [N], from ``mj_contactForce``
    bodies : (k,) name of the other body at each contact
    """

    points: NDArray[np.float64]
    forces: NDArray[np.float64]
    bodies: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.bodies)


def object_contacts(
    model: mujoco.MjModel, data: mujoco.MjData, object_body: str | int = "object"
) -> ObjectContacts:
    """Every active contact of ``object_body`` at ``data``, read from ``data.contact``.

    Unlike :func:`ihm.grasp_from_mujoco` this takes any ``condim`` (the torsional and
    rolling components of ``condim`` 4 and 6 are not reported) and any other body, and
    merges nothing: one row per MuJoCo contact that has constraint rows (``efc_address
    >= 0``). The force is that of the other body on the object (docs/design.md's sign), in
    world coordinates: ``mj_contactForce`` gives the force of ``geom1`` on ``geom2`` in
    the contact frame, negated where the object is ``geom1`` (as in :mod:`ihm.contacts`).
    """
    try:
        obj = model.body(object_body).id
    except (KeyError, IndexError) as exc:
        raise ValueError(f"no body {object_body!r} in the model") from exc
    points, forces, bodies = [], [], []
    for i, other, obj_first in object_contact_ids(data, (model.geom_bodyid == obj).tolist()):
        frame, c = contact_frame_force(model, data, i, object_is_geom1=obj_first)
        points.append(data.contact[i].pos.copy())
        forces.append(frame.T @ c)
        bodies.append(_body_name(model, int(model.geom_bodyid[other])))
    return ObjectContacts(
        points=np.array(points).reshape(-1, 3),
        forces=np.array(forces).reshape(-1, 3),
        bodies=tuple(bodies),
    )


class SceneRecorder:
    """A rerun recording of a MuJoCo model: geoms once, then poses, contacts and scalars.

    Parameters
    ----------
    model : the MuJoCo model whose geoms are logged (once, static, on construction).
    path_rrd : the ``.rrd`` file to write; parent folders are created.
    app_id : rerun application id (recordings with the same id open side by side).
    recording_name : name the viewer shows for the recording (default: none).
    groups : geom groups to log (MJCF convention: 2 visual, 3 collision); geoms with
        ``rgba`` alpha 0 are never logged.
    blueprint : the viewer layout stored in the file (``rerun.blueprint.Blueprint``),
        or None for rerun's automatic one.

    Static data go to the file at once. Time series (poses, frames, contacts,
    scalars) are buffered and written as columns (``send_columns``) by :meth:`flush`
    and :meth:`close`: 20x cheaper than one ``log`` call per value. Rerun stores
    positions and matrices as float32. Use as a context manager, or call
    :meth:`close`. Nothing is spawned or sent over the network.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        path_rrd: str | os.PathLike[str],
        *,
        app_id: str = "ihm",
        recording_name: str | None = None,
        groups: Sequence[int] = (0, 1, 2, 3),
        blueprint: rr.blueprint.BlueprintLike | None = None,
    ) -> None:
        self.model = model
        self.path = Path(path_rrd)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(app_id)
        self.rec.save(self.path, default_blueprint=blueprint)
        self._closed = False
        self._time: tuple[int, float] | None = None
        # entity -> (kind, steps, sim times [s], values): time series not yet written
        self._series: dict[str, tuple[str, list[int], list[float], list[NDArray[np.float64]]]]
        self._series = {}
        self._axes: set[str] = set()
        # (step, sim time [s], points, arrow vectors [m], point labels, arrow labels)
        self._contacts: list[tuple[int, float, NDArray, NDArray, list[str], list[str]]] = []
        self._contact_style = False
        if recording_name is not None:
            self.rec.send_recording_name(recording_name)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        keep = model.geom_type != _G.mjGEOM_PLANE
        plane_half = (
            2.0 * float(np.max(model.geom_rbound[keep])) if keep.any() else model.stat.extent
        )
        fixed = (model.body_weldid == 0) & (model.body_mocapid == -1)
        self.entities: dict[int, str] = {}  # geom id -> entity path, the geoms logged
        self._moving: list[int] = []
        self._fixed: list[int] = []
        for g in range(model.ngeom):
            if int(model.geom_group[g]) not in groups or model.geom_rgba[g, 3] == 0:
                continue
            prim = _primitive(model, g, plane_half)
            if prim is None:
                continue
            entity = f"world/geoms/{_body_name(model, model.geom_bodyid[g])}/{_geom_name(model, g)}"
            self.rec.log(entity, prim, static=True)
            self.entities[g] = entity
            (self._fixed if fixed[model.geom_bodyid[g]] else self._moving).append(g)
        self._fixed_logged = False

    # -- time -------------------------------------------------------------------------------
    def set_time(self, step: int, sim_time_s: float) -> None:
        """Log what follows at ``step`` (sequence timeline ``step``) and ``sim_time_s``
        (duration timeline ``sim_time`` [s])."""
        self._time = (int(step), float(sim_time_s))
        self.rec.set_time("step", sequence=self._time[0])
        self.rec.set_time("sim_time", duration=self._time[1])

    def _append(self, entity: str, kind: str, value: NDArray[np.float64]) -> None:
        if self._time is None:
            raise RuntimeError("call set_time(step, sim_time_s) before logging a time series")
        series = self._series.setdefault(entity, (kind, [], [], []))
        if series[0] != kind:
            raise ValueError(f"{entity!r} already holds {series[0]} values, not {kind}")
        series[1].append(self._time[0])
        series[2].append(self._time[1])
        series[3].append(value)

    def _pose(self, entity: str, position: ArrayLike, rotation: ArrayLike, static: bool) -> None:
        pos = np.asarray(position, dtype=float).reshape(3)
        mat = np.asarray(rotation, dtype=float).reshape(3, 3)
        if static:
            self.rec.log(entity, rr.Transform3D(translation=pos, mat3x3=mat), static=True)
        else:
            self._append(entity, "pose", np.concatenate([pos, mat.ravel()]))

    # -- scene ------------------------------------------------------------------------------
    def log_poses(self, data: mujoco.MjData, *, static: bool = False) -> None:
        """The world pose of every logged geom (``data.geom_xpos``, ``data.geom_xmat``).

        Geoms on bodies welded to the world are logged static, the first time only; the
        others at the current time (or static with ``static=True``)."""
        if not self._fixed_logged:
            for g in self._fixed:
                self._pose(self.entities[g], data.geom_xpos[g], data.geom_xmat[g], True)
            self._fixed_logged = True
        for g in self._moving:
            self._pose(self.entities[g], data.geom_xpos[g], data.geom_xmat[g], static)

    def log_frame(
        self,
        entity: str,
        position: ArrayLike,
        rotation: ArrayLike,
        axis_length: float,
        *,
        static: bool = False,
    ) -> None:
        """A coordinate frame: ``position`` (3,) [m], ``rotation`` (3, 3) (columns: the frame's
        axes in world coordinates), drawn as axes ``axis_length`` [m] long (set once)."""
        if entity not in self._axes:
            self.rec.log(entity, rr.TransformAxes3D(axis_length=axis_length), static=True)
            self._axes.add(entity)
        self._pose(entity, position, rotation, static)

    def log_contacts(
        self,
        points: ArrayLike,
        forces: ArrayLike,
        labels: Sequence[str],
        *,
        force_scale: float,
        radius: float,
        static: bool = False,
    ) -> None:
        """Contact points ``(k, 3)`` [m] labelled ``labels`` and force arrows ``(k, 3)`` [N]
        (``force_scale`` [m/N]; points and arrows sized by ``radius`` [m]) at
        ``world/contacts``, at the current time or static (a recording holds one or the
        other). Over time, ``k = 0`` clears what an earlier time showed, and the sizes of
        the first call hold throughout."""
        _check_force_scale(force_scale)
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        f = np.asarray(forces, dtype=float).reshape(-1, 3)
        if not len(p) == len(f) == len(labels):
            raise ValueError(
                f"points, forces and labels differ in length: {len(p)}, {len(f)}, {len(labels)}"
            )
        arrow_labels = [
            f"{name}: |c| = {np.linalg.norm(c):.3g} N" for name, c in zip(labels, f, strict=True)
        ]
        if static:
            self.rec.log(
                "world/contacts/points",
                rr.Points3D(p, radii=0.07 * radius, colors=[POINT_RGB], labels=list(labels)),
                static=True,
            )
            self.rec.log(
                "world/contacts/forces",
                rr.Arrows3D(
                    origins=p,
                    vectors=force_scale * f,
                    radii=0.025 * radius,
                    colors=[ARROW_RGB],
                    labels=arrow_labels,
                ),
                static=True,
            )
            return
        if self._time is None:
            raise RuntimeError("call set_time(step, sim_time_s) before logging a time series")
        if not self._contact_style:  # sizes and colours hold at every time
            self.rec.log(
                "world/contacts/points",
                rr.Points3D.from_fields(radii=0.07 * radius, colors=[POINT_RGB]),
                static=True,
            )
            self.rec.log(
                "world/contacts/forces",
                rr.Arrows3D.from_fields(radii=0.025 * radius, colors=[ARROW_RGB]),
                static=True,
            )
            self._contact_style = True
        self._contacts.append((*self._time, p, force_scale * f, list(labels), arrow_labels))

    def log_object(
        self,
        data: mujoco.MjData,
        object_body: str | int = "object",
        *,
        force_scale: float,
        static: bool = False,
    ) -> ObjectContacts:
        """The object frame (``world/object``) and all its contacts (:func:`object_contacts`),
        arrows ``force_scale`` [m/N] per newton; returns the contacts logged."""
        contacts = object_contacts(self.model, data, object_body)
        b = self.model.body(object_body).id
        radius = _body_radius(self.model, b)
        self.log_frame("world/object", data.xpos[b], data.xmat[b], radius, static=static)
        self.log_contacts(
            contacts.points,
            contacts.forces,
            contacts.bodies,
            force_scale=force_scale,
            radius=radius,
            static=static,
        )
        return contacts

    # -- time series ------------------------------------------------------------------------
    def log_scalars(self, values: Mapping[str, float]) -> None:
        """One scalar per entity path at the current time (e.g. ``{"reward": 0.4}``)."""
        for entity, v in values.items():
            self._append(entity, "scalar", np.array(float(v)))

    # -- file -------------------------------------------------------------------------------
    def flush(self) -> None:
        """Write the buffered time series as columns, one chunk per entity."""
        for entity, (kind, steps, times, values) in self._series.items():
            v = np.array(values)
            if kind == "pose":
                columns = rr.Transform3D.columns(
                    translation=v[:, :3], mat3x3=v[:, 3:].reshape(-1, 3, 3)
                )
            else:
                columns = rr.Scalars.columns(scalars=v)
            self.rec.send_columns(
                entity,
                indexes=[
                    rr.TimeColumn("step", sequence=steps),
                    rr.TimeColumn("sim_time", duration=times),
                ],
                columns=columns,
            )
        self._series.clear()
        if self._contacts:
            steps, times, p, v, labels, arrow_labels = zip(*self._contacts, strict=True)
            lengths = [len(x) for x in p]
            indexes = [
                rr.TimeColumn("step", sequence=steps),
                rr.TimeColumn("sim_time", duration=times),
            ]
            flat = [x for xs in labels for x in xs]
            self.rec.send_columns(
                "world/contacts/points",
                indexes=indexes,
                columns=rr.Points3D.columns(positions=np.concatenate(p), labels=flat).partition(
                    lengths
                ),
            )
            self.rec.send_columns(
                "world/contacts/forces",
                indexes=indexes,
                columns=rr.Arrows3D.columns(
                    origins=np.concatenate(p),
                    vectors=np.concatenate(v),
                    labels=[x for xs in arrow_labels for x in xs],
                ).partition(lengths),
            )
            self._contacts.clear()
        self.rec.flush()

    def close(self) -> None:
        """Flush everything to the file and close it (idempotent)."""
        if not self._closed:
            self._closed = True
            self.flush()
            self.rec.disconnect()

    def __enter__(self) -> SceneRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


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
    """Write the scene at ``data`` and the grasp's contacts to a rerun file, all static.

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
    _check_force_scale(force_scale)
    with SceneRecorder(model, path_rrd, app_id=app_id, groups=groups) as rec:
        rec.log_poses(data, static=True)
        if grasp is not None and grasp.m:
            radius = _body_radius(model, int(model.geom_bodyid[grasp.object_geoms[0]]))
            forces = grasp.forces_world()
            if force_scale is None:
                fmax = float(np.linalg.norm(forces, axis=1).max())
                force_scale = 0.8 * radius / fmax if fmax > 1e-9 else 0.0
            rec.log_frame("world/object", grasp.object_pos, grasp.object_mat, radius, static=True)
            rec.log_contacts(
                grasp.points_world(),
                forces,
                [_body_name(model, b) for b in grasp.hand_bodies],
                force_scale=force_scale,
                radius=radius,
                static=True,
            )
    return rec.path
