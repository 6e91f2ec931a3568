"""The hand's statics read off MuJoCo: independent coordinates, transmission, stops.

The grasp model (thesis ch. 5; docs/design.md, Conventions) needs, over the hand's
independent joint motions ``q`` (``l`` of them): the contact Jacobian ``J``, and the
transmission ``R`` (``l x a``) with hand equilibrium ``J^T c = R f``. A hand read from
MuJoCo can carry more than actuators. :func:`hand_model` maps each element to what the
model has:

* **Equality constraints** of every kind MuJoCo reports (``connect``, ``weld``,
  ``joint``, ``tendon``) between hand bodies or joints: a closed linkage. Their rows of
  MuJoCo's constraint Jacobian ``A`` (over the hand's dofs, ``A qdot = 0``) are folded
  into the coordinates: ``qdot_full = T q`` with ``A T = 0``. ``T`` keeps the identity
  on a set of independent joints (named in ``joint_names``) and expresses the others
  (dependent: joint1 of a joint equality first, then unactuated joints, distal first)
  through them. The equalities' constraint forces ``A^T lambda`` are annihilated by
  ``T^T``, so ``J = J_full T`` and ``R = T^T R_full`` hold the statics exactly. A
  nonlinear coupling enters through its derivative at the state (small motions).
  An equality that ties the hand to the object is refused (:class:`HandModelError`).
* **Actuators**: one column each, ``T^T`` times the actuator's moment (gear, tendon
  moment arms). Nonbackdrivable (the thesis': ``f >= f_c``, one-way) unless
  backdrivable: a force-saturated actuator (``actuator_force`` at its ``forcerange``
  bound: a saturated position servo is a constant force source, whichever way it is
  pushed) is backdrivable; so is any actuator named in ``backdrivable``. An unsaturated
  position servo (``biasprm[1] < 0``) is a joint spring of stiffness ``kp``, which the
  unit-virtual-spring model has no place for: ``servo="nonbackdrivable"`` (default; the
  thesis' treatment of the Barrett spread servo: it does not give way to a load) or
  ``"force"`` (a constant force source: right for a servo much softer than the contacts).
* **Active limits** (joint or tendon limits whose constraint carries force): one-way
  stops. A stop is a nonbackdrivable actuator commanded 0 (``f >= 0``, it can move only
  away from the limit, ``f = 0`` when it does): a column ``T^T a^T`` with ``a`` the limit's
  constraint-Jacobian row. A stop acting along a nonbackdrivable actuator's own column
  (a :class:`ihm.ratchet.Ratchet` on the actuated joint) is that actuator's passive
  reaction: its force is added to the actuator's, no column is added.
* **Constant joint torques** at the state, each a backdrivable column with its torque
  as command: passive springs (``qfrc_spring``, per joint: ``spring:<joint>``; the
  stiffness itself is not modelled: valid while ``k`` times the motion stays small
  against the torque), the links' own weight (``qfrc_gravcomp - qfrc_bias`` at rest,
  ``gravity``) and forces applied to the hand (``qfrc_applied``, ``applied``).
* **Refused by default**: a passive motion held by springs alone (no actuator and no
  loaded stop takes part in it; e.g. a Robotiq 2F-85 whose couplers settle just off their
  stops): the model has no joint stiffness and would call every load on it unresisted
  (``spring_held="warn"`` models it anyway, with a warning).
* **Unrepresented**: dry joint friction (``frictionloss``), contacts of the hand with
  anything but the object, fluid forces, motion (damping, inertia). They are named in
  :attr:`HandModel.warnings` (and warned about by ``grasp_from_mujoco``), and their
  torques show in the hand-equilibrium residual, which ``grasp_from_mujoco`` checks.

Every element that enters the model is listed in :attr:`HandModel.elements`.

**Compliance** (``compliance="mujoco"``; the table in :mod:`ihm.compliance`): the columns
carry MuJoCo's stiffness and stop gaps, :attr:`HandModel.stiffness` ``K`` and
:attr:`HandModel.gaps` ``g`` (the grasp model's ``f = f_c - K v + lambda``, ``v >= -g``):
an actuator whose force depends on its length (an unsaturated servo) is a backdrivable
spring of stiffness ``K = -dF/dL`` (``servo`` is not used); passive springs get their
stiffness and a motion held by springs alone is no longer refused; joint limits within
``max(stop_gap, near_limit)`` of engaging become stops with that distance as gap.
``compliance="unit"`` (default) is the model above, ``K = g = 0``.

This module holds :func:`hand_model` and :class:`HandModel`, the reading of the hand's joints
and constraint rows at the state, the folding of the equalities into ``T`` and the checks
and warnings on what stays out of the model; the elements and the columns of ``R``
(actuators, stops, constant torques) are built in :mod:`ihm.handparts`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from .compliance import actuator_stiffness
from .handparts import (
    FORCE_ATOL,
    Columns,
    HandElement,
    HandModelError,
    HandState,
    add_active_stops,
    add_actuators,
    add_constant_torques,
    add_gap_stops,
    column_elements,
    object_name,
)
from .handparts import NEAR_LIMIT as NEAR_LIMIT  # re-exported: the stops' warning distance

__all__ = ["HandElement", "HandModel", "HandModelError", "hand_model", "transmission"]

_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
_C = mujoco.mjtConstraint
_CONTACT = (int(_C.mjCNSTR_CONTACT_FRICTIONLESS), int(_C.mjCNSTR_CONTACT_PYRAMIDAL),
            int(_C.mjCNSTR_CONTACT_ELLIPTIC))  # fmt: skip
_FRICTION = (int(_C.mjCNSTR_FRICTION_DOF), int(_C.mjCNSTR_FRICTION_TENDON))
_EQ = mujoco.mjtEq
_EQ_KIND = {int(_EQ.mjEQ_CONNECT): "connect", int(_EQ.mjEQ_WELD): "weld",
            int(_EQ.mjEQ_JOINT): "joint", int(_EQ.mjEQ_TENDON): "tendon"}  # fmt: skip
#: singular values below this times the largest are zero (rank of the equalities, rows
#: scaled to unit norm): a four-bar whose axes are parallel to 1e-6 rad (URDF round-off of
#: pi/2 is 3.7e-6) still folds to its one free motion instead of locking rigid
RANK_RTOL = 1e-6


@dataclass
class HandModel:
    """The hand's statics at a MuJoCo state (module docstring).

    dofs : (nv_hand,) MuJoCo dof indices of the hand joints
    T : (nv_hand, l) ``qdot[dofs] = T q``
    joint_names : the ``l`` independent joints; ``dependent``: the others
    R : (l, a) columns for actuators, stops and constant torques, in that order
    commands : (a,) ``f_c`` per column; ``forces``: (a,) actual forces at the state
    backdrivable : (a,) constant force sources
    elements : every column and folded equality (:attr:`names`: the columns')
    warnings : elements the model leaves out (their torques stay in the residual)
    stiffness : (a,) ``K`` per column [N/m or N m/rad of its motion ``v = col^T q``]
    gaps : (a,) stop gap ``g`` per column [m or rad of ``v``]; both 0 with
        ``compliance="unit"``
    """

    dofs: NDArray[np.int64]
    T: NDArray[np.float64]
    joint_names: list[str]
    dependent: list[str]
    R: NDArray[np.float64]
    commands: NDArray[np.float64]
    forces: NDArray[np.float64]
    backdrivable: NDArray[np.bool_]
    elements: list[HandElement] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    stiffness: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    gaps: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    @property
    def names(self) -> list[str]:
        """(a,) the names of the columns of ``R``."""
        return [e.name for e in column_elements(self.elements)]

    @property
    def actuated(self) -> NDArray[np.bool_]:
        """(a,) True for the columns that are MuJoCo actuators (the commands one sets)."""
        return np.array([e.kind == "actuator" for e in column_elements(self.elements)], dtype=bool)


def efc_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> NDArray[np.float64]:
    """MuJoCo's constraint Jacobian ``efc_J`` as a dense ``(nefc, nv)`` array."""
    n = data.nefc
    if not mujoco.mj_isSparse(model):
        return np.array(data.efc_J[: n * model.nv]).reshape(n, model.nv)
    dense = np.zeros((n, model.nv))
    if n:
        mujoco.mju_sparse2dense(dense, data.efc_J, data.efc_J_rownnz, data.efc_J_rowadr,
                                data.efc_J_colind)  # fmt: skip
    return dense


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


def hand_joints(model: mujoco.MjModel, in_obj: NDArray[np.bool_]) -> list[int]:
    """Joint ids outside the object's subtree (``in_obj``: (nbody,) mask); a hand joint
    that is not a hinge or slide raises :class:`HandModelError` naming it."""
    joints, bad = [], []
    for j in range(model.njnt):
        if in_obj[model.jnt_bodyid[j]]:
            continue
        (joints if int(model.jnt_type[j]) in _HINGE_SLIDE else bad).append(j)
    if bad:
        names = [object_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in bad]
        raise HandModelError(
            f"hand joints must be hinges or slides; got {names} (a ball or free joint in the "
            "hand: replace it by hinges, or weld the base to the world; a second free body "
            "in the scene: only the object's subtree may have one)"
        )
    return joints


def _fold(
    model: mujoco.MjModel,
    A: NDArray[np.float64],
    joints: list[int],
    prefer: list[int],
) -> tuple[NDArray[np.float64], list[int]]:
    """``T`` with ``A T = 0`` and the identity on the independent joints; the dependent
    ones are picked greedily from ``prefer`` (positions in ``joints``)."""
    n = len(joints)
    if A.shape[0] == 0:
        return np.eye(n), []
    norms = np.linalg.norm(A, axis=1)
    A = A[norms > 0] / norms[norms > 0, None]  # same null space, rows of one scale
    s = np.linalg.svd(A, compute_uv=False)
    tol = RANK_RTOL * max(1.0, float(s[0]))
    rank = int(np.sum(s > tol))
    dep: list[int] = []
    for k in prefer:
        if len(dep) == rank:
            break
        trial = dep + [k]
        if np.linalg.matrix_rank(A[:, trial], tol=tol) == len(trial):
            dep = trial
    if len(dep) < rank:
        raise HandModelError("equality constraints of the hand could not be folded (rank)")
    ind = [k for k in range(n) if k not in dep]
    sol, *_ = np.linalg.lstsq(A[:, dep], -A[:, ind], rcond=None)
    if ind and np.abs(A[:, dep] @ sol + A[:, ind]).max() > 10 * RANK_RTOL:
        raise HandModelError("the hand's equality constraints are inconsistent at this state")
    T = np.zeros((n, len(ind)))
    T[ind, np.arange(len(ind))] = 1.0
    T[dep] = sol
    T[np.abs(T) < 1e-12] = 0.0
    return T, dep


def _check_modes(servo: str, spring_held: str, compliance: str) -> None:
    """:class:`HandModelError` for an unknown ``spring_held``, ``servo`` or ``compliance``."""
    if compliance not in ("unit", "mujoco"):
        raise HandModelError(f"compliance must be 'unit' or 'mujoco', got {compliance!r}")
    if spring_held not in ("raise", "warn"):
        raise HandModelError(f"spring_held must be 'raise' or 'warn', got {spring_held!r}")
    if servo not in ("nonbackdrivable", "force"):
        raise HandModelError(f"servo must be 'nonbackdrivable' or 'force', got {servo!r}")


def _hand_state(model: mujoco.MjModel, data: mujoco.MjData, in_obj: NDArray[np.bool_]) -> HandState:
    """The hand's joints and the constraint rows at the state. A row touches a dof where
    its Jacobian entry exceeds ``1e-9 max(1, max |E|)``."""
    joints = hand_joints(model, in_obj)
    dofs = np.array([model.jnt_dofadr[j] for j in joints], dtype=np.int64)
    hand = np.zeros(model.nv, dtype=bool)
    hand[dofs] = True
    E = efc_jacobian(model, data)
    scale = 1e-9 * max(1.0, float(np.abs(E).max(initial=0.0)))
    return HandState(
        model=model,
        data=data,
        in_obj=in_obj,
        joints=joints,
        dofs=dofs,
        jname=[object_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints],
        E=E,
        typ=np.asarray(data.efc_type[: data.nefc]),
        eid=np.asarray(data.efc_id[: data.nefc]),
        frc=np.asarray(data.efc_force[: data.nefc]),
        touches_hand=np.abs(E[:, hand]).max(axis=1, initial=0.0) > scale,
        touches_other=np.abs(E[:, ~hand]).max(axis=1, initial=0.0) > scale,
        Mh=transmission(model, data)[:, dofs],
        actuator_names=[
            object_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu)
        ],
    )


