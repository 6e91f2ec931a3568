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
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

__all__ = ["HandElement", "HandModel", "HandModelError", "hand_model", "transmission"]

_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
_C = mujoco.mjtConstraint
_CONTACT = (int(_C.mjCNSTR_CONTACT_FRICTIONLESS), int(_C.mjCNSTR_CONTACT_PYRAMIDAL),
            int(_C.mjCNSTR_CONTACT_ELLIPTIC))  # fmt: skip
_LIMIT = (int(_C.mjCNSTR_LIMIT_JOINT), int(_C.mjCNSTR_LIMIT_TENDON))
_FRICTION = (int(_C.mjCNSTR_FRICTION_DOF), int(_C.mjCNSTR_FRICTION_TENDON))
_EQ = mujoco.mjtEq
_EQ_KIND = {int(_EQ.mjEQ_CONNECT): "connect", int(_EQ.mjEQ_WELD): "weld",
            int(_EQ.mjEQ_JOINT): "joint", int(_EQ.mjEQ_TENDON): "tendon"}  # fmt: skip
#: singular values below this times the largest are zero (rank of the equalities, rows
#: scaled to unit norm): a four-bar whose axes are parallel to 1e-6 rad (URDF round-off of
#: pi/2 is 3.7e-6) still folds to its one free motion instead of locking rigid
RANK_RTOL = 1e-6
FORCE_ATOL = 1e-9  # a constraint or passive force below this [N, N m] is no force
NEAR_LIMIT = 0.05  # a joint this close to a limit [rad or m] without a stop gets a warning


class HandModelError(GraspError):
    """An element of the MuJoCo hand that the grasp model cannot represent."""


@dataclass
class HandElement:
    """One column of ``R`` (or one folded or unrepresented element) and how it is modelled.

    ``kind``: "actuator", "stop", "spring", "gravity", "applied" (columns of ``R``), or
    "equality" (folded into ``T``). ``model``: "nonbackdrivable", "backdrivable" or
    "folded". ``force``: its force at the state (actual, passive reaction included)
    [N or N m]; ``command``: ``f_c`` in the grasp model.
    """

    name: str
    kind: str
    model: str
    force: float = 0.0
    command: float = 0.0
    note: str = ""


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

    @property
    def names(self) -> list[str]:
        """(a,) the names of the columns of ``R``."""
        return [e.name for e in _columns(self.elements)]

    @property
    def actuated(self) -> NDArray[np.bool_]:
        """(a,) True for the columns that are MuJoCo actuators (the commands one sets)."""
        return np.array([e.kind == "actuator" for e in _columns(self.elements)], dtype=bool)


