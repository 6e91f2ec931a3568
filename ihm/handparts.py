"""The parts of the hand model :func:`ihm.handmodel.hand_model` assembles: its elements,
the hand at a MuJoCo state, and the columns of the transmission ``R`` over the independent
coordinates ``q`` (``qdot[dofs] = T q``).

* :class:`HandElement`, :class:`HandModelError`: one modelled element, and the error for an
  element the grasp model cannot represent.
* :class:`HandState`: the hand's joints, constraint rows and actuator moments at the state.
* :class:`Columns` and the steps that fill it, in the order :func:`ihm.handmodel.hand_model`
  calls them: :func:`add_actuators` (``T^T`` times each actuator's moment, nonbackdrivable
  or backdrivable), :func:`add_active_stops` (a one-way stop, command 0, per loaded joint
  or tendon limit; one along a nonbackdrivable actuator's column is merged into it as its
  passive reaction), :func:`add_gap_stops` (a stop per limit within ``stop_gap``) and
  :func:`add_constant_torques` (backdrivable columns for springs, weight and applied
  forces at the state). :mod:`ihm.handmodel`'s docstring states the model they implement.

With ``compliance="mujoco"`` (:mod:`ihm.compliance`) the columns also carry a stiffness
``K`` [per unit of the column's motion ``v = col^T q``] and a stop gap ``g`` [of ``v``]:
servos their ``-dF/dL``, springs their stiffness, limits near the state their distance.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import GraspError

from .compliance import limit_gaps, passive_stiffness

__all__ = [
    "FORCE_ATOL",
    "NEAR_LIMIT",
    "Columns",
    "HandElement",
    "HandModelError",
    "HandState",
    "add_active_stops",
    "add_actuators",
    "add_constant_torques",
    "add_gap_stops",
    "column_elements",
    "object_name",
]

_C = mujoco.mjtConstraint
_LIMIT = (int(_C.mjCNSTR_LIMIT_JOINT), int(_C.mjCNSTR_LIMIT_TENDON))
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


@dataclass(frozen=True)
class HandState:
    """The hand at a MuJoCo state, as the steps of :func:`ihm.handmodel.hand_model` read it.

    joints : hand joint ids; ``dofs``: their dof indices; ``jname``: their names
    in_obj : (nbody,) mask of the object's subtree
    E : (nefc, nv) constraint Jacobian; ``typ``, ``eid``, ``frc``: (nefc,) type, object id
        and force [N or N m] of each constraint row
    touches_hand, touches_other : (nefc,) a row acts on a hand dof / on a dof outside the hand
    Mh : (nu, nv_hand) actuator moments on the hand dofs; ``actuator_names``: (nu,)
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    in_obj: NDArray[np.bool_]
    joints: list[int]
    dofs: NDArray[np.int64]
    jname: list[str]
    E: NDArray[np.float64]
    typ: NDArray[np.int64]
    eid: NDArray[np.int64]
    frc: NDArray[np.float64]
    touches_hand: NDArray[np.bool_]
    touches_other: NDArray[np.bool_]
    Mh: NDArray[np.float64]
    actuator_names: list[str]


@dataclass
class Columns:
    """The columns of ``R`` as :func:`ihm.handmodel.hand_model` collects them: each column
    with its command ``f_c``, its actual force ``f_act`` [N or N m], whether it is
    backdrivable, its stiffness ``K`` and stop gap ``g`` (0 but with
    ``compliance="mujoco"``); ``elements`` lists every column and folded equality,
    ``warnings`` what stays out."""

    cols: list[NDArray[np.float64]] = field(default_factory=list)
    f_c: list[float] = field(default_factory=list)
    f_act: list[float] = field(default_factory=list)
    back: list[bool] = field(default_factory=list)
    elements: list[HandElement] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    stiff: list[float] = field(default_factory=list)
    gap: list[float] = field(default_factory=list)

    def add(self, col: NDArray[np.float64], command: float, force: float, backdrivable: bool,
            element: HandElement, stiffness: float = 0.0, gap: float = 0.0) -> None:  # fmt: skip
        """Append one column of ``R`` and its element."""
        self.cols.append(col)
        self.f_c.append(command)
        self.f_act.append(force)
        self.back.append(backdrivable)
        self.elements.append(element)
        self.stiff.append(stiffness)
        self.gap.append(gap)


def column_elements(elements: list[HandElement]) -> list[HandElement]:
    """The elements that are columns of ``R``, in order (not folded equalities, not stops
    merged into an actuator)."""
    return [e for e in elements if e.kind != "equality" and e.model != "merged"]


