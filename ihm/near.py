"""Near contacts: points where the hand does not touch the object yet.

:func:`ihm.grasp_from_mujoco` with ``near > 0`` [m] asks MuJoCo's own collision for them:
on a copy of the model every geom outside the object's subtree gets ``near`` more
``margin`` (and every ``<pair>`` with the object), so that MuJoCo reports, at the same
configuration, each point of a hand geom within ``near`` of the object beyond where its
contact engages. MuJoCo adds the two geoms' margins (checked on MuJoCo 4.0 in
``tests/ihm/test_near_contacts.py``), so a contact of the copy engages at its original
distance plus ``near`` and its gap is ``g = dist - (includemargin - near)`` [m]. Every
such contact with ``0 < g < near`` becomes a grasp contact (``g <= 0``: it touches, and
is read from the original state); one pair can give a near contact beside a touching one
(a link touching a face and lying just off an edge). Near contacts of one hand and object
body within ``merge_tol`` and 1e-3 rad are merged (:func:`ihm.patches.merge_contacts`,
the first one's gap kept).

* point, frame, friction: MuJoCo's contact of the copy (its ``pos``, the frame turned so
  that ``n`` points into the object, ``friction[0]`` as MuJoCo mixes it for the pair; 0 for
  ``condim`` 1; ``condim > 3`` refused as for touching contacts);
* force 0; the hand Jacobian as a touching contact of that body;
* stiffness (``compliance="mujoco"``): the slope at which the contact engages,
  ``K = sum_j k_j imp0 / R_j(imp0)`` over its rows with ``k_j > 0``, ``R_j(imp) = c_j (1 -
  imp) / imp`` with ``c_j = R_j imp_j / (1 - imp_j)`` read off the copy's rows and ``imp0 =
  solimp[0]`` (:func:`ihm.compliance.row_stiffness`'s slope of a row not yet engaged):
  ``k_j`` and ``c_j`` do not depend on the penetration, so this is the stiffness the
  contact has when it closes.

In a query (:func:`ihm.sim_maps.scene_disturbance`) a near contact is a spring with the
negative preload ``p = -K g`` [N]: it closes after the object has moved ``g`` towards the
hand (``c_n = max(0, p - K d_n)``).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

from .compliance import contact_rows
from .patches import ContactGroup, merge_contacts

__all__ = ["engage_stiffness", "near_contacts"]


def engage_stiffness(data: mujoco.MjData, i: int) -> float:
    """The normal stiffness [N/m] at which MuJoCo contact ``i`` engages (module docstring),
    whatever its current penetration; ``data`` after ``mj_forward``."""
    rows = np.array([j for j in contact_rows(data, i) if data.efc_KBIP[j, 0] > 0])
    kbip = np.asarray(data.efc_KBIP)[rows]
    k, imp = kbip[:, 0], kbip[:, 2]
    c = np.asarray(data.efc_R)[rows] * imp / (1.0 - imp)
    imp0 = float(np.clip(data.contact[i].solimp[0], mujoco.mjMINIMP, mujoco.mjMAXIMP))
    return float(np.sum(k * imp0 / (c * (1.0 - imp0) / imp0)))


def _widened(model: mujoco.MjModel, data: mujoco.MjData, in_obj: NDArray[np.bool_],
             near: float) -> tuple[mujoco.MjModel, mujoco.MjData]:  # fmt: skip
    """A copy of the model with ``near`` more margin on every hand geom and hand-object
    ``<pair>``, and its data at ``data``'s configuration after ``mj_forward``."""
    m2 = copy.copy(model)
    obj_geom = in_obj[model.geom_bodyid]
    m2.geom_margin[~obj_geom] += near
    for p in range(model.npair):
        if obj_geom[model.pair_geom1[p]] != obj_geom[model.pair_geom2[p]]:
            m2.pair_margin[p] += near
    d2 = mujoco.MjData(m2)
    d2.qpos[:] = data.qpos
    d2.mocap_pos[:], d2.mocap_quat[:] = data.mocap_pos, data.mocap_quat
    mujoco.mj_forward(m2, d2)
    return m2, d2


def near_contacts(model: mujoco.MjModel, data: mujoco.MjData, in_obj: NDArray[np.bool_],
                  near: float, stiffness: bool,
                  merge_tol: float) -> tuple[list[ContactGroup], list[float]]:  # fmt: skip
    """The near contacts of the state (module docstring) and their gaps [m]; their stiffness
    [N/m] when ``stiffness`` (else 0)."""
    from .contacts import contact_frame_force, object_contact_ids

    m2, d2 = _widened(model, data, in_obj, near)
    found, gap_of = [], {}
    for i, hand_geom, obj_first in object_contact_ids(d2, in_obj[model.geom_bodyid].tolist()):
        con = d2.contact[i]
        gap = float(con.dist - (con.includemargin - near))
        if not 0.0 < gap < near:
            continue
        obj_geom = int(con.geom1 if obj_first else con.geom2)
        if con.dim > 3:
            raise GraspError(
                f"near contact {model.geom(hand_geom).name or hand_geom} / "
                f"{model.geom(obj_geom).name or obj_geom} has condim {con.dim}: torsional or "
                "rolling friction is not in the point-contact model; use condim 1 or 3"
            )
        frame, _ = contact_frame_force(m2, d2, i, obj_first)
        bodies = (int(model.geom_bodyid[hand_geom]), int(model.geom_bodyid[obj_geom]))
        mu = 0.0 if con.dim == 1 else float(con.friction[0])
        k = engage_stiffness(d2, i) if stiffness else 0.0
        g = ContactGroup((int(hand_geom), obj_geom), bodies, [con.pos.copy()], frame,
                         np.zeros(3), mu, [], k)  # fmt: skip
        found.append(g)
        gap_of[id(g)] = gap
    groups = merge_contacts(found, merge_tol)
    return groups, [gap_of[id(g)] for g in groups]
