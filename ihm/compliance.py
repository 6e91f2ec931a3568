"""MuJoCo's compliance in physical units: contact normal stiffness, actuator (servo) and
passive spring stiffness, and the distance of each limit to the state.

**Contact stiffness.** MuJoCo's soft constraints (documentation, Computation, "Soft
constraints"; ``mj_makeImpedance``, ``getimpedance`` and ``mj_referenceConstraint`` in
``engine_core_constraint.c``) give each constraint row ``j`` of a contact

* ``r_j = efc_pos - efc_margin`` [m], ``r < 0`` inside the margin (penetration);
* ``(k_j, b_j, imp_j, imp'_j) = efc_KBIP[j]``: the reference stiffness ``k`` [1/s^2]
  (``1 / (dmax^2 timeconst^2 dampratio^2)`` for a positive ``solref``, ``-solref[0] /
  dmax^2`` for a negative one; 0 for the friction rows of an elliptic cone), damping
  ``b``, the impedance ``imp = d(r)`` of ``solimp`` and its slope ``imp' = d imp / d r``;
* ``R_j = efc_R[j] = c_j (1 - imp_j) / imp_j`` with ``c_j`` an inverse inertia that does
  not depend on ``r`` (``body_invweight0`` of the two bodies; for a pyramidal cone
  scaled by ``2 mu^2 (1 + mu^2) / impratio``, ``mu = friction[0]``) and ``D_j = 1 / R_j``;
* the reference acceleration ``aref_j = -b_j v_j - k_j imp_j r_j``.

Where the row's force is unclipped (a loaded contact) the solver's force is
``f_j = D_j (aref_j - J_j qacc)``; at rest (``v = 0, qacc = 0``) that is the static law
``f_j = -k_j imp_j r_j / R_j`` [N]. The normal force is the sum over the rows with
``k_j > 0``: the one row of a frictionless contact (``condim`` 1), the ``2 (condim - 1)``
edges of a pyramidal cone (each edge's normal component is its whole force), the first
row of an elliptic cone. With ``dR/dr = -R imp' / (imp (1 - imp))`` its stiffness is

    K = -d f_n / d r = sum_j (k_j / R_j) [imp_j + imp'_j r_j (2 - imp_j) / (1 - imp_j)]

[N/m], a spring ``c_n = max(0, p - K d_n)`` for a small separation ``d_n`` (``d r =
d_n``). With constant impedance (``solimp`` ``dmin = dmax``) it is ``k imp / R``: for a
frictionless or elliptic contact ``K = k imp^2 / ((1 - imp) A)``, ``A`` the sum of the
two bodies' ``body_invweight0[:, 0]``. A contact inside its ``gap`` (``r >= 0``: no force
yet) gets the slope at which it engages, ``k imp(0) / R(imp(0))``.
:func:`probe_contact_stiffness` measures the same slope by finite differences of
MuJoCo's inverse dynamics, independently of these formulas.

The static law is MuJoCo's own force only where nothing but the contacts' positions
decides it. With the ``noslip`` post-processor (``noslip_iterations > 0``) the normal
forces are those of the main solve, in which the object creeps (``qacc != 0``), and a
settled grasp's normal forces then differ from ``-k imp r / R`` (by a factor 0.43 to 1.76
on the Barrett and tendon scenes); the slope ``K`` is still the soft contact's, the
preload ``p`` is MuJoCo's force.

**Actuators** (:func:`actuator_stiffness`): MuJoCo's ``force = gain u + bias`` with ``gain =
g0 + g1 L + g2 Ldot`` (``gaintype`` affine; ``g0`` when fixed) and ``bias = b0 + b1 L + b2
Ldot`` (``biastype`` affine), ``L`` the actuator length and ``u`` the control (or the
activation). At rest ``K = -dF/dL = -(g1 u + b1)`` in the actuator's force per length
unit (N/m for a tendon or slide, N m/rad for a hinge): ``kp`` for a position servo (``b1 =
-kp``, whatever ``gain`` is), 0 for a motor, and 0 for an actuator saturated at its
``forcerange``. **Passive springs** (:func:`passive_stiffness`): ``-d qfrc_spring / d q``
over the given dofs by central differences (joint and tendon springs, polynomial ones
included). **Limits** (:func:`limit_gaps`, :func:`tendon_limit_gaps`): how far a joint
or tendon can move toward each limit before the limit's constraint engages
(``dist - margin``).

**What each MJCF element becomes** in :func:`ihm.grasp_from_mujoco`, as
``compliance="unit"`` / ``compliance="mujoco"`` (``K``: the column's stiffness, ``g``: its
stop gap; ``T``, ``e_k`` as in :mod:`ihm.handmodel`):

* contact (``condim`` 1 or 3, any cone): a unit spring ``k = 1`` / ``k = K`` above [N/m],
  summed over the MuJoCo contacts merged into it (:mod:`ihm.patches`).
* motor (fixed gain, no bias): nonbackdrivable, ``K = 0`` / the same.
* position servo or affine ``general``, unsaturated: nonbackdrivable (a constant force
  with ``servo="force"``) / a backdrivable spring, ``K = -dF/dL`` (``kp``).
* actuator saturated at its ``forcerange``: a constant force / the same, ``K = 0``.
* actuator named in ``backdrivable``: as asked / as asked, with ``K = -dF/dL``.
* muscle, DC motor or user actuator: as the kinds above / refused (:class:`GraspError`).
* joint spring (linear or polynomial): a constant torque, a motion it holds alone refused
  / backdrivable, ``K = K_kk |T^T e_k|^2``, also at zero torque, nothing refused.
* tendon spring: its joint torques, constant / the same, each joint's own stiffness (the
  coupling between joints is named in the warnings).
* loaded joint or tendon limit: a one-way stop, ``g = 0`` (on a ratcheted actuator's
  joint: that actuator's reaction) / the same.
* joint limit within ``stop_gap``: a stop, ``g = 0`` / a stop for each limit within
  ``max(stop_gap, near_limit)`` of engaging, ``g = dist - margin``.
* unloaded tendon limit: nothing / nothing.
* equality (connect, weld, joint, tendon): folded into ``T`` / the same.
* links' weight, applied forces: constant torques / the same.
* dry friction, damping, fluid forces: left out, warned / the same.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

__all__ = [
    "actuator_stiffness",
    "contact_depth",
    "contact_rows",
    "contact_stiffness",
    "impedance",
    "limit_gaps",
    "passive_stiffness",
    "probe_contact_stiffness",
    "row_stiffness",
    "static_normal_force",
    "tendon_limit_gaps",
]

_C = mujoco.mjtConstraint
_PYRAMIDAL = int(_C.mjCNSTR_CONTACT_PYRAMIDAL)
_ELLIPTIC = int(_C.mjCNSTR_CONTACT_ELLIPTIC)
_FRICTIONLESS = int(_C.mjCNSTR_CONTACT_FRICTIONLESS)


def contact_rows(data: mujoco.MjData, i: int) -> range:
    """The constraint rows of MuJoCo contact ``i``: 1 (frictionless), ``2 (condim - 1)``
    (pyramidal) or ``condim`` (elliptic) from ``efc_address``; :class:`GraspError` for a
    contact without rows (excluded, or beyond ``ncon``)."""
    if not 0 <= i < data.ncon:
        raise GraspError(f"contact {i} out of range: {data.ncon} contacts")
    con = data.contact[i]
    adr = int(con.efc_address)
    if adr < 0:
        raise GraspError(f"contact {i} has no constraint rows (excluded or inactive)")
    typ = int(data.efc_type[adr])
    if typ == _FRICTIONLESS:
        return range(adr, adr + 1)
    if typ == _PYRAMIDAL:
        return range(adr, adr + 2 * (int(con.dim) - 1))
    if typ == _ELLIPTIC:
        return range(adr, adr + int(con.dim))
    raise GraspError(f"contact {i}: row {adr} is not a contact row (type {typ})")


def row_stiffness(
    data: mujoco.MjData, rows: Iterable[int], engage_imp: float | None = None
) -> NDArray[np.float64]:
    """``-d f_j / d r_j`` per constraint row of the static law ``f_j = -k_j imp_j r_j / R_j``
    (module docstring) [N/m for contacts; N m/rad, N/m for joint and tendon limits].

    ``engage_imp``: for a row with ``r >= 0`` (no force yet), the impedance at ``r = 0``
    (``solimp[0]``); the row then gets the slope at which it engages, ``k imp0 / R(imp0)``.
    None leaves such rows at their current ``imp``, ``imp'``.
    """
    idx = np.fromiter(rows, dtype=np.int64)
    kbip = np.asarray(data.efc_KBIP)[idx]
    k, imp, imp_p = kbip[:, 0], kbip[:, 2], kbip[:, 3]
    R = np.asarray(data.efc_R)[idx]
    r = np.asarray(data.efc_pos)[idx] - np.asarray(data.efc_margin)[idx]
    out = (k / R) * (imp + imp_p * r * (2.0 - imp) / (1.0 - imp))
    if engage_imp is not None:
        free = r >= 0
        imp0 = float(np.clip(engage_imp, mujoco.mjMINIMP, mujoco.mjMAXIMP))
        c = R * imp / (1.0 - imp)  # R = c (1 - imp) / imp, c independent of r
        out[free] = k[free] * imp0 / (c[free] * (1.0 - imp0) / imp0)
    return out


def contact_depth(data: mujoco.MjData, i: int) -> float:
    """How far MuJoCo contact ``i`` presses into its margin, ``max(0, includemargin - dist)``
    [m] (``-r`` of its rows, module docstring)."""
    con = data.contact[i]
    return max(0.0, float(con.includemargin - con.dist))


def contact_stiffness(
    model: mujoco.MjModel, data: mujoco.MjData, contact_ids: Iterable[int]
) -> NDArray[np.float64]:
    """Normal stiffness ``K = -d c_n / d r`` [N/m] of each MuJoCo contact's soft constraint at
    the state (module docstring): the sum of :func:`row_stiffness` over its rows with
    ``k > 0`` (frictionless, pyramidal edges, the elliptic normal). ``data`` after
    ``mj_forward``; any ``condim`` and cone."""
    out = []
    for i in contact_ids:
        rows = [j for j in contact_rows(data, int(i)) if data.efc_KBIP[j, 0] > 0]
        solimp0 = float(data.contact[int(i)].solimp[0])
        out.append(float(row_stiffness(data, rows, engage_imp=solimp0).sum()))
    return np.array(out, dtype=float)


def impedance(solimp: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """MuJoCo's impedance ``d(r)`` of ``solimp = (d0, dwidth, width, midpoint, power)`` at the
    violations ``r`` [m] (``getimpedance`` in ``engine_core_constraint.c``): with ``x =
    |r| / width``, ``y = x^p / m^(p-1)`` for ``x <= m`` and ``1 - (1-x)^p / (1-m)^(p-1)``
    above, ``d = d0 + y (dwidth - d0)``, ``dwidth`` beyond the width, clamped to MuJoCo's
    ``[mjMINIMP, mjMAXIMP]``."""
    d0, dw, width, mid, power = (float(v) for v in solimp[:5])
    r = np.abs(np.asarray(r, dtype=float))
    if d0 == dw or width <= mujoco.mjMINVAL:
        imp = np.full_like(r, 0.5 * (d0 + dw) if width <= mujoco.mjMINVAL else d0)
    else:
        x = np.minimum(r / width, 1.0)
        if power == 1:
            y = x
        else:
            y = np.where(x <= mid, x**power / mid ** (power - 1),
                         1.0 - (1.0 - x) ** power / (1.0 - mid) ** (power - 1))  # fmt: skip
        imp = d0 + y * (dw - d0)
    return np.clip(imp, mujoco.mjMINIMP, mujoco.mjMAXIMP)


def static_normal_force(
    model: mujoco.MjModel, data: mujoco.MjData, contact_ids: Iterable[int]
) -> NDArray[np.float64]:
    """The static law's normal force ``sum_j max(0, -k_j imp_j r_j / R_j)`` [N] of each
    contact (rows with ``k > 0``): MuJoCo's normal force at rest without ``noslip``."""
    out = []
    for i in contact_ids:
        idx = np.array([j for j in contact_rows(data, int(i)) if data.efc_KBIP[j, 0] > 0])
        kbip = np.asarray(data.efc_KBIP)[idx]
        r = np.asarray(data.efc_pos)[idx] - np.asarray(data.efc_margin)[idx]
        f = -kbip[:, 0] * kbip[:, 2] * r / np.asarray(data.efc_R)[idx]
        out.append(float(np.maximum(f, 0.0).sum()))
    return np.array(out, dtype=float)