def object_name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    """The MuJoCo name of object ``i`` of type ``obj``, or ``#i`` when it has none."""
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


def _actuator_mode(
    hs: HandState, a: int, backdrivable: bool | set[str] | None, servo: str, spring: bool
) -> tuple[bool, str]:
    """Whether actuator ``a`` is backdrivable, and why (:mod:`ihm.handmodel` docstring,
    Actuators); ``spring``: its force depends on its length (``compliance="mujoco"``, an
    unsaturated servo): a backdrivable spring."""
    model = hs.model
    force = float(hs.data.actuator_force[a])
    lo, hi = model.actuator_forcerange[a]
    limited = bool(model.actuator_forcelimited[a]) and hi > lo
    saturated = limited and min(abs(force - lo), abs(force - hi)) <= 1e-9 * (1 + abs(force))
    is_servo = (int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
                and model.actuator_biasprm[a, 1] < 0)  # fmt: skip
    if backdrivable is None:
        b = saturated or spring or (is_servo and servo == "force")
        why = ("saturated at its forcerange: a constant force source" if saturated else
               "a spring, K = -dF/dL (compliance='mujoco')" if spring else
               "position servo (servo='force')" if b else
               "position servo, modelled nonbackdrivable (servo='nonbackdrivable')"
               if is_servo else "motor (the thesis' nonbackdrivable transmission)")  # fmt: skip
        return b, why
    if isinstance(backdrivable, bool):
        return backdrivable, "as asked (backdrivable=...)"
    return hs.actuator_names[a] in backdrivable, "as asked (backdrivable=...)"


def add_actuators(
    hs: HandState,
    T: NDArray[np.float64],
    backdrivable: bool | Iterable[str] | None,
    servo: str,
    acc: Columns,
    stiffness: NDArray[np.float64] | None = None,
) -> None:
    """One column ``T^T moment`` per actuator, its force as command; an unknown name in
    ``backdrivable`` raises :class:`HandModelError`. ``stiffness``: ``K = -dF/dL`` per
    actuator (:func:`ihm.compliance.actuator_stiffness`; ``compliance="mujoco"``), in the
    column's units (``v = col^T q`` is the actuator length's change); an actuator with
    ``K > 0`` is backdrivable unless ``backdrivable`` names it otherwise, and ``K < 0``
    raises :class:`HandModelError`."""
    names = hs.actuator_names
    mode = (backdrivable if backdrivable is None or isinstance(backdrivable, bool)
            else set(backdrivable))  # fmt: skip
    if isinstance(mode, set):
        unknown = mode - set(names)
        if unknown:
            raise HandModelError(f"backdrivable names unknown actuators {sorted(unknown)}; "
                                 f"actuators: {names}")  # fmt: skip
    for a in range(hs.model.nu):
        force = float(hs.data.actuator_force[a])
        k = 0.0 if stiffness is None else float(stiffness[a])
        if k < 0:
            raise HandModelError(f"actuator {names[a]}: dF/dL = {-k:.3g} > 0 (positive "
                                 "feedback): not a stiffness the grasp model has")  # fmt: skip
        b, why = _actuator_mode(hs, a, mode, servo, k > 0)
        note = f"{why}; K {k:.4g}" if stiffness is not None else why
        acc.add(T.T @ hs.Mh[a], force, force, b,
                HandElement(names[a], "actuator", "backdrivable" if b else "nonbackdrivable",
                            force, force, note), stiffness=k)  # fmt: skip


def _merge_into_actuator(
    hs: HandState, acc: Columns, lname: str, col: NDArray[np.float64], force: float
) -> bool:
    """A loaded stop along a nonbackdrivable actuator's column (a ratchet on the actuated
    joint) is that actuator's passive reaction: its share ``force (col . c_a) / |c_a|^2``
    is added to the actuator's force and the stop listed as merged. False if no actuator
    acts along ``col``."""
    for a in range(hs.model.nu):
        ca = acc.cols[a]
        if acc.back[a] or not _along(ca, col):
            continue
        add = force * float(col @ ca) / float(ca @ ca)
        acc.f_act[a] += add
        acc.elements[_index(acc.elements, hs.actuator_names[a])].force += add
        acc.elements.append(HandElement(f"limit:{lname}", "stop", "merged", force,
                                        note=f"along actuator {hs.actuator_names[a]}: its "
                                        "passive reaction (a ratchet)"))  # fmt: skip
        return True
    return False


