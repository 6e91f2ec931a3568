"""Linearised grasp compliance (thesis sec. "Grasp model", after Cutkosky and Bicchi).

At a MuJoCo state, :func:`linearize` builds the grasp's compliance and the two maps that
predict one step ahead how the object and the contact forces respond to a change of the
servo setpoints ``dq`` (thesis eq. "linearization")::

    [c; u]_{t+1} ~ [c; u]_t + [E; F] dq

Conventions (docs/design.md, with the axes stated here)
-------------------------------------------------------
* Contact ``i`` has the frame ``[n, t1, t2]`` (rows, world coordinates), ``n`` pointing INTO
  the object; ``c_i = (c_n, c_t1, c_t2)`` is the force of the hand on the object in it [N].
  Where contacts have torsional friction (MuJoCo ``condim`` 4, the four-finger env), each
  contact has a fourth component, the moment ``c_tau`` of the hand on the object about
  ``n`` [N m] (a soft-finger contact), with its column ``(0, n)`` in ``G`` and the hand
  link's rotation about ``n`` in ``J``: ``nc = 4`` components per contact, else 3.
* ``G`` (6 x 3m) gives the wrench on the object about the object body's origin, in WORLD
  axes: ``w = G c`` with ``w = (f, torque)`` [N, N m]. (``ihm.grasp_from_mujoco`` expresses
  the same ``G`` in object axes; the shield's box and tilt limits are in world axes.)
* ``J`` (3m x l) maps the ``l`` servo setpoints [rad] to the motion of the hand's contact
  point in the contact frames [m]; for the position servos of the four-finger hand a
  setpoint is the joint angle the servo pulls toward, so ``J`` is the hand Jacobian.
* The relative motion at the contacts is ``d = G^T du - J dq`` (``d_n > 0`` separates);
  ``u = (p, theta)``: the object origin's position [m] and a small rotation vector [rad],
  world axes.

Compliance
----------
``C = C_contact + J C_joint J^T`` (3m x 3m), ``K = C^{-1}`` [N/m] (thesis eqs. "motion" to
"K_matrix"), with

* ``C_joint = diag(1 / kp)`` [rad/(N m)]: the servo's proportional gain (the four-finger
  hand's series-elastic coupling, ``force = kp (ctrl - q)``); joint springs
  (``jnt_stiffness``) must be 0.
* ``C_contact``: what MuJoCo's soft contact does, read off the solver's own data. MuJoCo
  solves each contact row for the force ``f = -(a - a_ref) / R`` with ``a_ref = -B v -
  K_s I r`` (``efc_KBIP`` = ``K_s, B, I``; ``efc_R`` = ``R``; ``r`` the penetration, ``v`` the
  row's velocity). At rest (``a = 0, v = 0``) the normal row is a linear spring:
  ``c_n = (K_s I / R_n) (-r)``, compliance ``R_n / (K_s I)`` [m/N]. With the skin's
  ``solref = (0.01 s, 1)`` and constant impedance ``I = 0.9`` this is ``K_s =
  1 / (0.9^2 0.01^2) = 12,346 s^-2`` and ``R_n = (1 - I) / I * A`` (``A`` MuJoCo's diagonal
  approximation of the contact's inverse inertia): 2,313 N/m for a fingertip on the
  70 mm sphere. The tangential rows have no position term (``a_ref = -B v``): under a
  constant tangential force MuJoCo's contact creeps at ``v = R_t c_t / B`` instead of
  springing back. Over the prediction horizon ``h`` (the policy period) that is the
  compliance ``R_t h / B`` [m/N] (about 1.1e-5 m/N at ``h`` = 0.05 s, impratio 100).
  That is the converged contact model; the env's PGS stops at tolerance 1e-4 and leaves a
  residual in the creep of up to about 1e-4 m/s (median 2e-5, beside creeps of 7e-5 m/s
  median at rest; tested).
  The torsional row creeps the same way: ``R_tau h / B`` [rad/(N m)] (0.43 here). Leaving
  it out (a point contact) doubles the prediction error on the four-finger grasps: the
  fingertip's twist about the contact normal is the abduction joint's rotation, and the
  torsional friction couples it to the object. Among horizons from 0.0125 to 0.1 s, the
  policy period ``h = 0.05 s`` predicts MuJoCo's step best.

Object motion and contact forces (Bicchi)
-----------------------------------------
With the external wrench constant, equilibrium ``G dc = 0`` and ``dc = K (J dq - G^T du)``
give ::

    F = (G K G^T)^+ G K J                    du = F dq      (thesis eq. F_matrix)
    E = K (J - G^T F)                        dc = E dq      (thesis eq. E_matrix)

The thesis prints ``(G K G)^{-1}`` (read ``G K G^T``) and ``E = (I - G^T (G K G^T)^{-1} G) K
J``; the form above is the one that satisfies ``G E = 0`` (``E = (I - K G^T (G K G^T)^{-1}
G) K J``). ``^+`` is the pseudo-inverse: an object direction that no contact stiffness
holds (two point contacts: the spin about the line through them) gets no motion.

What the linearisation leaves out (its accuracy is measured in tests/shields/test_compliance.py and
``python -m train.bench shield accuracy``): contacts that roll or slide, contacts that make or
break, the change of the contact frames with the motion (Cutkosky's geometric stiffness), the
servo's force limit (a saturated servo does not follow its setpoint), the dynamics within the
step,
and contacts between fingers. Palm and floor contacts are fixed bodies (zero ``J`` rows).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from ihm.contacts import body_subtree, object_contact_ids

__all__ = ["GraspLinearization", "ShieldError", "linearize"]


_SKEW_AT = [1, 2, 3, 5, 6, 7]
_SKEW_FROM = [2, 1, 2, 0, 1, 0]
_SKEW_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, -1.0, 1.0])


class ShieldError(ValueError):
    """Bad input to the grasp shield or its model (unsupported model, bad option, no object)."""


@dataclass
class GraspLinearization:
    """The linearised grasp at one MuJoCo state (module docstring for conventions).

    Attributes (``m`` contacts, ``l`` servos)
    ----------------------------------------
    contact_ids : (m,) MuJoCo contact index of each contact
    bodies : (m,) MuJoCo body id of the hand side (a static body: the palm or floor)
    links : (m,) names of those bodies
    points : (m, 3) contact points, world [m]
    frames : (m, 3, 3) rows ``n, t1, t2``, world, ``n`` into the object
    forces : (m, nc) ``c = (c_n, c_t1, c_t2[, c_tau])`` MuJoCo computed [N, N m]
    mu : (m,) sliding friction coefficients
    mu_torsion : (m,) torsional friction coefficients [m] (0: none)
    G : (6, nc m) grasp map, world axes, about ``object_pos``
    J : (nc m, l) setpoints [rad] -> hand contact-point motion in contact frames [m] (and
        the hand link's rotation about the normal [rad])
    C_contact : (nc m,) diagonal contact compliance [m/N] (normal, t1, t2 per contact; the
        torsional one [rad/(N m)])
    C_joint : (l,) servo compliance ``1 / kp`` [rad/(N m)]
    K : (nc m, nc m) grasp stiffness ``(C_contact + J C_joint J^T)^{-1}`` [N/m]
    F : (6, l) object motion per setpoint change, ``du = F dq`` [m/rad, rad/rad]
    E : (nc m, l) contact-force change per setpoint change, ``dc = E dq`` [N/rad]
    object_pos : (3,) object body origin, world [m]
    object_mat : (3, 3) object body orientation (columns: its axes in world)
    horizon : prediction horizon of the tangential creep compliance [s]
    """

    contact_ids: NDArray[np.int64]
    bodies: NDArray[np.int64]
    links: list[str]
    points: NDArray[np.float64]
    frames: NDArray[np.float64]
    forces: NDArray[np.float64]
    mu: NDArray[np.float64]
    mu_torsion: NDArray[np.float64]
    G: NDArray[np.float64]
    J: NDArray[np.float64]
    C_contact: NDArray[np.float64]
    C_joint: NDArray[np.float64]
    K: NDArray[np.float64]
    F: NDArray[np.float64]
    E: NDArray[np.float64]
    object_pos: NDArray[np.float64]
    object_mat: NDArray[np.float64]
    horizon: float

    @property
    def m(self) -> int:
        """Number of contacts."""
        return len(self.contact_ids)

    @property
    def nc(self) -> int:
        """Components per contact: 3 (force) or 4 (force and torsional moment)."""
        return self.forces.shape[1]

    def predict(self, dq: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(c + E dq, F dq)``: predicted contact forces (m, nc) [N] and object motion ``du``
        (6,) [m, rad] for the setpoint change ``dq`` (l,) [rad]."""
        dq = np.asarray(dq, dtype=np.float64)
        return self.forces + (self.E @ dq).reshape(self.m, -1), self.F @ dq


class _HandInfo:
    """Per-model data of :func:`linearize`, computed once per model."""

    def __init__(self, model: mujoco.MjModel, object_body: str) -> None:
        obj = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, object_body)
        if obj < 0:
            raise ShieldError(f"no body named {object_body!r} in the model")
        if model.opt.cone != mujoco.mjtCone.mjCONE_ELLIPTIC:
            raise ShieldError("the compliance model reads elliptic-cone contact rows; set cone")
        self.obj = obj
        in_obj = body_subtree(model, obj).tolist()
        dofs, kp = [], []
        for a in range(model.nu):
            if int(model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT):
                raise ShieldError(f"actuator {model.actuator(a).name}: only joint servos")
            j = int(model.actuator_trnid[a, 0])
            gain, bias = model.actuator_gainprm[a], model.actuator_biasprm[a]
            if (
                model.actuator_gear[a, 0] != 1.0
                or gain[0] <= 0
                or not np.isclose(bias[1], -gain[0])
                or int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_HINGE)
            ):
                raise ShieldError(
                    f"actuator {model.actuator(a).name}: only position servos (gear 1, "
                    "force = kp (ctrl - q)) on hinges"
                )
            if model.jnt_stiffness[j] != 0.0:
                raise ShieldError(f"joint {model.joint(j).name} has a spring; not modelled")
            dofs.append(int(model.jnt_dofadr[j]))
            kp.append(float(gain[0]))
        self.dofs = np.array(dofs, dtype=np.int64)
        self.C_joint = 1.0 / np.array(kp)
        self.names = [model.body(b).name for b in range(model.nbody)]
        self.nbody = model.nbody
        self.geom_body = model.geom_bodyid.tolist()
        self.geom_in_obj = [in_obj[b] for b in self.geom_body]
        self.static = (model.body_weldid == 0).tolist()