def _equality_rows(hs: HandState, elements: list[HandElement]) -> list[int]:
    """Constraint rows of the hand's equalities (to fold), each equality listed in
    ``elements``; equalities inside the object are skipped, one that ties the hand to the
    object (or is of an unsupported kind) raises :class:`HandModelError`."""
    model = hs.model
    eq_rows = np.flatnonzero(hs.typ == int(_C.mjCNSTR_EQUALITY))
    folded: list[int] = []
    for e in sorted(set(hs.eid[eq_rows].tolist())):
        rows = eq_rows[hs.eid[eq_rows] == e]
        kind = _EQ_KIND.get(int(model.eq_type[e]), f"type {int(model.eq_type[e])}")
        ename = f"{kind} equality {object_name(model, mujoco.mjtObj.mjOBJ_EQUALITY, e)}"
        if not hs.touches_hand[rows].any():
            continue  # inside the object
        if hs.touches_other[rows].any():
            raise HandModelError(
                f"{ename} ties the hand to the object (or to another free body); the grasp "
                "model has no such constraint: deactivate it (data.eq_active) or make the "
                "body part of the hand"
            )
        if kind.startswith("type"):
            raise HandModelError(f"{ename} is not supported (connect, weld, joint, tendon are)")
        folded.extend(rows.tolist())
        elements.append(HandElement(ename, "equality", "folded", note=f"{rows.size} rows"))
    return folded