def add_active_stops(hs: HandState, T: NDArray[np.float64], acc: Columns) -> None:
    """A one-way stop (command 0) per joint or tendon limit of the hand that carries
    force, unless it merges into an actuator or the equalities lock its motion."""
    model = hs.model
    for r in np.flatnonzero(np.isin(hs.typ, _LIMIT) & hs.touches_hand):
        if hs.frc[r] <= FORCE_ATOL:
            continue
        is_joint = int(hs.typ[r]) == int(_C.mjCNSTR_LIMIT_JOINT)
        obj = mujoco.mjtObj.mjOBJ_JOINT if is_joint else mujoco.mjtObj.mjOBJ_TENDON
        lname = object_name(model, obj, int(hs.eid[r]))
        col = T.T @ hs.E[r, hs.dofs]
        if _merge_into_actuator(hs, acc, lname, col, float(hs.frc[r])):
            continue
        if np.linalg.norm(col) == 0:
            continue  # a limit on a joint the equalities lock: no motion, no column
        acc.add(col, 0.0, float(hs.frc[r]), False,
                HandElement(f"limit:{lname}", "stop", "nonbackdrivable", float(hs.frc[r]), 0.0,
                            "one-way stop, command 0"))  # fmt: skip


def add_gap_stops(
    hs: HandState,
    T: NDArray[np.float64],
    stop_gap: float,
    acc: Columns,
    near_limit: float | None = None,
) -> list[str]:
    """A stop (command 0, no force yet) per joint limit within ``stop_gap`` [rad or m] that
    no nonbackdrivable column blocks already; returns the joints within
    :data:`NEAR_LIMIT` of a limit that got none (for a warning). ``near_limit``
    (``compliance="mujoco"``): stops for the limits within ``max(stop_gap, near_limit)``
    of engaging (:func:`ihm.compliance.limit_gaps`: ``dist - margin``), each with that
    distance as its gap ``g`` (0 where inside the margin); None: gap 0 (the thesis' lock)."""
    model, data, typ, frc = hs.model, hs.data, hs.typ, hs.frc
    active_joints = {int(hs.eid[r]) for r in np.flatnonzero(typ == int(_C.mjCNSTR_LIMIT_JOINT))
                     if frc[r] > FORCE_ATOL}  # fmt: skip
    within = stop_gap if near_limit is None else max(stop_gap, near_limit)
    near: list[str] = []
    for k, j in enumerate(hs.joints):
        if not model.jnt_limited[j] or j in active_joints:
            continue
        q = float(data.qpos[model.jnt_qposadr[j]])
        lo, hi = model.jnt_range[j]
        engage = limit_gaps(model, data, [j])[0]
        for bound, sign, g in ((lo, 1.0, engage[0]), (hi, -1.0, engage[1])):
            gap = sign * (q - bound)  # >= 0 inside the range
            col = T.T @ (sign * np.eye(len(hs.joints))[k])
            if np.linalg.norm(col) == 0 or _blocked(col, acc.cols, acc.back):
                continue  # locked by the equalities, or a nonbackdrivable column holds it
            dist = gap if near_limit is None else float(g)
            if dist <= within:
                g_stop = 0.0 if near_limit is None else max(0.0, float(g))
                note = (f"within stop_gap: {gap:.3g} from its limit" if near_limit is None else
                        f"within {within:g} of engaging: gap {g_stop:.3g}")  # fmt: skip
                acc.add(col, 0.0, 0.0, False,
                        HandElement(f"limit:{hs.jname[k]}", "stop", "nonbackdrivable", 0.0,
                                    0.0, note), gap=g_stop)  # fmt: skip
            elif dist <= NEAR_LIMIT:
                near.append(f"{hs.jname[k]} ({gap:.3g} from its limit)")
    return near


def _add_constant(
    acc: Columns,
    T: NDArray[np.float64],
    tau_full: NDArray[np.float64],
    name: str,
    kind: str,
    note: str,
) -> None:
    """A backdrivable column along the joint torque ``T^T tau_full`` [N m or N] with its
    norm as command; none when the torque is below :data:`FORCE_ATOL`."""
    tau = T.T @ tau_full
    size = float(np.linalg.norm(tau))
    if size <= FORCE_ATOL:
        return
    acc.add(tau / size, size, size, True, HandElement(name, kind, "backdrivable", size, size, note))