_INFO: dict[tuple[int, str], _HandInfo] = {}


def _info(model: mujoco.MjModel, object_body: str) -> _HandInfo:
    key = (id(model), object_body)
    info = _INFO.get(key)
    if info is not None and (len(info.geom_body) != model.ngeom or info.nbody != model.nbody):
        info = None  # a new model at a freed model's address
    if info is None:
        if len(_INFO) > 64:
            _INFO.clear()
        info = _INFO[key] = _HandInfo(model, object_body)
    return info


def contact_compliance(
    data: mujoco.MjData, efc_address: int, horizon: float
) -> tuple[float, float]:
    """``(normal, tangential)`` compliance [m/N] of the contact whose first constraint row is
    ``efc_address``: ``R_n / (K_s I)`` and ``R_t horizon / B`` (module docstring)."""
    k_s, _, imp, _ = data.efc_KBIP[efc_address]
    b = data.efc_KBIP[efc_address + 1, 1]
    return float(data.efc_R[efc_address] / (k_s * imp)), float(
        data.efc_R[efc_address + 1] * horizon / b
    )


def linearize(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    object_body: str = "object",
    *,
    horizon: float = 0.05,
) -> GraspLinearization:
    """The linearised grasp (``G, J, K, F, E``) at the current state of ``data``.

    Every active contact between the object (``object_body``'s subtree) and another body
    counts; contacts with a static body get zero ``J`` rows. Call after ``mj_forward`` or
    ``mj_step`` (contacts and constraint rows of the current state). ``horizon`` [s] sets
    the tangential creep compliance (the policy period).

    Returns a :class:`GraspLinearization` with ``m = 0`` (empty maps) when the object
    touches nothing.

    Raises
    ------
    ShieldError
        No such body; a pyramidal friction cone; actuators other than position servos on
        hinges; a frictionless contact; ``horizon <= 0``.
    """
    if not horizon > 0 or not np.isfinite(horizon):
        raise ShieldError(f"horizon must be a finite number > 0 [s], got {horizon!r}")
    info = _info(model, object_body)
    obj = info.obj
    x_o = data.xpos[obj].copy()
    R_o = data.xmat[obj].reshape(3, 3).copy()
    ids, bodies, sign, dims = _object_contacts(data, info)
    m = len(ids)
    if m == 0:
        return _no_contacts(info, x_o, R_o, horizon)
    if min(dims) < 3 or max(dims) > 4:
        raise ShieldError(
            "object contacts must have condim 3 (point contact with friction) or 4 (with "
            f"torsional friction); got {sorted(set(dims))}"
        )
    nc = max(dims)
    con = data.contact
    idx = np.array(ids)
    s = np.array(sign)
    frames = con.frame[idx].reshape(m, 3, 3)
    frames[:, :2] *= s[:, None, None]
    tors = np.array(dims) == 4
    forces, C_contact = _contact_rows(data, con.efc_address[idx], s, tors, nc, horizon)
    points = con.pos[idx]
    fr = con.friction[idx]
    G = _grasp_map(frames, points, x_o, nc)
    J = _hand_jacobian(model, data, info, bodies, points, frames, nc)
    K, F, E = _object_response(G, J, C_contact, info.C_joint)
    return GraspLinearization(
        contact_ids=idx.astype(np.int64),
        bodies=np.array(bodies, dtype=np.int64),
        links=[info.names[b] for b in bodies],
        points=points,
        frames=frames,
        forces=forces,
        mu=fr[:, 0],
        mu_torsion=np.where(tors, fr[:, 2], 0.0) if nc == 4 else np.zeros(m),
        G=G,
        J=J,
        C_contact=C_contact,
        C_joint=info.C_joint.copy(),
        K=K,
        F=F,
        E=E,
        object_pos=x_o,
        object_mat=R_o,
        horizon=float(horizon),
    )


