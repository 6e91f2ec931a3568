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

* point, frame, friction: MuJoCo's contact of the copy, read as a touching one
  (:func:`ihm.grasp_from_mujoco`: its ``pos``, the frame turned so that ``n`` points into
  the object, ``friction[0]`` as MuJoCo mixes it for the pair; 0 for ``condim`` 1;
  ``condim > 3`` refused);
* force 0; the hand Jacobian as a touching contact of that body;
* law (``compliance="mujoco"``): MuJoCo's static law from first touch (``ContactGroup.law``
  with depth 0, :mod:`ihm.contact_law`);
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
from dataclasses import replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from .compliance import contact_rows
from .patches import ContactGroup, ContactLaw, merge_contacts

__all__ = ["engage_stiffness", "near_contacts", "widened"]


def engage_stiffness(data: mujoco.MjData, i: int) -> float:
    """The normal stiffness [N/m] at which MuJoCo contact ``i`` engages (module docstring),
    whatever its current penetration; ``data`` after ``mj_forward``."""
    rows = np.array([j for j in contact_rows(data, i) if data.efc_KBIP[j, 0] > 0])
    kbip = np.asarray(data.efc_KBIP)[rows]
    k, imp = kbip[:, 0], kbip[:, 2]
    c = np.asarray(data.efc_R)[rows] * imp / (1.0 - imp)
    imp0 = float(np.clip(data.contact[i].solimp[0], mujoco.mjMINIMP, mujoco.mjMAXIMP))
    return float(np.sum(k * imp0 / (c * (1.0 - imp0) / imp0)))


def widened(model: mujoco.MjModel, data: mujoco.MjData, in_obj: NDArray[np.bool_],
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


def near_contacts(read: list[ContactGroup], data: mujoco.MjData, near: float, stiffness: bool,
                  merge_tol: float) -> tuple[list[ContactGroup], list[float]]:  # fmt: skip
    """The near contacts (module docstring) and their gaps [m], from ``read``: the object's
    contacts of the widened copy (:func:`widened`), one :class:`ContactGroup` per MuJoCo
    contact of ``data`` (the copy's); their force set to 0, their stiffness [N/m] the
    engaging one when ``stiffness`` (else 0)."""
    found, gap_of = [], {}
    for g in read:
        i = g.ids[0]
        con = data.contact[i]
        gap = float(con.dist - (con.includemargin - near))
        if not 0.0 < gap < near:
            continue
        k = engage_stiffness(data, i) if stiffness else 0.0
        law = ContactLaw.of(con, 0.0) if stiffness else None
        h = replace(g, force_world=np.zeros(3), ids=[], stiffness=k, law=law)
        found.append(h)
        gap_of[id(h)] = gap
    groups = merge_contacts(found, merge_tol)
    return groups, [gap_of[id(g)] for g in groups]