def _free_joint_qposadr(model: mujoco.MjModel, body: int) -> int:
    """``qpos`` address of the free joint that moves ``body`` (its own or an ancestor's)."""
    b = body
    while b > 0:
        for j in range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b])):
            if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE):
                return int(model.jnt_qposadr[j])
        b = int(model.body_parentid[b])
    raise GraspError(f"body {model.body(body).name!r} is not moved by a free joint")


def _subtree(model: mujoco.MjModel, root: int) -> NDArray[np.bool_]:
    """``(nbody,)`` mask of ``root`` and its descendants."""
    inside = np.zeros(model.nbody, dtype=bool)
    inside[root] = True
    for b in range(root + 1, model.nbody):
        inside[b] = inside[model.body_parentid[b]]
    return inside


def _normal_force_at(
    model: mujoco.MjModel,
    work: mujoco.MjData,
    geoms: tuple[int, int],
    near: NDArray[np.float64],
) -> tuple[float, float]:
    """Static normal force [N] and ``dist - includemargin`` [m] of the contact between
    ``geoms`` (same order) nearest ``near`` in ``work`` after ``mj_inverse``."""
    best, best_d = -1, np.inf
    for j in range(work.ncon):
        c = work.contact[j]
        if (int(c.geom1), int(c.geom2)) != geoms or c.efc_address < 0:
            continue
        dist = float(np.linalg.norm(c.pos - near))
        if dist < best_d:
            best, best_d = j, dist
    if best < 0:
        raise GraspError(f"probe: the contact between geoms {geoms} vanished; use a smaller step")
    f6 = np.zeros(6)
    mujoco.mj_contactForce(model, work, best, f6)
    c = work.contact[best]
    return float(f6[0]), float(c.dist - c.includemargin)