def _object_contacts(
    data: mujoco.MjData, info: _HandInfo
) -> tuple[list[int], list[int], list[float], list[int]]:
    """The object's active contacts: their MuJoCo contact indices, the hand-side bodies, the
    frame sign (-1 where the object is geom1: ``n`` and ``t1`` flip to point into the
    object) and the contact dimensions (``condim``)."""
    ids, bodies, sign, dims = [], [], [], []
    dim = data.contact.dim.tolist()
    for i, other, o1 in object_contact_ids(data, info.geom_in_obj):
        ids.append(i)
        bodies.append(info.geom_body[other])
        sign.append(-1.0 if o1 else 1.0)  # object is geom1: flip n and t1
        dims.append(dim[i])
    return ids, bodies, sign, dims


def _no_contacts(
    info: _HandInfo, x_o: NDArray[np.float64], R_o: NDArray[np.float64], horizon: float
) -> GraspLinearization:
    """The linearisation of an object that touches nothing: ``m = 0``, empty maps."""
    n_servo = len(info.dofs)
    z = np.zeros
    return GraspLinearization(
        np.zeros(0, np.int64), np.zeros(0, np.int64), [], z((0, 3)), z((0, 3, 3)),
        z((0, 3)), z(0), z(0), z((6, 0)), z((0, n_servo)), z(0), info.C_joint.copy(),
        z((0, 0)), z((6, n_servo)), z((0, n_servo)), x_o, R_o, float(horizon),
    )  # fmt: skip