def _dependent_order(hs: HandState) -> list[int]:
    """Positions in ``hs.joints`` in the order they are tried as dependent joints: joint1
    of each active joint equality first, then unactuated joints before actuated ones,
    distal (higher index) first."""
    model, data, joints = hs.model, hs.data, hs.joints
    actuated = np.abs(hs.Mh).max(axis=0, initial=0.0) > 0
    eq_joint1 = []
    for e in range(model.neq):
        if int(model.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT) and data.eq_active[e]:
            j1 = int(model.eq_obj1id[e])
            if j1 in joints:
                eq_joint1.append(joints.index(j1))
    rest = sorted(range(len(joints)), key=lambda k: (bool(actuated[k]), -k))
    return eq_joint1 + [k for k in rest if k not in eq_joint1]


def _fold_equalities(
    hs: HandState, elements: list[HandElement]
) -> tuple[NDArray[np.float64], list[int]]:
    """``T`` (``qdot[dofs] = T q``) with the hand's equalities folded in, and the
    positions of the dependent joints (:func:`_fold`)."""
    folded = _equality_rows(hs, elements)
    A = (hs.E[np.array(folded, dtype=np.int64)][:, hs.dofs] if folded
         else np.zeros((0, len(hs.joints))))  # fmt: skip
    return _fold(hs.model, A, hs.joints, _dependent_order(hs))


