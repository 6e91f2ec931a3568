"""Near contacts: geom pairs of the hand and the object that do not touch yet.

:func:`ihm.grasp_from_mujoco` with ``near > 0`` [m] adds one grasp contact per pair
(geom of a body outside the object's subtree, geom of the object) that MuJoCo could collide
(``contype``/``conaffinity`` or a ``<pair>``, not ``<exclude>``-d), has no active contact at
the state, and whose distance (``mj_geomDistance``) is below ``near``:

* point: the middle of the two closest points; normal ``n``: from the hand geom's closest
  point towards the object's (into the object, as a touching contact's); tangents any
  right-handed completion;
* friction: MuJoCo's mixing of the pair (``mj_contactParam``): a ``<pair>``'s own
  ``friction[0]``, else the geom of higher ``priority``'s, else the larger of the two
  geoms' sliding friction; 0 where the mixed ``condim`` is 1 (``condim > 3`` is refused as
  for touching contacts);
* gap ``g`` [m]: the distance less the pair's ``margin - gap`` (MuJoCo's contact engages
  at ``dist = margin - gap``), at least 0;
* force 0; the hand Jacobian as a touching contact of that body;
* stiffness (``compliance="mujoco"``): the slope at which MuJoCo's contact of this pair
  would engage, ``k imp(0) / R(imp(0))`` (:mod:`ihm.compliance`, "a contact inside its
  gap"), read by :func:`ihm.compliance.contact_stiffness` off a copy of the model whose
  pair ``margin`` is raised just past the distance (``gap`` 0), so that MuJoCo itself
  creates the contact's rows at this configuration. That slope depends only on the pair's
  ``solref``/``solimp``, friction, cone and the bodies' ``body_invweight0``, not on where
  the contact will form, so it is the stiffness MuJoCo's contact has when it closes.

In a query (:func:`ihm.sim_maps.scene_disturbance`) a near contact is a spring with the
negative preload ``p = -k g`` [N]: it closes after the object has moved ``g`` towards the
hand (``c_n = max(0, p - k d_n)``).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

from .compliance import contact_stiffness
from .patches import ContactGroup

__all__ = ["near_contacts"]

_GAP_TINY = 1e-7  # [m] the raised margin's reach past the distance (stiffness read-off)


def _excluded(model: mujoco.MjModel, b1: int, b2: int) -> bool:
    sig = {int(s) for s in np.asarray(model.exclude_signature).tolist()}
    return ((b1 << 16) + b2) in sig or ((b2 << 16) + b1) in sig


def _explicit_pair(model: mujoco.MjModel, g1: int, g2: int) -> int:
    """The ``<pair>`` index of geoms ``g1, g2`` (either order), -1 if none."""
    for p in range(model.npair):
        a, b = int(model.pair_geom1[p]), int(model.pair_geom2[p])
        if {a, b} == {g1, g2}:
            return p
    return -1


def _mixed(model: mujoco.MjModel, hg: int, og: int, pair: int) -> tuple[int, float, float]:
    """``(condim, mu, margin - gap)`` of the pair as MuJoCo mixes them (module docstring)."""
    if pair >= 0:
        return (int(model.pair_dim[pair]), float(model.pair_friction[pair, 0]),
                float(model.pair_margin[pair] - model.pair_gap[pair]))  # fmt: skip
    margin = max(float(model.geom_margin[hg]), float(model.geom_margin[og]))
    gap = max(float(model.geom_gap[hg]), float(model.geom_gap[og]))
    ph, po = int(model.geom_priority[hg]), int(model.geom_priority[og])
    if ph != po:
        g = hg if ph > po else og
        return int(model.geom_condim[g]), float(model.geom_friction[g, 0]), margin - gap
    condim = max(int(model.geom_condim[hg]), int(model.geom_condim[og]))
    mu = max(float(model.geom_friction[hg, 0]), float(model.geom_friction[og, 0]))
    return condim, mu, margin - gap


def _frame(n: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows ``n, t1, t2``: a right-handed orthonormal frame with first row ``n``."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    return np.array([n, t1, np.cross(n, t1)])


def _engage_stiffness(model: mujoco.MjModel, data: mujoco.MjData, hg: int, og: int,
                      pair: int, dist: float) -> float:  # fmt: skip
    """MuJoCo's normal stiffness [N/m] of the pair's contact as it engages (module
    docstring): the pair's margin raised to ``dist + 1e-7`` m on a copy of the model."""
    m2 = copy.copy(model)
    reach = dist + _GAP_TINY
    if pair >= 0:
        m2.pair_margin[pair], m2.pair_gap[pair] = reach, 0.0
    else:
        for g in (hg, og):
            m2.geom_margin[g], m2.geom_gap[g] = reach, 0.0
    d2 = mujoco.MjData(m2)
    d2.qpos[:] = data.qpos
    d2.mocap_pos[:], d2.mocap_quat[:] = data.mocap_pos, data.mocap_quat
    mujoco.mj_forward(m2, d2)
    best, best_d = -1, np.inf
    for i in range(d2.ncon):
        c = d2.contact[i]
        if {int(c.geom1), int(c.geom2)} == {hg, og} and c.efc_address >= 0 and c.dist < best_d:
            best, best_d = i, float(c.dist)
    if best < 0:
        raise GraspError(
            f"near contact {model.geom(hg).name or hg} / {model.geom(og).name or og}: MuJoCo "
            f"made no contact of the pair with its margin raised to {reach:.3g} m"
        )
    return float(contact_stiffness(m2, d2, [best])[0])


