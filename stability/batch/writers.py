"""Query files from the inputs users have: random grasps (:mod:`stability.examples`), the
directions of a resistible-force map, and any list of ``(grasp, query)`` pairs. Grasps read
from MuJoCo scenes: :func:`ihm.sim_maps.scene_map_rows` (the ``ihm`` layer)."""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import GraspError
from ..examples import random_fingers, random_wrench
from ..grasp import Grasp
from ..maps import plane_axes
from ..queries import Existence, MaxDisturbance, Query
from .rows import encode_query

__all__ = ["MapPlane", "map_rows", "random_planar", "random_rows", "write_rows"]


def write_rows(path: str | Path, rows: Iterable[dict[str, Any]]) -> int:
    """Write query rows (:func:`stability.batch.rows.encode_query`) as JSON lines; returns
    how many."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    with open(path, "w", encoding="utf-8") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
            n += 1
    return n


def random_planar(rng: np.random.Generator, m: int) -> Grasp:
    """``m`` contacts on a circle of radius 0.05 m, normals towards the centre tilted by up
    to 0.3 rad, mu in [0.3, 1]: a rigid planar grasp."""
    a = np.sort(rng.uniform(0.0, 2 * np.pi, m))
    pts = 0.05 * np.stack([np.cos(a), np.sin(a)], axis=1)
    b = a + np.pi + rng.uniform(-0.3, 0.3, m)
    return Grasp(pts, np.stack([np.cos(b), np.sin(b)], axis=1), rng.uniform(0.3, 1.0, m))


def random_rows(
    n: int,
    *,
    contacts: int = 4,
    planar: bool = False,
    query: str = "Existence",
    seed: int = 0,
    cap: float = 10.0,
    method: str | None = None,
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """``n`` query rows about random grasps with ``contacts`` contacts: planar rigid grasps
    (:func:`random_planar`; wrenches ``(fx, fy, tz)`` ~ N(0, (1 N, 1 N, 0.05 N m))) or the
    spatial single-joint-finger hands of :func:`stability.examples.random_fingers` (wrenches
    :func:`~stability.examples.random_wrench`, commands of 1 N per finger).
    ``query``: ``"Existence"`` (that wrench) or ``"MaxDisturbance"`` (along it, up to
    ``cap``). Ids ``"rand-<seed>-<k>"``; the same arguments give the same rows."""
    if query not in ("Existence", "MaxDisturbance"):
        raise GraspError(f"query must be 'Existence' or 'MaxDisturbance', got {query!r}")
    if int(n) < 0 or int(contacts) < 1:
        raise GraspError(f"n must be >= 0 and contacts >= 1, got {n}, {contacts}")
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(int(n)):
        if planar:
            g, commands = random_planar(rng, contacts), None
            w = rng.normal(size=3) * np.array([1.0, 1.0, 0.05])
        else:
            g = random_fingers(rng, contacts)
            w, commands = random_wrench(rng), np.ones(contacts)
        q: Query = (
            Existence(wrench=w, commands=commands)
            if query == "Existence"
            else MaxDisturbance(direction=w / np.linalg.norm(w), commands=commands, cap=cap)
        )
        rows.append(encode_query(g, q, id=f"rand-{seed}-{k}", method=method, options=options))
    return rows


@dataclass(frozen=True)
class MapPlane:
    """The directions of a resistible-force map as disturbance wrenches on a grasp.

    ``directions`` unit forces at angles ``a_k = 2 pi k / directions`` [rad] from the
    plane's first axis towards its second, ``u_k = cos(a_k) e_1 + sin(a_k) e_2`` (the
    directions of :func:`stability.maps.resistible_forces`). ``rotation`` (spatial grasps
    only): the object frame's orientation in the frame whose axes ``plane`` names (3 x 3,
    object to world); the force ``u`` given in world axes is ``rotation^T u`` in the object
    frame. Each force acts through ``torque_point`` [m, object frame; default its origin]:
    a force ``f`` through ``p`` is the wrench ``(f, p x f)`` (planar: ``(f, p_x f_y - p_y
    f_x)``)."""

    plane: str = "xy"
    directions: int = 36
    torque_point: ArrayLike | None = None
    rotation: ArrayLike | None = None

    def wrenches(self, planar: bool) -> list[np.ndarray]:
        """One disturbance wrench per direction, for a planar (3-vector wrenches) or a
        spatial grasp (6-vectors); :class:`GraspError` for a plane, direction count or
        rotation that does not fit the grasp."""
        i, j = plane_axes(self.plane)
        if planar and self.plane != "xy":
            raise GraspError(f"a planar grasp has only the 'xy' force plane, got {self.plane!r}")
        if int(self.directions) < 1:
            raise GraspError(f"directions must be >= 1, got {self.directions}")
        if self.rotation is not None and planar:
            raise GraspError("rotation is for spatial grasps")
        rot = None if self.rotation is None else np.asarray(self.rotation, dtype=float)
        if rot is not None and rot.shape != (3, 3):
            raise GraspError(f"rotation must be a 3 x 3 matrix, got shape {rot.shape}")
        tp = self.torque_point
        out = []
        for a in np.linspace(0.0, 2 * np.pi, int(self.directions), endpoint=False):
            f = np.zeros(2 if planar else 3)
            f[i], f[j] = np.cos(a), np.sin(a)
            if rot is not None:
                f = rot.T @ f
            if planar:
                p = np.zeros(2) if tp is None else np.asarray(tp, float)
                out.append(np.r_[f, p[0] * f[1] - p[1] * f[0]])
            else:
                p = np.zeros(3) if tp is None else np.asarray(tp, float)
                out.append(np.r_[f, np.cross(p, f)])
        return out


def map_rows(
    grasp: Grasp,
    where: MapPlane | None = None,
    *,
    cap: float = 10.0,
    base: ArrayLike | None = None,
    commands: ArrayLike | None = None,
    preload: float | ArrayLike | None = None,
    id_prefix: str = "dir",
    method: str | None = None,
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One MaxDisturbance row per direction of a resistible-force map: the wrenches of
    ``where`` (default ``MapPlane()``: 36 directions in the xy plane through the object-frame
    origin), each searched up to ``cap`` on top of ``base`` (e.g. the object's weight), with
    ``commands`` / ``preload`` as in :class:`stability.queries.MaxDisturbance`. Ids
    ``"<id_prefix>-<k>"``."""
    where = MapPlane() if where is None else where
    rows = []
    for k, d in enumerate(where.wrenches(grasp.planar)):
        q = MaxDisturbance(direction=d, base=base, commands=commands, preload=preload, cap=cap)
        rows.append(encode_query(grasp, q, id=f"{id_prefix}-{k}", method=method, options=options))
    return rows