def _warn_unmodelled(hs: HandState, object_contacts: Iterable[int], warns: list[str]) -> None:
    """Name the loaded contacts of the hand with anything but the object (once per body
    pair) and the hand's dry friction (``frictionloss``) in ``warns``."""
    model, data, typ, eid, frc = hs.model, hs.data, hs.typ, hs.eid, hs.frc
    own = {int(i) for i in object_contacts}
    for r in np.flatnonzero(np.isin(typ, _CONTACT) & hs.touches_hand):
        if int(eid[r]) in own or abs(frc[r]) <= FORCE_ATOL:
            continue
        con = data.contact[int(eid[r])]
        b1, b2 = model.geom_bodyid[con.geom1], model.geom_bodyid[con.geom2]
        body = mujoco.mjtObj.mjOBJ_BODY
        msg = (f"contact {object_name(model, body, int(b1))} / "
               f"{object_name(model, body, int(b2))} (not hand-object)")  # fmt: skip
        if msg not in warns:
            warns.append(msg)
    for r in np.flatnonzero(np.isin(typ, _FRICTION) & hs.touches_hand):
        if abs(frc[r]) <= FORCE_ATOL:
            continue
        is_dof = int(typ[r]) == int(_C.mjCNSTR_FRICTION_DOF)
        obj = mujoco.mjtObj.mjOBJ_DOF if is_dof else mujoco.mjtObj.mjOBJ_TENDON
        who = (hs.jname[list(hs.dofs).index(int(eid[r]))] if is_dof and int(eid[r]) in hs.dofs
               else object_name(model, obj, int(eid[r])))  # fmt: skip
        warns.append(f"dry friction (frictionloss) of {who}: {frc[r]:.3g}")


