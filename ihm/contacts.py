"""MuJoCo contact data to a spatial :class:`stability.Grasp`.

Conventions (docs/design.md, Conventions): everything is expressed in the *object
frame*, the frame of the MuJoCo body ``object_body`` (origin at the body origin, axes of
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

The hand (:mod:`ihm.handmodel`): closed linkages (every active ``connect``, ``weld``,
``joint`` and ``tendon`` equality among hand bodies) are folded into independent
coordinates, ``q_full = T q`` with ``J = J_full T`` and ``R = T^T R_full``; active joint
and tendon limits become one-way stops (columns of ``R`` commanded 0); saturated
actuators, passive springs and the links' weight become constant force sources
(backdrivable columns). What the model leaves out (dry joint friction, hand contacts
with anything but the object) is warned about by name, and the hand-equilibrium
residual ``J^T c - R f`` with MuJoCo's own forces is checked: above ``hand_rtol`` of the
joint torques it raises.

Merging contacts: MuJoCo may report the same touch point more than once (box-box at a
vertex; two geoms of one link whose faces meet, such as a pad made of two boxes or a pad
and its silicone layer). Contacts between the same *hand body* and *object body* whose
points lie within ``merge_tol`` [m] (default 0.1 mm) and whose normals agree within
``1e-3`` rad are merged into one: the point is their mean, the frame the first one's,
the force their sum, the friction the smallest. Distinct points of a line or face
contact stay distinct, as in the thesis' point-contact model.

Reducing a patch (optional): a face contact reported as many points (a pad on a box
face) costs the 3D solvers time exponential in the contact count. A patch is the
contacts of one hand body and object body with normals within 1e-3 rad.

* ``reduce="line"``: each patch to two points on the line through its centre of
  pressure (where its normal forces have no in-plane moment) along its longest extent
  (principal axis), where that line leaves the patch (the convex hull of its points).
  The two forces carry the patch's whole wrench exactly (coplanar points), so both
  equilibria hold with MuJoCo's forces. Torsional friction about the normal then has
  the lever of the line's half-length only (the patch's width in the other direction
  is lost: conservative); where MuJoCo's state needs more torsion than that, a
  :class:`HandModelWarning` says so (reduced forces outside the cone are checked for
  either reduction). A strip narrower than 10 um is reduced to its ends.
* ``reduce="rect"``: the line's two ends, each split across the line to where the patch
  ends on either side (four points per patch, the corners of a rectangular pad), the
  end's force and stiffness shared by the lever rule (the patch's wrench kept). The
  patch's width is kept as a lever for torsion about the normal: a pad whose centre of
  pressure is off the load's line needs it (``linkage_box`` along x with
  ``compliance="mujoco"``: the line gives 2.9 % less than MuJoCo, these 1e-4 more).
* ``reduce="extremes"``: at most ``patch_points`` of MuJoCo's points, chosen farthest
  first (the two farthest apart, the one whose triangle with them holds the centre of
  pressure deepest, then the farthest from those). A dropped point's
  force is added to the nearest kept point, then the kept forces are corrected (least
  change, pseudo-inverse) to carry the patch's wrench: exactly with three or more
  points; with two, the in-plane moment across their line is lost (the residuals show
  it, and the hand check may refuse the grasp).

The effect of each reduction on the answers is measured in ``docs/linkage.md``.

Compliance: ``compliance="unit"`` (default) is the thesis' model, unit virtual springs at
the contacts and rigid actuators and stops; ``compliance="mujoco"`` gives the grasp
MuJoCo's own stiffness in physical units (``Grasp(stiffness=, actuator_stiffness=,
stop_gap=)``): each contact the normal stiffness of the MuJoCo contacts it stands for
(:mod:`ihm.compliance`, summed as :mod:`ihm.patches` says), servos and springs their
stiffness, limits near the state their gaps. What each MJCF element becomes under either
mode: the table in :mod:`ihm.compliance`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stability import Grasp, GraspError

from .compliance import contact_depth, contact_stiffness
from .contact_law import CONTACT_LAWS, LAW_SPAN, law_pieces
from .handmodel import (
    NEAR_LIMIT,
    HandElement,
    HandModel,
    HandModelError,
    hand_joints,
    hand_model,
    transmission,
)
from .near import near_contacts, widened
from .patches import ContactGroup, ContactLaw, merge_contacts, reduce_patches

__all__ = [
    "HandModelError",
    "HandModelWarning",
    "HandOptions",
    "MujocoSource",
    "SceneGrasp",
    "body_subtree",
    "contact_frame_force",
    "grasp_from_mujoco",
    "hand_coordinates",
    "object_contact_ids",
    "transmission",
]


@dataclass(frozen=True)
class HandOptions:
    """How :func:`grasp_from_mujoco` models the hand (:func:`ihm.handmodel.hand_model`).

    backdrivable : None (force-saturated actuators only), True/False (every actuator), or
        the names of the backdrivable actuators
    servo : how an unsaturated position servo enters: ``"nonbackdrivable"`` or ``"force"``
    stop_gap : a joint limit this close [rad or m] that carries no force yet is a stop too
    spring_held : a passive motion held by springs alone raises :class:`HandModelError`
        (``"raise"``) or is modelled with the springs as constant torques and a warning
        (``"warn"``); not used with ``compliance="mujoco"`` (the springs' stiffness holds)
    near_limit : with ``compliance="mujoco"``, a joint limit within ``max(stop_gap,
        near_limit)`` [rad or m] of engaging is a stop with that distance as its gap
    """

    backdrivable: bool | tuple[str, ...] | None = None
    servo: str = "nonbackdrivable"
    stop_gap: float = 0.0
    spring_held: str = "raise"
    near_limit: float = NEAR_LIMIT


@dataclass(frozen=True)
class MujocoSource:
    """Where a :class:`SceneGrasp` came from: what MuJoCo reported at the state it was read
    at, per contact ``k`` of the grasp (object frame, SI units).

    forces : (m, 3) contact forces MuJoCo computed, ``(c_n, c_t1, c_t2)`` [N]
    hand : the :class:`ihm.handmodel.HandModel` (``T``, columns of ``R``, their commands
        and actual forces, dependent joints, warnings)
    hand_residual : ``max |J^T c - R f| / max |J^T c|`` with MuJoCo's forces
    gravity_wrench : (6,) gravity's wrench on the object about the object origin
        ``(f, torque)`` [N, N m]
    hand_bodies : (m,) MuJoCo body id of the hand link at each contact
    hand_geoms, object_geoms : (m,) MuJoCo geom ids at each contact
    contact_ids : per contact, the MuJoCo contact indices merged into it
    object_pos, object_mat : the object frame in world coordinates: origin [m] and
        rotation (columns the object's axes)
    object_com : (3,) the object body's centre of mass in the object frame [m] (the point
        whose displacement :mod:`ihm.resistance` measures)
    gaps : (m,) per contact how far it is from engaging [m]: 0 for a touching contact, the
        gap of a near contact (``grasp_from_mujoco(near=)``, :mod:`ihm.near`)
    near : (m,) booleans, True for a near contact (no MuJoCo contact behind it) and for
        the pieces of one
    piece_of : (m,) per contact the contact whose fitted law it is a piece of
        (``grasp_from_mujoco(contact_law="fitted")``, :mod:`ihm.contact_law`): its own
        index for a contact read off MuJoCo, the base contact's for a piece, which has the
        base's point and frame, no force and the gap where its step of the law starts
    """

    forces: NDArray[np.float64]
    hand: HandModel
    hand_residual: float
    gravity_wrench: NDArray[np.float64]
    hand_bodies: NDArray[np.int64]
    hand_geoms: NDArray[np.int64]
    object_geoms: NDArray[np.int64]
    contact_ids: list[list[int]]
    object_pos: NDArray[np.float64]
    object_mat: NDArray[np.float64]
    object_com: NDArray[np.float64]
    gaps: NDArray[np.float64] | None = None
    near: NDArray[np.bool_] | None = None
    piece_of: NDArray[np.int64] | None = None


class _FromSource:
    """A read-only attribute of :class:`SceneGrasp`: the field of the same name of its
    :class:`MujocoSource`."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, grasp: SceneGrasp | None, owner: type | None = None) -> Any:
        return self if grasp is None else getattr(grasp.source, self.name)


class SceneGrasp(Grasp):
    """A :class:`stability.Grasp` read off a MuJoCo state, with what MuJoCo reported.

    ``source`` (:class:`MujocoSource`) records that state; its fields are also read-only
    attributes of the grasp (``grasp.forces`` is ``grasp.source.forces``), and so are
    these, from ``source.hand`` (:class:`ihm.handmodel.HandModel`):

    commands : (a,) ``f_c`` per column of ``R``: actuators their force at this state
        (``data.actuator_force``) [N m for joint actuators, N for tendons], stops 0,
        constant torques (springs, link weight) their torque [N m]
    actuator_forces : (a,) the columns' actual forces at this state (a stop's limit
        force, an actuator's force plus a ratchet's passive reaction)
    actuator_names : names of the ``a`` columns of ``R`` (actuators, ``limit:<joint>``,
        ``spring:<joint>``, ``gravity``, ``applied``)
    elements : :class:`ihm.handmodel.HandElement` per column and folded equality
    joint_names : names of the ``l`` independent hand joints (columns of ``J``)
    T : (nv_hand, l) independent-to-full hand joint map (coupled joints)
    hand_dofs : (nv_hand,) MuJoCo dof indices of the hand
    """

    forces = _FromSource()
    hand = _FromSource()
    hand_residual = _FromSource()
    gravity_wrench = _FromSource()
    hand_bodies = _FromSource()
    hand_geoms = _FromSource()
    object_geoms = _FromSource()
    contact_ids = _FromSource()
    object_pos = _FromSource()
    object_mat = _FromSource()
    object_com = _FromSource()
    gaps = _FromSource()
    near = _FromSource()
    piece_of = _FromSource()

    def __init__(self, *, source: MujocoSource, **grasp: Any) -> None:
        """``grasp``: :class:`stability.Grasp`'s arguments; ``source``: the MuJoCo record."""
        super().__init__(**grasp)
        self._source = source

    @property
    def source(self) -> MujocoSource:
        """What MuJoCo reported at the state this grasp was read at."""
        return self._source

    @property
    def commands(self) -> NDArray[np.float64]:
        return self.source.hand.commands

    @property
    def actuator_forces(self) -> NDArray[np.float64]:
        return self.source.hand.forces

    @property
    def actuator_names(self) -> list[str]:
        return self.source.hand.names

    @property
    def elements(self) -> list[HandElement]:
        return self.source.hand.elements

    @property
    def joint_names(self) -> list[str]:
        return self.source.hand.joint_names

    @property
    def T(self) -> NDArray[np.float64]:  # noqa: N802 (the thesis' symbol)
        return self.source.hand.T

    @property
    def hand_dofs(self) -> NDArray[np.int64]:
        return self.source.hand.dofs

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
        ``hand``: ``max |J^T c - R f|`` with ``f`` the columns' actual forces
        (``actuator_forces``; hand equilibrium over the independent joints).
        """
        c = self.forces.reshape(-1)
        return {
            "object": float(np.abs(self.G @ c + self.gravity_wrench).max()),
            "hand": float(np.abs(self.J.T @ c - self.R @ self.actuator_forces).max()),
        }

    def command_range(
        self, upper: float | ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(lower, upper)`` for :class:`stability.OptimalCommands` over the columns of ``R``:
        the actuators free in ``[0, upper]`` (``upper`` per actuator or one number; default
        no bound, ``inf``), every other column (stops, springs, weight) pinned at its
        command."""
        act = self.hand.actuated
        lo = np.where(act, 0.0, self.commands)
        hi = self.commands.copy()
        hi[act] = np.inf if upper is None else np.broadcast_to(np.asarray(upper, float),
                                                               (int(act.sum()),))  # fmt: skip
        return lo, hi

    def full_commands(self, actuator_commands: ArrayLike) -> NDArray[np.float64]:
        """Commands for every column of ``R`` from one command per MuJoCo actuator (the
        scene's ``ihm_preload`` order): the actuators' columns get them, every other
        column (stops, springs, weight) keeps its own command. Commands already one per
        column pass through."""
        f = np.asarray(actuator_commands, dtype=float).reshape(-1)
        act = self.hand.actuated
        if f.shape == self.commands.shape:
            return f
        if f.size != int(act.sum()):
            raise GraspError(f"commands: {f.size} values for {int(act.sum())} actuators "
                             f"({self.commands.size} columns of R)")  # fmt: skip
        out = self.commands.copy()
        out[act] = f
        return out

    def command_weights(self) -> NDArray[np.float64]:
        """Weights for ``OptimalCommands(objective="weighted", weights=...)``: 1 per
        actuator, 0 for every pinned column (stops, springs, weight), so that only the
        commands one sets are minimised (the ``"max"`` objective would also count the
        pinned columns' commands)."""
        return self.hand.actuated.astype(float)

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


def object_contact_ids(
    data: mujoco.MjData, geom_is_object: list[bool]
) -> list[tuple[int, int, bool]]:
    """The object's active contacts in ``data.contact``: ``(i, other, object_is_geom1)`` for
    each contact ``i`` with constraint rows (``efc_address >= 0``, not excluded) between a
    geom of the object and one that is not (``other``: that geom's id). ``geom_is_object``
    (per geom, a plain list for speed: ``in_obj[model.geom_bodyid].tolist()`` for the
    object's subtree) says which geoms are the object's. The one reader of the object's
    contacts: grasps, recordings, shields, env observations and the shield benchmarks."""
    if data.ncon == 0:
        return []
    c = data.contact
    out = []
    for i, ((g1, g2), adr, ex) in enumerate(
        zip(c.geom.tolist(), c.efc_address.tolist(), c.exclude.tolist(), strict=True)
    ):
        if adr < 0 or ex:
            continue
        o1, o2 = geom_is_object[g1], geom_is_object[g2]
        if o1 != o2:
            out.append((i, g2 if o1 else g1, o1))
    return out


def hand_coordinates(
    model: mujoco.MjModel, data: mujoco.MjData, object_body: str = "object"
) -> tuple[NDArray[np.int64], NDArray[np.float64], list[str]]:
    """The hand's dofs and its independent coordinates (after ``mj_forward``).

    Returns ``(hand_dofs, T, names)``: the MuJoCo dof indices of every hinge or slide
    joint outside the object's subtree, the map ``T`` (len(hand_dofs) x l) with
    ``qvel[hand_dofs] = T qdot`` under the hand's active equality constraints
    (:mod:`ihm.handmodel`), and the names of the ``l`` independent joints.
    """
    in_obj = body_subtree(model, _body_id(model, object_body))
    hm = hand_model(model, data, in_obj)
    return hm.dofs, hm.T, hm.joint_names


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


def _read(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    in_obj: NDArray[np.bool_],
    stiffness: bool,
) -> list[ContactGroup]:
    """One :class:`ContactGroup` per active object contact (:func:`object_contact_ids`), with
    its normal stiffness (:func:`ihm.compliance.contact_stiffness`) and static law
    (``ContactGroup.law``) if ``stiffness``;
    :class:`GraspError` for a contact with torsional or rolling friction."""
    out = []
    for i, hand_geom, obj_first in object_contact_ids(data, in_obj[model.geom_bodyid].tolist()):
        con = data.contact[i]
        if con.dim > 3:
            raise GraspError(
                f"contact {i} ({model.geom(con.geom1).name or con.geom1} / "
                f"{model.geom(con.geom2).name or con.geom2}) has condim {con.dim}: torsional or "
                "rolling friction is not in the point-contact model; use condim 1 or 3"
            )
        frame, force = contact_frame_force(model, data, i, obj_first)
        obj_geom = con.geom1 if obj_first else con.geom2
        bodies = (int(model.geom_bodyid[hand_geom]), int(model.geom_bodyid[obj_geom]))
        mu = 0.0 if con.dim == 1 else float(con.friction[0])
        k = float(contact_stiffness(model, data, [i])[0]) if stiffness else 0.0
        law = ContactLaw.of(con, contact_depth(data, i)) if stiffness else None
        out.append(ContactGroup((int(hand_geom), int(obj_geom)), bodies, [con.pos.copy()],
                                frame, frame.T @ force, mu, [i], k, law))  # fmt: skip
    return out


def grasp_from_mujoco(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    object_body: str = "object",
    *,
    merge_tol: float = 1e-4,
    reduce: str | None = None,
    patch_points: int = 3,
    hand: HandOptions | None = None,
    hand_rtol: float = 0.02,
    compliance: str = "unit",
    near: float = 0.0,
    contact_law: str = "slope",
) -> SceneGrasp:
    """Read the grasp of ``object_body`` off a MuJoCo state (after ``mj_forward``).

    One contact per active MuJoCo contact between the object's subtree and any
    other body (the hand; a static body counts as a fixed finger with zero
    Jacobian rows), duplicates merged and patches optionally reduced (module
    docstring; ``reduce``: None, ``"line"``, ``"rect"`` or ``"extremes"`` with
    ``patch_points``).
    Friction is MuJoCo's sliding friction of the contact
    (``contact.friction[0]``; 0 for a frictionless ``condim=1`` contact; ``condim``
    4 or 6, with torsional or rolling friction, is refused). The hand's equalities,
    limits, springs and saturated actuators are modelled as :mod:`ihm.handmodel`
    says (``hand``: :class:`HandOptions`, default ``HandOptions()``);
    ``grasp.elements`` lists each, ``grasp.commands`` holds ``f_c`` per column of ``R``
    (actuators: their force at the state; stops: 0; constant torques: the torque).

    The hand equilibrium ``J^T c = R f`` with MuJoCo's contact forces and the actual
    column forces ``f`` (a stop's limit force, an actuator's force plus a ratchet's
    reaction) is checked: ``grasp.hand_residual`` is ``max |J^T c - R f|`` over the
    joints divided by the largest joint torque ``max |J^T c|``; above ``hand_rtol`` it
    raises, naming what the model leaves out. Unmodelled elements warn
    (:class:`HandModelWarning`). ``compliance``: ``"unit"`` (default; the thesis' unit
    springs, rigid actuators and stops) or ``"mujoco"`` (MuJoCo's contact, servo and
    spring stiffness and the limits' gaps in physical units: module docstring). ``near``
    [m] (``compliance="mujoco"`` only; default 0, none): points of the hand within
    ``near`` of the object that do not touch it yet (MuJoCo's collision with ``near`` more
    margin) become contacts too, with force 0, MuJoCo's stiffness as they engage and their
    gap in ``grasp.gaps`` (:mod:`ihm.near`); they come after the touching contacts.
    ``contact_law`` (``compliance="mujoco"`` only): ``"slope"`` (default) makes each contact
    a linear spring of its slope at the state; ``"fitted"`` follows MuJoCo's static law,
    which stiffens as a contact presses, as a convex piecewise-linear spring over
    :data:`ihm.contact_law.LAW_SPAN` past the state (:mod:`ihm.contact_law`): each contact
    keeps the law's first slope, and each further slope step is a co-located contact
    (``grasp.piece_of``) with no force and a gap in ``grasp.gaps``, after all the others.

    Raises
    ------
    GraspError
        No body ``object_body``; no active contact between it and the hand; a
        contact with torsional/rolling friction (condim > 3); a bad option.
    HandModelError
        A hand joint that is not a hinge or slide; an equality tying the hand to the
        object; a passive motion held by springs alone (``spring_held="raise"``); a
        hand-equilibrium residual above ``hand_rtol``.
    """
    if not (isinstance(merge_tol, (int, float)) and np.isfinite(merge_tol) and merge_tol >= 0):
        raise GraspError(f"merge_tol must be a finite number >= 0 [m], got {merge_tol!r}")
    if reduce not in (None, "extremes", "line", "rect"):
        raise GraspError(f"reduce must be None, 'extremes', 'line' or 'rect', got {reduce!r}")
    if not isinstance(patch_points, (int, np.integer)) or patch_points < 1:
        raise GraspError(f"patch_points must be an integer >= 1, got {patch_points!r}")
    if not (np.isfinite(hand_rtol) and hand_rtol > 0):
        raise GraspError(f"hand_rtol must be a finite number > 0, got {hand_rtol!r}")
    if compliance not in ("unit", "mujoco"):
        raise GraspError(f"compliance must be 'unit' or 'mujoco', got {compliance!r}")
    if not (isinstance(near, (int, float)) and np.isfinite(near) and near >= 0):
        raise GraspError(f"near must be a finite number >= 0 [m], got {near!r}")
    if contact_law not in CONTACT_LAWS:
        raise GraspError(
            f"contact_law must be {' or '.join(map(repr, CONTACT_LAWS))}, got {contact_law!r}"
        )
    if (near > 0 or contact_law != "slope") and compliance != "mujoco":
        raise GraspError("near contacts and contact_law='fitted' need compliance='mujoco': "
                         "they are MuJoCo's lengths and law, which the thesis' unit springs "
                         "do not have")  # fmt: skip
    mj = compliance == "mujoco"
    obj = _body_id(model, object_body)
    in_obj = body_subtree(model, obj)
    hand_joints(model, in_obj)  # a ball or free joint in the hand: refused before anything
    x_o = data.xpos[obj].copy()
    R_o = data.xmat[obj].reshape(3, 3).copy()

    groups = merge_contacts(_read(model, data, in_obj, mj), merge_tol)
    if not groups:
        raise GraspError(
            f"no active contact between body {object_body!r} and the hand "
            f"({data.ncon} MuJoCo contacts in all); settle the grasp first"
        )
    if reduce is not None:
        groups = reduce_patches(groups, {"line": 0, "rect": -1}.get(reduce, patch_points))
    gaps = np.zeros(len(groups))
    n_near = 0
    if near > 0:
        m2, d2 = widened(model, data, in_obj, float(near))
        extra, extra_gaps = near_contacts(_read(m2, d2, in_obj, False), d2, float(near), mj,
                                          merge_tol)  # fmt: skip
        groups = groups + extra
        n_near = len(extra)
        gaps = np.r_[gaps, extra_gaps]
    is_near = np.arange(len(groups)) >= len(groups) - n_near
    owner = np.arange(len(groups))
    if contact_law == "fitted":
        groups, gaps, owner = law_pieces(groups, gaps, LAW_SPAN)
        is_near = is_near[owner]

    ho = HandOptions() if hand is None else hand
    hm = hand_model(model, data, in_obj, backdrivable=ho.backdrivable, servo=ho.servo,
                    stop_gap=ho.stop_gap, spring_held=ho.spring_held, compliance=compliance,
                    near_limit=ho.near_limit,
                    object_contacts=[i for g in groups for i in g.ids])  # fmt: skip
    pts_w = np.array([np.mean(g.pos, axis=0) for g in groups])
    frames_w = np.array([g.frame for g in groups])  # (m, 3, 3) rows n, t1, t2
    forces = np.einsum("mkj,mj->mk", frames_w, np.array([g.force_world for g in groups]))
    hand_geoms = np.array([g.pair[0] for g in groups], dtype=np.int64)
    hand_bodies = model.geom_bodyid[hand_geoms].astype(np.int64)
    if reduce is not None:  # can the reduced points carry MuJoCo's state?
        _warn_outside_cone(model, groups, forces, hand_bodies, reduce)
    J = _hand_jacobian(model, data, pts_w, frames_w, hand_bodies, hm)
    pts_o = (pts_w - x_o) @ R_o
    frames_o = frames_w @ R_o  # each row v -> R_o^T v
    for w in hm.warnings:
        warnings.warn(f"grasp_from_mujoco: not in the grasp model: {w}", HandModelWarning,
                      stacklevel=2)  # fmt: skip
    mass = model.body_subtreemass[obj]
    f_g = mass * model.opt.gravity
    tau_g = np.cross(data.subtree_com[obj] - x_o, f_g)
    source = MujocoSource(
        forces=forces,
        hand=hm,
        hand_residual=_hand_residual(J, forces, hm, hand_rtol),
        gravity_wrench=np.concatenate([R_o.T @ f_g, R_o.T @ tau_g]),
        hand_bodies=hand_bodies,
        hand_geoms=hand_geoms,
        object_geoms=np.array([g.pair[1] for g in groups], dtype=np.int64),
        contact_ids=[g.ids for g in groups],
        object_pos=x_o,
        object_mat=R_o,
        object_com=R_o.T @ (data.xipos[obj] - x_o),
        gaps=gaps,
        near=is_near,
        piece_of=owner,
    )
    physical = (dict(stiffness=[g.stiffness for g in groups], actuator_stiffness=hm.stiffness,
                     stop_gap=hm.gaps) if mj else {})  # fmt: skip
    return SceneGrasp(
        points=pts_o,
        normals=frames_o[:, 0],
        mu=[g.mu for g in groups],
        tangents=frames_o[:, 1:],
        J=J,
        R=hm.R,
        backdrivable=hm.backdrivable,
        source=source,
        **physical,
    )


def _warn_outside_cone(model: mujoco.MjModel, groups: list[ContactGroup],
                       forces: NDArray[np.float64], hand_bodies: NDArray[np.int64],
                       reduce: str) -> None:  # fmt: skip
    """A :class:`HandModelWarning` for each reduced point whose force (contact frame, [N])
    is outside its friction cone: the reduced grasp cannot carry MuJoCo's state there."""
    mu = np.array([g.mu for g in groups])
    tang = np.linalg.norm(forces[:, 1:], axis=1)
    scale = 1e-6 * (1.0 + float(np.abs(forces).max()))
    bad = np.flatnonzero((forces[:, 0] < -scale) | (tang > mu * forces[:, 0] + scale))
    for k in bad:
        warnings.warn(
            f"grasp_from_mujoco(reduce={reduce!r}): the patch on "
            f"{model.body(int(hand_bodies[k])).name} needs a force outside the friction "
            f"cone at a reduced point (c_n {forces[k, 0]:.3g} N, |c_t| {tang[k]:.3g} N, mu "
            f"{mu[k]:g}): the reduced grasp cannot carry MuJoCo's state (torsion about the "
            "normal, or a centre of pressure outside the kept points); use more points",
            HandModelWarning,
            stacklevel=3,
        )


def _hand_jacobian(model: mujoco.MjModel, data: mujoco.MjData, pts_w: NDArray[np.float64],
                   frames_w: NDArray[np.float64], hand_bodies: NDArray[np.int64],
                   hm: HandModel) -> NDArray[np.float64]:  # fmt: skip
    """``J`` (3m x l): each contact's rows (its frame n, t1, t2) of the hand link's point
    Jacobian at the contact, over the independent joints (``hm.T``)."""
    J = np.zeros((3 * len(pts_w), hm.T.shape[1]))
    jacp = np.zeros((3, model.nv))
    for k in range(len(pts_w)):
        mujoco.mj_jac(model, data, jacp, None, pts_w[k], int(hand_bodies[k]))
        J[3 * k : 3 * k + 3] = frames_w[k] @ jacp[:, hm.dofs] @ hm.T
    return J


def _hand_residual(J: NDArray[np.float64], forces: NDArray[np.float64], hm: HandModel,
                   hand_rtol: float) -> float:  # fmt: skip
    """``max |J^T c - R f| / max |J^T c|`` with MuJoCo's contact forces ``c`` and the columns'
    actual forces ``f``; :class:`HandModelError` above ``hand_rtol``, naming the joint and
    what the model leaves out."""
    torque = np.abs(J.T @ forces.reshape(-1))
    res = np.abs(J.T @ forces.reshape(-1) - hm.R @ hm.forces)
    rel = float(res.max(initial=0.0) / max(float(torque.max(initial=0.0)), 1e-9))
    if rel > hand_rtol:
        k = int(np.argmax(res))
        raise HandModelError(
            f"hand equilibrium J^T c = R f does not hold with MuJoCo's forces: residual "
            f"{res[k]:.3g} at joint {hm.joint_names[k]} ({rel:.1%} of the "
            f"largest joint torque {torque.max():.3g}; hand_rtol {hand_rtol:g}). Left out of "
            f"the model: {'; '.join(hm.warnings) or 'nothing named (is the hand at rest?)'}"
        )
    return rel


class HandModelWarning(UserWarning):
    """An element of the hand that the grasp model leaves out (named in the message)."""
