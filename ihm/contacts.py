"""MuJoCo contact data to a spatial :class:`stability.Grasp`.

Conventions (DESIGN.md): everything is expressed in the *object frame*, the
frame of the MuJoCo body ``object_body`` (origin at the body origin, axes of
``data.xmat``). A contact frame is ``[n, t1, t2]`` with ``n`` pointing INTO the
object; contact forces ``c = (c_n, c_t1, c_t2)`` are forces of the hand on the
object in that frame [N]. ``G`` gives the wrench about the object-frame origin
(``G c + w = 0``); ``J`` maps the hand's independent joint velocities to the
velocity of the hand's contact point in contact frames, so that the relative
motion is ``d = G^T r - J q`` (``d_n > 0`` separates); ``R`` maps actuator
forces to joint torques, ``tau = R f``.

MuJoCo gives each contact a frame whose first row is the normal pointing from
``geom1`` to ``geom2``, and ``mj_contactForce`` the force of ``geom1`` on
``geom2`` in that frame. Where the object is ``geom1`` the frame is turned
about ``t2`` (``n, t1 -> -n, -t1``), which keeps it right-handed.

Coupled joints: active joint equalities ``q_1 = a0 + a1 q_2`` (MuJoCo
``<equality><joint polycoef="a0 a1 0 0 0"/>``) make ``q_1`` a dependent joint.
``J`` and ``R`` are expressed over the *independent* hand joints only:
``q_full = T q`` with ``T`` (nv_hand x l), ``J = J_full T``, ``R = T^T R_full``.
The equality's constraint force ``lambda (e_1 - a1 e_2)`` is annihilated by
``T^T``, so hand equilibrium reads ``J^T c = R f`` over the independent joints.
This is how the Barrett hand's rigidly coupled proximal/distal joints and
mirrored spread joints reach the thesis' model (all finger torque on the
proximal joint). Nonlinear couplings are refused.

Duplicate contacts: MuJoCo may report the same touch point more than once for
one geom pair (e.g. box-box at a vertex). Contacts of the same geom pair
whose points lie within ``merge_tol`` [m] and whose normals agree within
``1e-3`` rad are merged into one: the point is their mean, the frame the
first one's, the force their sum. Distinct points of a line or face contact
(capsule on a face: two points) stay distinct, as in the thesis' point-contact
model.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import Grasp, GraspError

__all__ = [
    "SceneGrasp",
    "body_subtree",
    "contact_frame_force",
    "grasp_from_mujoco",
    "hand_coordinates",
    "transmission",
]

_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


class SceneGrasp(Grasp):
    """A :class:`stability.Grasp` read off a MuJoCo state, with what MuJoCo reported.

    Extra attributes (all in the object frame, SI units):

    forces : (m, 3) contact forces MuJoCo computed, ``(c_n, c_t1, c_t2)`` [N]
    commands : (a,) actuator forces at this state (``data.actuator_force``)
        [N m for joint actuators, N for tendons]
    gravity_wrench : (6,) gravity's wrench on the object about the object
        origin ``(f, torque)`` [N, N m]
    joint_names : names of the ``l`` independent hand joints (columns of ``J``)
    actuator_names : names of the ``a`` actuators (columns of ``R``)
    T : (nv_hand, l) independent-to-full hand joint map (coupled joints)
    hand_dofs : (nv_hand,) MuJoCo dof indices of the hand
    hand_bodies : (m,) MuJoCo body id of the hand link at each contact
    hand_geoms, object_geoms : (m,) MuJoCo geom ids at each contact
    contact_ids : per contact, the MuJoCo contact indices merged into it
    object_pos, object_mat : object frame in world coordinates
    """

    forces: NDArray[np.float64]
    commands: NDArray[np.float64]
    gravity_wrench: NDArray[np.float64]
    joint_names: list[str]
    actuator_names: list[str]
    T: NDArray[np.float64]
    hand_dofs: NDArray[np.int64]
    hand_bodies: NDArray[np.int64]
    hand_geoms: NDArray[np.int64]
    object_geoms: NDArray[np.int64]
    contact_ids: list[list[int]]
    object_pos: NDArray[np.float64]
    object_mat: NDArray[np.float64]

    def points_world(self) -> NDArray[np.float64]:
        """Contact points in world coordinates, (m, 3) [m]."""
        return self.object_pos + self.points @ self.object_mat.T

    def frames_world(self) -> NDArray[np.float64]:
        """Contact frames in world coordinates, (m, 3, 3), rows ``n, t1, t2``."""
        frames = np.concatenate([self.normals[:, None, :], self.tangents], axis=1)
        return frames @ self.object_mat.T

    def equilibrium_residuals(self) -> dict[str, float]:
        """How well MuJoCo's contact forces satisfy the model's statics [N, N m].

        ``object``: ``max |G c + w_gravity|`` (object equilibrium, no other load);
        ``hand``: ``max |J^T c - R f|`` with ``f`` the actuator forces (hand
        equilibrium over the independent joints; hand links are gravity-compensated).
        """
        c = self.forces.reshape(-1)
        return {
            "object": float(np.abs(self.G @ c + self.gravity_wrench).max()),
            "hand": float(np.abs(self.J.T @ c - self.R @ self.commands).max()),
        }

    def forces_world(self) -> NDArray[np.float64]:
        """Forces of the hand on the object in world coordinates, (m, 3) [N]."""
        return np.einsum("mk,mkj->mj", self.forces, self.frames_world())


def _body_id(model: mujoco.MjModel, name: str) -> int:
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if i < 0:
        bodies = [model.body(b).name for b in range(1, model.nbody)]
        raise GraspError(f"no body named {name!r} in the model; bodies: {', '.join(bodies)}")
    return i


def body_subtree(model: mujoco.MjModel, root: int) -> NDArray[np.bool_]:
    """``(nbody,)`` mask of ``root`` and its descendants (the object and what it carries)."""
    inside = np.zeros(model.nbody, dtype=bool)
    inside[root] = True
    for b in range(root + 1, model.nbody):  # parents precede children
        inside[b] = inside[model.body_parentid[b]]
    return inside


def hand_coordinates(
    model: mujoco.MjModel, data: mujoco.MjData, object_body: str = "object"
) -> tuple[NDArray[np.int64], NDArray[np.float64], list[str]]:
    """The hand's dofs and its independent coordinates.

    Returns ``(hand_dofs, T, names)``: the MuJoCo dof indices of every hinge or
    slide joint outside the object's subtree, the map ``T`` (len(hand_dofs) x l)
    with ``qvel[hand_dofs] = T qdot`` under the active linear joint
    equalities, and the names of the ``l`` independent joints.
    """
    obj = _body_id(model, object_body)
    in_obj = body_subtree(model, obj)
    joints = [
        j
        for j in range(model.njnt)
        if not in_obj[model.jnt_bodyid[j]] and int(model.jnt_type[j]) in _HINGE_SLIDE
    ]
    others = [j for j in range(model.njnt) if not in_obj[model.jnt_bodyid[j]] and j not in joints]
    if others:
        raise GraspError(
            f"hand joints must be hinges or slides; got {[model.joint(j).name for j in others]}"
        )
    # dependent joint -> (independent joint or -1 for a locked joint, ratio)
    depends: dict[int, tuple[int, float]] = {}
    active = data.eq_active
    for e in range(model.neq):
        if int(model.eq_type[e]) != int(mujoco.mjtEq.mjEQ_JOINT) or not active[e]:
            continue
        j1, j2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
        if j1 not in joints:
            continue
        poly = model.eq_data[e, :5]
        if np.any(np.abs(poly[2:]) > 1e-12):
            raise GraspError(
                f"joint equality {model.equality(e).name or e} is nonlinear "
                f"(polycoef {poly.tolist()}); only q1 = a0 + a1 q2 is supported"
            )
        depends[j1] = (j2, float(poly[1]) if j2 >= 0 else 0.0)
    indep = [j for j in joints if j not in depends]

    def resolve(j: int, depth: int = 0) -> dict[int, float]:
        if depth > len(joints):
            raise GraspError("cyclic joint equalities")
        if j not in depends:
            return {j: 1.0}
        j2, a = depends[j]
        if j2 < 0 or a == 0.0:
            return {}
        return {k: a * v for k, v in resolve(j2, depth + 1).items()}

    col = {j: c for c, j in enumerate(indep)}
    T = np.zeros((len(joints), len(indep)))
    for r, j in enumerate(joints):
        for k, v in resolve(j).items():
            if k not in col:
                raise GraspError(f"joint {model.joint(j).name} coupled to a non-hand joint")
            T[r, col[k]] += v
    dofs = np.array([model.jnt_dofadr[j] for j in joints], dtype=np.int64)
    return dofs, T, [model.joint(j).name for j in indep]


def transmission(model: mujoco.MjModel, data: mujoco.MjData) -> NDArray[np.float64]:
    """Dense actuator moment matrix, (nu, nv): ``qfrc_actuator = moment^T force``.

    For a joint actuator the row is ``gear`` at its dof; for a fixed-tendon
    actuator ``gear`` times the tendon coefficients [m]. ``data.actuator_moment``
    is stored sparse in MuJoCo >= 3; this expands it.
    """
    dense = np.zeros((model.nu, model.nv))
    if model.nu:
        mujoco.mju_sparse2dense(
            dense, data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind
        )
    return dense


def contact_frame_force(
    model: mujoco.MjModel, data: mujoco.MjData, i: int, object_is_geom1: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Contact ``i``'s frame (rows n, t1, t2, with n pointing into the object) and the force of
    the hand on the object in it (``mj_contactForce``); ``object_is_geom1``: the object is
    the contact's first geom."""
    con = data.contact[i]
    frame = con.frame.reshape(3, 3).copy()
    f6 = np.zeros(6)
    mujoco.mj_contactForce(model, data, i, f6)
    f_on_geom2 = frame.T @ f6[:3]  # world
    if object_is_geom1:
        frame[0] *= -1.0
        frame[1] *= -1.0
        f_on_obj = -f_on_geom2
    else:
        f_on_obj = f_on_geom2
    return frame, frame @ f_on_obj