def probe_contact_stiffness(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    contact_ids: Iterable[int],
    *,
    step: float | None = None,
    object_body: str = "object",
) -> NDArray[np.float64]:
    """Normal stiffness [N/m] of each MuJoCo contact measured by finite differences,
    independently of :func:`contact_stiffness`'s formulas.

    For contact ``i`` with normal ``n`` (world, into ``object_body``): on a copy of
    ``data`` the object (its free joint) is translated by ``+-h n``, ``qvel = qacc = 0``
    and ``mj_inverse`` gives the static constraint forces that hold that configuration
    (``f = D aref`` at rest, projected on the cone, without ``noslip``). The contact with
    the same geom pair nearest the displaced point is read (``mj_contactForce``: its
    normal force ``c_n`` [N]; MuJoCo may reorder the contacts), and ``K = -(c_n(+h) -
    c_n(-h)) / (2 h)``. Translating the object along ``n`` separates the contact by
    ``h`` (``d_n = h``); the other contacts move too, but only this contact's own force
    is differenced. ``step``: ``h`` [m]; default 1 % of the contact's depth ``|dist -
    margin|``, within [1e-9, 1e-6] m. ``data`` is not changed.
    """
    obj = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, object_body)
    if obj < 0:
        raise GraspError(f"no body named {object_body!r}")
    adr = _free_joint_qposadr(model, obj)
    in_obj = _subtree(model, obj)
    work = copy.copy(data)
    out = []
    for i in contact_ids:
        con = data.contact[int(i)]
        geoms = (int(con.geom1), int(con.geom2))
        obj_first = bool(in_obj[model.geom_bodyid[geoms[0]]])
        if obj_first == bool(in_obj[model.geom_bodyid[geoms[1]]]):
            raise GraspError(f"contact {i} is not between {object_body!r} and another body")
        n = con.frame[:3] * (-1.0 if obj_first else 1.0)
        depth = abs(float(con.dist - con.includemargin))
        h = float(np.clip(0.01 * depth, 1e-9, 1e-6)) if step is None else float(step)
        f = []
        for s in (1.0, -1.0):
            work.qpos[:] = data.qpos
            work.qpos[adr : adr + 3] += s * h * n
            work.qvel[:] = 0.0
            work.qacc[:] = 0.0
            mujoco.mj_inverse(model, work)
            f.append(_normal_force_at(model, work, geoms, con.pos + 0.5 * s * h * n)[0])
        out.append(-(f[0] - f[1]) / (2.0 * h))
    return np.array(out, dtype=float)