def _spring_held(acc: Columns, n_free: int) -> list[str]:
    """The springs that hold a motion of the hand no actuator and no loaded stop takes
    part in (``n_free``: the number of independent coordinates)."""
    columns = column_elements(acc.elements)
    holding = [c for c, e, fa in zip(acc.cols, columns, acc.f_act, strict=True)
               if e.kind == "actuator" or (e.kind == "stop" and fa > FORCE_ATOL)]  # fmt: skip
    free = _null(np.stack(holding, axis=0)) if holding else np.eye(n_free)
    spring_cols = [(c, e.name) for c, e in zip(acc.cols, columns, strict=True)
                   if e.kind == "spring"]  # fmt: skip
    return [n for c, n in spring_cols
            if free.shape[1] and np.linalg.norm(free.T @ c) > 1e-6 * np.linalg.norm(c)]  # fmt: skip


def _check_spring_held(acc: Columns, n_free: int, spring_held: str) -> None:
    """A passive motion held by springs alone raises :class:`HandModelError`
    (``spring_held="raise"``) or is named in the warnings (``"warn"``)."""
    held = _spring_held(acc, n_free)
    if held and spring_held == "raise":
        raise HandModelError(
            f"a passive motion of the hand is held by the spring(s) {held} alone (no actuator, "
            "no loaded stop takes part in it): the grasp model has no joint stiffness, so it "
            "would call any load on that motion unresisted, where MuJoCo moves the joint until "
            "the spring or a stop holds it. Not supported. Settle the grasp so that the "
            "linkage rests on its stops, or pass spring_held='warn' (grasp_from_mujoco: "
            "hand=HandOptions(spring_held='warn')) to model the spring as a constant torque "
            "and read such answers as 'unresisted by the model'"
        )
    for n in held:
        acc.warnings.append(
            f"{n}: a passive motion of the hand is held by this spring alone (no actuator, "
            "no loaded stop): the model keeps the spring's torque constant (its stiffness "
            "is not modelled), so it calls a load on that motion unresisted where MuJoCo "
            "moves the joint until the spring or a stop holds it"
        )


def _warn_motion_forces(
    hs: HandState, T: NDArray[np.float64], R: NDArray[np.float64], acc: Columns
) -> None:
    """Name fluid and damping torques on the hand above 1e-3 of the largest modelled
    joint torque ``|R f_act|`` (at least :data:`FORCE_ATOL`)."""
    big = float(np.abs(R @ np.array(acc.f_act)).max(initial=0.0)) if acc.cols else 0.0
    for what, vec in (("fluid", hs.data.qfrc_fluid), ("damping (motion)", hs.data.qfrc_damper)):
        tau = T.T @ np.asarray(vec)[hs.dofs]
        if np.abs(tau).max(initial=0.0) > 1e-3 * max(big, FORCE_ATOL):
            acc.warnings.append(f"{what} forces {np.abs(tau).max():.3g} N m on the hand joints")