def grasp_from_mujoco(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    object_body: str = "object",
    *,
    merge_tol: float = 1e-4,
) -> SceneGrasp:
    """Read the grasp of ``object_body`` off a MuJoCo state (after ``mj_forward``).

    One contact per active MuJoCo contact between the object's subtree and any
    other body (the hand; a static body counts as a fixed finger with zero
    Jacobian rows), duplicates merged (see the module docstring). Friction is
    MuJoCo's sliding friction of the contact (``contact.friction[0]``; 0 for a
    frictionless ``condim=1`` contact; ``condim`` 4 or 6, with torsional or
    rolling friction, is refused).

    Raises
    ------
    GraspError
        No body ``object_body``; no active contact between it and the hand; a
        contact with torsional/rolling friction (condim > 3);
        a hand joint that is not a hinge or slide; a nonlinear joint coupling.
    """
    obj = _body_id(model, object_body)
    in_obj = body_subtree(model, obj)
    hand_dofs, T, joint_names = hand_coordinates(model, data, object_body)
    x_o = data.xpos[obj].copy()
    R_o = data.xmat[obj].reshape(3, 3).copy()

    groups: list[dict[str, Any]] = []
    for i in range(data.ncon):
        con = data.contact[i]
        if con.exclude != 0 or con.efc_address < 0:
            continue
        b1, b2 = model.geom_bodyid[con.geom1], model.geom_bodyid[con.geom2]
        if in_obj[b1] == in_obj[b2]:
            continue  # not between object and hand
        if con.dim > 3:
            raise GraspError(
                f"contact {i} ({model.geom(con.geom1).name or con.geom1} / "
                f"{model.geom(con.geom2).name or con.geom2}) has condim {con.dim}: torsional or "
                "rolling friction is not in the point-contact model; use condim 1 or 3"
            )
        obj_first = bool(in_obj[b1])
        frame, force = contact_frame_force(model, data, i, obj_first)
        hand_geom, obj_geom = (con.geom2, con.geom1) if obj_first else (con.geom1, con.geom2)
        pos = con.pos.copy()
        for g in groups:
            if (
                g["pair"] == (hand_geom, obj_geom)
                and np.linalg.norm(g["pos"][0] - pos) <= merge_tol
                and g["frame"][0] @ frame[0] >= np.cos(1e-3)
            ):
                g["pos"].append(pos)
                g["force_world"] += frame.T @ force
                g["ids"].append(i)
                break
        else:
            groups.append(
                {
                    "pair": (hand_geom, obj_geom),
                    "pos": [pos],
                    "frame": frame,
                    "force_world": frame.T @ force,
                    "mu": 0.0 if con.dim == 1 else float(con.friction[0]),
                    "ids": [i],
                }
            )
    if not groups:
        raise GraspError(
            f"no active contact between body {object_body!r} and the hand "
            f"({data.ncon} MuJoCo contacts in all); settle the grasp first"
        )

    m = len(groups)
    pts_w = np.array([np.mean(g["pos"], axis=0) for g in groups])
    frames_w = np.array([g["frame"] for g in groups])  # (m, 3, 3) rows n, t1, t2
    forces = np.einsum("mkj,mj->mk", frames_w, np.array([g["force_world"] for g in groups]))
    hand_geoms = np.array([g["pair"][0] for g in groups], dtype=np.int64)
    hand_bodies = model.geom_bodyid[hand_geoms].astype(np.int64)

    J = np.zeros((3 * m, T.shape[1]))
    jacp = np.zeros((3, model.nv))
    for k in range(m):
        mujoco.mj_jac(model, data, jacp, None, pts_w[k], int(hand_bodies[k]))
        J[3 * k : 3 * k + 3] = frames_w[k] @ jacp[:, hand_dofs] @ T
    R = T.T @ transmission(model, data)[:, hand_dofs].T

    pts_o = (pts_w - x_o) @ R_o
    frames_o = frames_w @ R_o  # each row v -> R_o^T v
    grasp = SceneGrasp(
        points=pts_o,
        normals=frames_o[:, 0],
        mu=[g["mu"] for g in groups],
        tangents=frames_o[:, 1:],
        J=J,
        R=R,
    )
    mass = model.body_subtreemass[obj]
    f_g = mass * model.opt.gravity
    tau_g = np.cross(data.subtree_com[obj] - x_o, f_g)
    grasp.forces = forces
    grasp.commands = data.actuator_force.copy()
    grasp.gravity_wrench = np.concatenate([R_o.T @ f_g, R_o.T @ tau_g])
    grasp.joint_names = joint_names
    grasp.actuator_names = [model.actuator(a).name for a in range(model.nu)]
    grasp.T = T
    grasp.hand_dofs = hand_dofs
    grasp.hand_bodies = hand_bodies
    grasp.hand_geoms = hand_geoms
    grasp.object_geoms = np.array([g["pair"][1] for g in groups], dtype=np.int64)
    grasp.contact_ids = [g["ids"] for g in groups]
    grasp.object_pos = x_o
    grasp.object_mat = R_o
    return grasp