def actuator_stiffness(model: mujoco.MjModel, data: mujoco.MjData) -> NDArray[np.float64]:
    """``K = -dF/dL`` per actuator at the state (module docstring) [N/m or N m/rad, the
    actuator's force per unit of its length]: ``-(g1 u + b1)`` for affine gain and bias
    (``u``: the control, clamped to ``ctrlrange``, or the last activation), 0 for an
    actuator whose force sits at a bound of its ``forcerange`` (saturated). Negative
    values (positive feedback) are returned as they are. :class:`GraspError` for a gain
    or bias type whose length dependence is not affine (muscle, DC motor, user)."""
    out = np.zeros(model.nu)
    fixed, affine = int(mujoco.mjtGain.mjGAIN_FIXED), int(mujoco.mjtGain.mjGAIN_AFFINE)
    none_b, affine_b = int(mujoco.mjtBias.mjBIAS_NONE), int(mujoco.mjtBias.mjBIAS_AFFINE)
    for a in range(model.nu):
        gt, bt = int(model.actuator_gaintype[a]), int(model.actuator_biastype[a])
        if gt not in (fixed, affine) or bt not in (none_b, affine_b):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"#{a}"
            raise GraspError(f"actuator {name}: gain type {gt} / bias type {bt} has no affine "
                             "length dependence; its stiffness is not modelled")  # fmt: skip
        force = float(data.actuator_force[a])
        lo, hi = model.actuator_forcerange[a]
        at_bound = min(abs(force - lo), abs(force - hi)) <= 1e-9 * (1 + abs(force))
        if model.actuator_forcelimited[a] and hi > lo and at_bound:
            continue  # saturated: a constant force
        u = float(data.ctrl[a])
        if model.actuator_ctrllimited[a]:
            u = float(np.clip(u, *model.actuator_ctrlrange[a]))
        if model.actuator_actadr[a] >= 0:
            u = float(data.act[model.actuator_actadr[a] + model.actuator_actnum[a] - 1])
        g1 = float(model.actuator_gainprm[a, 1]) if gt == affine else 0.0
        b1 = float(model.actuator_biasprm[a, 1]) if bt == affine_b else 0.0
        out[a] = -(g1 * u + b1) + 0.0  # + 0.0: no -0.0 for a motor
    return out