def hand_model(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    in_obj: NDArray[np.bool_],
    *,
    backdrivable: bool | Iterable[str] | None = None,
    servo: str = "nonbackdrivable",
    object_contacts: Iterable[int] = (),
    stop_gap: float = 0.0,
    spring_held: str = "raise",
    compliance: str = "unit",
    near_limit: float = NEAR_LIMIT,
) -> HandModel:
    """The hand's coordinates, transmission, stops and constant torques (module doc).

    ``data`` after ``mj_forward``. ``in_obj``: ``(nbody,)`` mask of the object's subtree.
    ``backdrivable``: None (force-saturated actuators only), True/False (every actuator),
    or the names of the backdrivable actuators. ``servo``: how an unsaturated position
    servo enters ("nonbackdrivable" or "force"). ``object_contacts``: MuJoCo contact
    indices between the object and the hand (the grasp's; other contacts on the hand
    are reported as unmodelled). ``stop_gap`` [rad or m]: a joint limit this close that
    carries no force yet is a stop too (engaged by a motion of at most ``stop_gap``).
    ``spring_held``: a passive motion held by springs alone (no actuator, no loaded stop
    takes part in it) raises :class:`HandModelError` (``"raise"``, default) or is modelled
    with the springs as constant torques and a warning (``"warn"``). ``compliance``:
    ``"unit"`` (default) or ``"mujoco"`` (module docstring, Compliance: servo and spring
    stiffness, stops within ``max(stop_gap, near_limit)`` [rad or m] with their gaps).

    The steps: fold the equalities into ``T``; then the columns of ``R`` in order:
    actuators, loaded stops, stops within ``stop_gap``, constant torques; then the
    warnings for what stays out of the model.
    """
    _check_modes(servo, spring_held, compliance)
    mj = compliance == "mujoco"
    hs = _hand_state(model, data, in_obj)
    acc = Columns()
    T, dep = _fold_equalities(hs, acc.elements)
    ind = [k for k in range(len(hs.joints)) if k not in dep]
    if hs.joints and not ind:
        acc.warnings.append(f"the hand's equality constraints lock all {len(hs.joints)} joints: "
                            "the hand is a rigid fixture in the model")  # fmt: skip
    add_actuators(hs, T, backdrivable, servo, acc,
                  actuator_stiffness(model, data) if mj else None)  # fmt: skip
    add_active_stops(hs, T, acc)
    near = add_gap_stops(hs, T, stop_gap, acc, near_limit if mj else None)
    add_constant_torques(hs, T, acc, spring_stiffness=mj)
    _warn_unmodelled(hs, object_contacts, acc.warnings)
    if not mj:  # with compliance="mujoco" the springs' stiffness holds their motions
        _check_spring_held(acc, T.shape[1], spring_held)
    for what in near:
        acc.warnings.append(f"joint {what}: a stop that a small motion engages is not in the "
                            "model (the grasp model is first order); pass stop_gap to include "
                            "it (grasp_from_mujoco: hand=HandOptions(stop_gap=...))")  # fmt: skip
    R = np.stack(acc.cols, axis=1) if acc.cols else np.zeros((len(ind), 0))
    _warn_motion_forces(hs, T, R, acc)
    return HandModel(
        dofs=hs.dofs,
        T=T,
        joint_names=[hs.jname[k] for k in ind],
        dependent=[hs.jname[k] for k in dep],
        R=R,
        commands=np.array(acc.f_c),
        forces=np.array(acc.f_act),
        backdrivable=np.array(acc.back, dtype=bool),
        elements=acc.elements,
        warnings=acc.warnings,
        stiffness=np.array(acc.stiff, dtype=float),
        gaps=np.array(acc.gap, dtype=float),
    )


def _null(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis (columns) of the null space of ``A`` (rows: constraints)."""
    _, sv, vt = np.linalg.svd(A)
    rank = int(np.sum(sv > RANK_RTOL * max(1.0, float(sv.max(initial=0.0)))))
    return vt[rank:].T