def near_contacts(model: mujoco.MjModel, data: mujoco.MjData, in_obj: NDArray[np.bool_],
                  touching: set[tuple[int, int]], near: float,
                  stiffness: bool) -> tuple[list[ContactGroup], list[float]]:  # fmt: skip
    """The near contacts of the state (module docstring) and their gaps [m], in geom order:
    pairs (hand geom, object geom) within ``near`` [m] not in ``touching``; their stiffness
    [N/m] when ``stiffness`` (else 0)."""
    body = model.geom_bodyid
    obj_geoms = np.flatnonzero(in_obj[body])
    hand_geoms = np.flatnonzero(~in_obj[body])
    groups, gaps = [], []
    fromto = np.zeros(6)
    for hg in hand_geoms.tolist():
        for og in obj_geoms.tolist():
            if (hg, og) in touching or _excluded(model, int(body[hg]), int(body[og])):
                continue
            pair = _explicit_pair(model, hg, og)
            filt = (model.geom_contype[hg] & model.geom_conaffinity[og]) or (
                model.geom_contype[og] & model.geom_conaffinity[hg])  # fmt: skip
            if pair < 0 and not filt:
                continue
            dist = float(mujoco.mj_geomDistance(model, data, hg, og, near, fromto))
            if dist >= near:
                continue
            condim, mu, engage = _mixed(model, hg, og, pair)
            if condim > 3:
                raise GraspError(
                    f"near contact {model.geom(hg).name or hg} / {model.geom(og).name or og} "
                    f"has condim {condim}: torsional or rolling friction is not in the "
                    "point-contact model; use condim 1 or 3"
                )
            a, b = fromto[:3].copy(), fromto[3:].copy()
            seg = b - a
            if np.linalg.norm(seg) < 1e-9:
                continue  # touching within round-off yet not a MuJoCo contact: no normal
            frame = _frame(seg / np.linalg.norm(seg))
            k = _engage_stiffness(model, data, hg, og, pair, dist) if stiffness else 0.0
            groups.append(ContactGroup((hg, og), (int(body[hg]), int(body[og])),
                                       [0.5 * (a + b)], frame, np.zeros(3),
                                       0.0 if condim == 1 else mu, [], k))  # fmt: skip
            gaps.append(max(0.0, dist - engage))
    return groups, gaps