def _contact_rows(
    data: mujoco.MjData, a: NDArray[np.int64], s: NDArray[np.float64],
    tors: NDArray[np.bool_], nc: int, horizon: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # fmt: skip
    """``(forces (m, nc), C_contact (nc m,))`` from the contacts' constraint rows (first row
    ``a``, frame sign ``s``, ``tors`` where a contact has a torsional row): the force of
    the hand on the object [N, N m] and the diagonal compliance, ``R_n / (K_s I)`` [m/N]
    normal and ``R horizon / B`` tangential [m/N] and torsional [rad/(N m)]."""
    # elliptic cone: the rows a, a+1, a+2 (a+3) are the force (and moment about the normal)
    # on geom2 in MuJoCo's frame; in the frame flipped when the object is geom1, the force of
    # the hand on the object has the same (n, t1) numbers and the opposite t2, and the moment
    # about the (flipped) normal is the same number
    rows = a[:, None] + np.arange(nc)
    if nc == 4:
        rows[~tors, 3] = a[~tors]  # condim 3 in a condim-4 grasp: no torsional row
    forces = data.efc_force[rows]
    forces[:, 2] *= s
    kbip, R = data.efc_KBIP[rows], data.efc_R[rows]
    # normal: R_n / (K_s I); tangential and torsional: R h / B
    comp = R * horizon / kbip[:, :, 1]
    comp[:, 0] = R[:, 0] / (kbip[:, 0, 0] * kbip[:, 0, 2])
    if nc == 4 and not tors.all():
        forces[~tors, 3] = 0.0
        comp[~tors, 3] = 1e9  # a condim-3 contact has no torsional friction: a free twist
    return forces, comp.reshape(-1)


def _grasp_map(
    frames: NDArray[np.float64], points: NDArray[np.float64], x_o: NDArray[np.float64], nc: int
) -> NDArray[np.float64]:
    """``G`` (6, nc m), world axes, about the object origin ``x_o``: ``f = frame^T c``,
    torque ``= (p - x_o) x f = [r]_x frame^T c``, and the torsional moment ``c_tau`` about
    ``n`` (``nc = 4``)."""
    m = len(frames)
    Ft = frames.transpose(0, 2, 1)  # (m, 3, 3): columns n, t1, t2 in world
    r = points - x_o
    Gc = np.zeros((m, 6, nc))
    Gc[:, :3, :3] = Ft
    rx = np.zeros((m, 9))  # [r]_x, row-major: [[0, -z, y], [z, 0, -x], [-y, x, 0]]
    rx[:, _SKEW_AT] = r[:, _SKEW_FROM] * _SKEW_SIGN
    Gc[:, 3:, :3] = rx.reshape(m, 3, 3) @ Ft
    if nc == 4:
        Gc[:, 3:, 3] = frames[:, 0]
    return Gc.transpose(1, 0, 2).reshape(6, nc * m)


def _hand_jacobian(
    model: mujoco.MjModel, data: mujoco.MjData, info: _HandInfo, bodies: list[int],
    points: NDArray[np.float64], frames: NDArray[np.float64], nc: int,
) -> NDArray[np.float64]:  # fmt: skip
    """``J`` (nc m, l): the servo setpoints [rad] to the hand's contact-point motion in the
    contact frames [m] (and, ``nc = 4``, the hand link's rotation about ``n`` [rad]); zero
    rows for static bodies."""
    m = len(bodies)
    J = np.zeros((nc * m, len(info.dofs)))
    jac = np.zeros((6, model.nv))
    jacp, jacr = jac[:3], jac[3:]
    for k in range(m):
        b = bodies[k]
        if info.static[b]:
            continue  # static body: no motion
        mujoco.mj_jac(model, data, jacp, jacr if nc == 4 else None, points[k], b)
        jk = jac[:, info.dofs]
        J[nc * k : nc * k + 3] = frames[k] @ jk[:3]
        if nc == 4:
            J[nc * k + 3] = frames[k, 0] @ jk[3:]
    return J


def _object_response(
    G: NDArray[np.float64], J: NDArray[np.float64], C_contact: NDArray[np.float64],
    C_joint: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:  # fmt: skip
    """``(K, F, E)`` (module docstring): ``K = (C_contact + J C_joint J^T)^{-1}``, ``F =
    (G K G^T)^+ G K J``, ``E = K (J - G^T F)``; the inverse by Cholesky where ``G K G^T``
    is well conditioned, else the pseudo-inverse over its eigenvalues above ``1e-10``
    relative."""
    n = len(C_contact)
    C = (J * C_joint) @ J.T
    C.flat[:: n + 1] += C_contact
    K = np.linalg.inv(C)
    GK = G @ K
    GKGt = GK @ G.T
    GKJ = GK @ J
    try:  # positive definite (the contacts hold every object direction): Cholesky
        L = np.linalg.cholesky(GKGt)
        d = np.diagonal(L)
        if d.min() < 1e-5 * d.max():
            raise np.linalg.LinAlgError
        F = np.linalg.solve(GKGt, GKJ)
    except np.linalg.LinAlgError:  # a direction no contact holds: pseudo-inverse
        lam, V = np.linalg.eigh(GKGt)
        keep = lam > 1e-10 * max(float(lam[-1]), 1e-300)
        Vk = V[:, keep]
        F = (Vk / lam[keep]) @ (Vk.T @ GKJ)
    E = K @ J - K @ (G.T @ F)
    return K, F, E