def _columns(elements: list[HandElement]) -> list[HandElement]:
    """The elements that are columns of ``R``, in order (not folded equalities, not stops
    merged into an actuator)."""
    return [e for e in elements if e.kind != "equality" and e.model != "merged"]


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


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
        names = [_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in bad]
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
    with the springs as constant torques and a warning (``"warn"``).
    """
    if spring_held not in ("raise", "warn"):
        raise HandModelError(f"spring_held must be 'raise' or 'warn', got {spring_held!r}")
    if servo not in ("nonbackdrivable", "force"):
        raise HandModelError(f"servo must be 'nonbackdrivable' or 'force', got {servo!r}")
    joints = hand_joints(model, in_obj)
    dofs = np.array([model.jnt_dofadr[j] for j in joints], dtype=np.int64)
    jname = [_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
    hand = np.zeros(model.nv, dtype=bool)
    hand[dofs] = True
    E = efc_jacobian(model, data)
    typ = np.asarray(data.efc_type[: data.nefc])
    eid = np.asarray(data.efc_id[: data.nefc])
    frc = np.asarray(data.efc_force[: data.nefc])
    scale = 1e-9 * max(1.0, float(np.abs(E).max(initial=0.0)))
    touches_hand = np.abs(E[:, hand]).max(axis=1, initial=0.0) > scale
    touches_other = np.abs(E[:, ~hand]).max(axis=1, initial=0.0) > scale
    elements: list[HandElement] = []
    warns: list[str] = []

    # -- equalities: fold the closed chains ------------------------------------------
    eq_rows = np.flatnonzero(typ == int(_C.mjCNSTR_EQUALITY))
    folded = []
    for e in sorted(set(eid[eq_rows].tolist())):
        rows = eq_rows[eid[eq_rows] == e]
        kind = _EQ_KIND.get(int(model.eq_type[e]), f"type {int(model.eq_type[e])}")
        ename = f"{kind} equality {_name(model, mujoco.mjtObj.mjOBJ_EQUALITY, e)}"
        if not touches_hand[rows].any():
            continue  # inside the object
        if touches_other[rows].any():
            raise HandModelError(
                f"{ename} ties the hand to the object (or to another free body); the grasp "
                "model has no such constraint: deactivate it (data.eq_active) or make the "
                "body part of the hand"
            )
        if kind.startswith("type"):
            raise HandModelError(f"{ename} is not supported (connect, weld, joint, tendon are)")
        folded.extend(rows.tolist())
        elements.append(HandElement(ename, "equality", "folded", note=f"{rows.size} rows"))
    A = E[np.array(folded, dtype=np.int64)][:, dofs] if folded else np.zeros((0, len(joints)))
    Mh = transmission(model, data)[:, dofs]
    actuated = np.abs(Mh).max(axis=0, initial=0.0) > 0
    eq_joint1 = []
    for e in range(model.neq):
        if int(model.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT) and data.eq_active[e]:
            j1 = int(model.eq_obj1id[e])
            if j1 in joints:
                eq_joint1.append(joints.index(j1))
    rest = sorted(range(len(joints)), key=lambda k: (bool(actuated[k]), -k))
    prefer = eq_joint1 + [k for k in rest if k not in eq_joint1]
    T, dep = _fold(model, A, joints, prefer)
    ind = [k for k in range(len(joints)) if k not in dep]
    if joints and not ind:
        warns.append(f"the hand's equality constraints lock all {len(joints)} joints: the hand is "
                     "a rigid fixture in the model")  # fmt: skip

    # -- actuators -----------------------------------------------------------------------
    cols: list[NDArray[np.float64]] = []
    f_c: list[float] = []
    f_act: list[float] = []
    back: list[bool] = []
    names = [_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu)]
    if backdrivable is not None and not isinstance(backdrivable, bool):
        wanted = set(backdrivable)
        unknown = wanted - set(names)
        if unknown:
            raise HandModelError(f"backdrivable names unknown actuators {sorted(unknown)}; "
                                 f"actuators: {names}")  # fmt: skip
    for a in range(model.nu):
        force = float(data.actuator_force[a])
        lo, hi = model.actuator_forcerange[a]
        limited = bool(model.actuator_forcelimited[a]) and hi > lo
        saturated = limited and min(abs(force - lo), abs(force - hi)) <= 1e-9 * (1 + abs(force))
        is_servo = (int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
                    and model.actuator_biasprm[a, 1] < 0)  # fmt: skip
        if backdrivable is None:
            b = saturated or (is_servo and servo == "force")
            why = ("saturated at its forcerange: a constant force source" if saturated else
                   "position servo (servo='force')" if b else
                   "position servo, modelled nonbackdrivable (servo='nonbackdrivable')"
                   if is_servo else "motor (the thesis' nonbackdrivable transmission)")  # fmt: skip
        else:
            b = backdrivable if isinstance(backdrivable, bool) else names[a] in wanted
            why = "as asked (backdrivable=...)"
        cols.append(T.T @ Mh[a])
        f_c.append(force)
        f_act.append(force)
        back.append(b)
        elements.append(HandElement(names[a], "actuator",
                                    "backdrivable" if b else "nonbackdrivable", force, force,
                                    why))  # fmt: skip

    # -- active limits: one-way stops ------------------------------------------------------
    for r in np.flatnonzero(np.isin(typ, _LIMIT) & touches_hand):
        if frc[r] <= FORCE_ATOL:
            continue
        is_joint = int(typ[r]) == int(_C.mjCNSTR_LIMIT_JOINT)
        lname = _name(model, mujoco.mjtObj.mjOBJ_JOINT if is_joint else mujoco.mjtObj.mjOBJ_TENDON,
                      int(eid[r]))  # fmt: skip
        col = T.T @ E[r, dofs]
        merged = False
        for a in range(model.nu):
            ca = cols[a]
            if back[a] or not _along(ca, col):
                continue
            add = float(frc[r]) * float(col @ ca) / float(ca @ ca)
            f_act[a] += add
            elements[_index(elements, names[a])].force += add
            elements.append(HandElement(f"limit:{lname}", "stop", "merged", float(frc[r]),
                                        note=f"along actuator {names[a]}: its passive "
                                        "reaction (a ratchet)"))  # fmt: skip
            merged = True
            break
        if merged:
            continue
        if np.linalg.norm(col) == 0:
            continue  # a limit on a joint the equalities lock: no motion, no column
        cols.append(col)
        f_c.append(0.0)
        f_act.append(float(frc[r]))
        back.append(False)
        elements.append(HandElement(f"limit:{lname}", "stop", "nonbackdrivable", float(frc[r]),
                                    0.0, "one-way stop, command 0"))  # fmt: skip

    # -- limits within stop_gap: stops engaged by a small motion -------------------------------
    active_joints = {int(eid[r]) for r in np.flatnonzero(typ == int(_C.mjCNSTR_LIMIT_JOINT))
                     if frc[r] > FORCE_ATOL}  # fmt: skip
    near: list[str] = []
    for k, j in enumerate(joints):
        if not model.jnt_limited[j] or j in active_joints:
            continue
        q = float(data.qpos[model.jnt_qposadr[j]])
        lo, hi = model.jnt_range[j]
        for bound, sign in ((lo, 1.0), (hi, -1.0)):
            gap = sign * (q - bound)  # >= 0 inside the range
            col = T.T @ (sign * np.eye(len(joints))[k])
            if np.linalg.norm(col) == 0 or _blocked(col, cols, back):
                continue  # locked by the equalities, or a nonbackdrivable column holds it
            if gap <= stop_gap:
                cols.append(col)
                f_c.append(0.0)
                f_act.append(0.0)
                back.append(False)
                note = f"within stop_gap: {gap:.3g} from its limit"
                elements.append(HandElement(f"limit:{jname[k]}", "stop", "nonbackdrivable",
                                            0.0, 0.0, note))  # fmt: skip
            elif gap <= NEAR_LIMIT:
                near.append(f"{jname[k]} ({gap:.3g} from its limit)")

    # -- constant torques ------------------------------------------------------------------
    def constant(name: str, kind: str, tau_full: NDArray[np.float64], note: str) -> None:
        tau = T.T @ tau_full
        size = float(np.linalg.norm(tau))
        if size <= FORCE_ATOL:
            return
        cols.append(tau / size)
        f_c.append(size)
        f_act.append(size)
        back.append(True)
        elements.append(HandElement(name, kind, "backdrivable", size, size, note))

    spring = np.asarray(data.qfrc_spring)[dofs]
    for k in np.flatnonzero(np.abs(spring) > FORCE_ATOL):
        e = np.zeros(len(joints))
        e[k] = spring[k]
        constant(f"spring:{jname[k]}", "spring", e,
                 "its torque at the state; stiffness not modelled")  # fmt: skip
    weight = (np.asarray(data.qfrc_gravcomp) - np.asarray(data.qfrc_bias))[dofs]
    constant("gravity", "gravity", weight, "the links' own weight (at rest)")
    constant("applied", "applied", np.asarray(data.qfrc_applied)[dofs], "qfrc_applied")
    if np.any(data.xfrc_applied[~in_obj] != 0):
        xf = np.zeros(model.nv)
        for b in np.flatnonzero(~in_obj):
            if np.any(data.xfrc_applied[b] != 0):
                mujoco.mj_applyFT(model, data, data.xfrc_applied[b, :3], data.xfrc_applied[b, 3:],
                                  data.xipos[b], int(b), xf)  # fmt: skip
        constant("xfrc_applied", "applied", xf[dofs], "xfrc_applied on hand bodies")

    # -- what stays out (in the residual) ---------------------------------------------------
    own = {int(i) for i in object_contacts}
    for r in np.flatnonzero(np.isin(typ, _CONTACT) & touches_hand):
        if int(eid[r]) in own or abs(frc[r]) <= FORCE_ATOL:
            continue
        con = data.contact[int(eid[r])]
        b1, b2 = model.geom_bodyid[con.geom1], model.geom_bodyid[con.geom2]
        msg = (f"contact {_name(model, mujoco.mjtObj.mjOBJ_BODY, int(b1))} / "
               f"{_name(model, mujoco.mjtObj.mjOBJ_BODY, int(b2))} (not hand-object)")  # fmt: skip
        if msg not in warns:
            warns.append(msg)
    for r in np.flatnonzero(np.isin(typ, _FRICTION) & touches_hand):
        if abs(frc[r]) <= FORCE_ATOL:
            continue
        is_dof = int(typ[r]) == int(_C.mjCNSTR_FRICTION_DOF)
        obj = mujoco.mjtObj.mjOBJ_DOF if is_dof else mujoco.mjtObj.mjOBJ_TENDON
        who = (jname[list(dofs).index(int(eid[r]))] if is_dof and int(eid[r]) in dofs
               else _name(model, obj, int(eid[r])))  # fmt: skip
        warns.append(f"dry friction (frictionloss) of {who}: {frc[r]:.3g}")
    # a motion that no actuator and no loaded stop takes part in, held by springs alone
    columns = _columns(elements)
    holding = [c for c, e, fa in zip(cols, columns, f_act, strict=True)
               if e.kind == "actuator" or (e.kind == "stop" and fa > FORCE_ATOL)]  # fmt: skip
    free = _null(np.stack(holding, axis=0)) if holding else np.eye(T.shape[1])
    spring_cols = [(c, e.name) for c, e in zip(cols, columns, strict=True)
                   if e.kind == "spring"]  # fmt: skip
    held = [n for c, n in spring_cols
            if free.shape[1] and np.linalg.norm(free.T @ c) > 1e-6 * np.linalg.norm(c)]  # fmt: skip
    if held and spring_held == "raise":
        raise HandModelError(
            f"a passive motion of the hand is held by the spring(s) {held} alone (no actuator, "
            "no loaded stop takes part in it): the grasp model has no joint stiffness, so it "
            "would call any load on that motion unresisted, where MuJoCo moves the joint until "
            "the spring or a stop holds it. Not supported. Settle the grasp so that the "
            "linkage rests on its stops, or pass spring_held='warn' to model the spring as a "
            "constant torque and read such answers as 'unresisted by the model'"
        )
    for n in held:
        warns.append(
            f"{n}: a passive motion of the hand is held by this spring alone (no actuator, "
            "no loaded stop): the model keeps the spring's torque constant (its stiffness "
            "is not modelled), so it calls a load on that motion unresisted where MuJoCo "
            "moves the joint until the spring or a stop holds it"
        )
    for what in near:
        warns.append(f"joint {what}: a stop that a small motion engages is not in the model "
                     "(the grasp model is first order); pass stop_gap to include it")  # fmt: skip
    R = np.stack(cols, axis=1) if cols else np.zeros((len(ind), 0))
    big = float(np.abs(R @ np.array(f_act)).max(initial=0.0)) if cols else 0.0
    for what, vec in (("fluid", data.qfrc_fluid), ("damping (motion)", data.qfrc_damper)):
        tau = T.T @ np.asarray(vec)[dofs]
        if np.abs(tau).max(initial=0.0) > 1e-3 * max(big, FORCE_ATOL):
            warns.append(f"{what} forces {np.abs(tau).max():.3g} N m on the hand joints")
    return HandModel(
        dofs=dofs,
        T=T,
        joint_names=[jname[k] for k in ind],
        dependent=[jname[k] for k in dep],
        R=R,
        commands=np.array(f_c),
        forces=np.array(f_act),
        backdrivable=np.array(back, dtype=bool),
        elements=elements,
        warnings=warns,
    )


def _blocked(col: NDArray[np.float64], cols: list[NDArray[np.float64]], back: list[bool]) -> bool:
    """A nonbackdrivable column (actuator or stop) acts along ``col``, the same way: the
    motion a stop along ``col`` would block is blocked already."""
    return any(not b and _along(c, col) for c, b in zip(cols, back, strict=True))


def _along(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """``a`` and ``b`` are non-zero and point the same way (to 1e-9 in the cosine)."""
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return bool(na > 0 and nb > 0 and a @ b >= (1 - 1e-9) * na * nb)


def _null(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis (columns) of the null space of ``A`` (rows: constraints)."""
    _, sv, vt = np.linalg.svd(A)
    rank = int(np.sum(sv > RANK_RTOL * max(1.0, float(sv.max(initial=0.0)))))
    return vt[rank:].T


def _index(elements: list[HandElement], name: str) -> int:
    for k, e in enumerate(elements):
        if e.name == name and e.kind == "actuator":
            return k
    raise KeyError(name)