def passive_stiffness(
    model: mujoco.MjModel, data: mujoco.MjData, dofs: Iterable[int], step: float = 1e-6
) -> NDArray[np.float64]:
    """``K = -d qfrc_spring[dofs] / d q[dofs]`` (n x n) [N m/rad, N/m] of the passive joint
    and tendon springs at the state, by central differences of ``step`` on each dof (hinge
    or slide joints: one ``qpos`` per dof). Symmetric up to round-off; diagonal when only
    joint springs act (a tendon spring couples the dofs it spans)."""
    idx = np.fromiter(dofs, dtype=np.int64)
    jnt_of = {int(model.jnt_dofadr[j]): j for j in range(model.njnt)}
    hinge_slide = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    work = copy.copy(data)
    K = np.zeros((idx.size, idx.size))
    for c, dof in enumerate(idx):
        j = jnt_of.get(int(dof))
        if j is None or int(model.jnt_type[j]) not in hinge_slide:
            raise GraspError(f"dof {dof} is not a hinge or slide joint")
        col = []
        for s in (1.0, -1.0):
            work.qpos[:] = data.qpos
            work.qpos[model.jnt_qposadr[j]] += s * step
            work.qvel[:] = 0.0
            mujoco.mj_fwdPosition(model, work)
            mujoco.mj_passive(model, work)
            col.append(np.asarray(work.qfrc_spring)[idx].copy())
        K[:, c] = -(col[0] - col[1]) / (2.0 * step)
    return K


def limit_gaps(
    model: mujoco.MjModel, data: mujoco.MjData, joints: Iterable[int]
) -> NDArray[np.float64]:
    """``(n, 2)`` distances [rad or m] each joint can move toward its lower and upper limit
    before the limit's constraint engages: ``q - lo - margin`` and ``hi - q - margin``
    (``jnt_margin``), negative inside the margin; ``inf`` for an unlimited joint."""
    out = []
    for j in joints:
        if not model.jnt_limited[j]:
            out.append((np.inf, np.inf))
            continue
        q = float(data.qpos[model.jnt_qposadr[j]])
        lo, hi = model.jnt_range[j]
        mar = float(model.jnt_margin[j])
        out.append((q - lo - mar, hi - q - mar))
    return np.array(out, dtype=float).reshape(-1, 2)


def tendon_limit_gaps(
    model: mujoco.MjModel, data: mujoco.MjData, tendons: Iterable[int]
) -> NDArray[np.float64]:
    """``(n, 2)`` distances [m or rad] each tendon's length can move toward its lower and
    upper limit before the limit engages (``L - lo - margin``, ``hi - L - margin``);
    ``inf`` for an unlimited tendon."""
    out = []
    for t in tendons:
        if not model.tendon_limited[t]:
            out.append((np.inf, np.inf))
            continue
        L = float(data.ten_length[t])
        lo, hi = model.tendon_range[t]
        mar = float(model.tendon_margin[t])
        out.append((L - lo - mar, hi - L - mar))
    return np.array(out, dtype=float).reshape(-1, 2)