def _add_springs(hs: HandState, T: NDArray[np.float64], acc: Columns, stiffness: bool) -> None:
    """One backdrivable column per hand joint ``k`` with a passive spring: along the joint
    torque of its spring at the state, ``T^T e_k s_k``, with its norm as command (none
    below :data:`FORCE_ATOL`). ``stiffness`` (``compliance="mujoco"``): the column also
    carries ``K = K_kk |T^T e_k|^2`` with ``K_kk`` the joint's own ``-d qfrc_spring / d q``
    (the column's motion is ``v = dq_k / |T^T e_k|``), and a spring with no torque at the
    state but a stiffness gets a column ``T^T e_k / |T^T e_k|`` commanded 0. Off-diagonal
    passive stiffness (a tendon spring spanning several joints) is not represented: named
    in the warnings."""
    spring = np.asarray(hs.data.qfrc_spring)[hs.dofs]
    diag = np.zeros(len(hs.joints))
    if stiffness and hs.dofs.size:
        K = passive_stiffness(hs.model, hs.data, hs.dofs)
        diag = np.diag(K).copy()
        off = np.abs(K - np.diag(diag)).max(initial=0.0)
        if off > 1e-6 * max(1.0, float(np.abs(diag).max(initial=0.0))):
            acc.warnings.append(f"passive stiffness coupling the hand joints (tendon springs, "
                                f"up to {off:.3g}): only each joint's own is modelled")  # fmt: skip
    for k in np.flatnonzero((np.abs(spring) > FORCE_ATOL) | (diag > FORCE_ATOL)):
        e = np.zeros(len(hs.joints))
        e[k] = 1.0
        tk = T.T @ e
        n = float(np.linalg.norm(tk))
        tau = T.T @ (e * spring[k])
        size = float(np.linalg.norm(tau))
        K_a = max(0.0, float(diag[k])) * n**2
        if size > FORCE_ATOL:
            col = tau / size
        elif K_a > 0:
            col, size = tk / n, 0.0
        else:
            continue  # no torque to keep, no stiffness (or a joint the equalities lock)
        note = (f"its torque at the state; stiffness K {K_a:.4g}" if stiffness
                else "its torque at the state; stiffness not modelled")  # fmt: skip
        acc.add(col, size, size, True,
                HandElement(f"spring:{hs.jname[k]}", "spring", "backdrivable", size, size, note),
                stiffness=K_a)  # fmt: skip


def add_constant_torques(
    hs: HandState, T: NDArray[np.float64], acc: Columns, spring_stiffness: bool = False
) -> None:
    """Passive springs (one column per joint, :func:`_add_springs`; with their stiffness
    when ``spring_stiffness``, ``compliance="mujoco"``), the links' weight at rest,
    ``qfrc_applied`` and ``xfrc_applied`` on hand bodies, as constant torques at the
    state."""
    model, data, dofs = hs.model, hs.data, hs.dofs
    _add_springs(hs, T, acc, spring_stiffness)
    weight = (np.asarray(data.qfrc_gravcomp) - np.asarray(data.qfrc_bias))[dofs]
    _add_constant(acc, T, weight, "gravity", "gravity", "the links' own weight (at rest)")
    _add_constant(acc, T, np.asarray(data.qfrc_applied)[dofs], "applied", "applied",
                  "qfrc_applied")  # fmt: skip
    hand_bodies = ~hs.in_obj
    if np.any(data.xfrc_applied[hand_bodies] != 0):
        xf = np.zeros(model.nv)
        for b in np.flatnonzero(hand_bodies):
            if np.any(data.xfrc_applied[b] != 0):
                mujoco.mj_applyFT(model, data, data.xfrc_applied[b, :3], data.xfrc_applied[b, 3:],
                                  data.xipos[b], int(b), xf)  # fmt: skip
        _add_constant(acc, T, xf[dofs], "xfrc_applied", "applied", "xfrc_applied on hand bodies")


def _blocked(col: NDArray[np.float64], cols: list[NDArray[np.float64]], back: list[bool]) -> bool:
    """A nonbackdrivable column (actuator or stop) acts along ``col``, the same way: the
    motion a stop along ``col`` would block is blocked already."""
    return any(not b and _along(c, col) for c, b in zip(cols, back, strict=True))


def _along(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """``a`` and ``b`` are non-zero and point the same way (to 1e-9 in the cosine)."""
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return bool(na > 0 and nb > 0 and a @ b >= (1 - 1e-9) * na * nb)


def _index(elements: list[HandElement], name: str) -> int:
    for k, e in enumerate(elements):
        if e.name == name and e.kind == "actuator":
            return k
    raise KeyError(name)
