"""The four-finger rotation env's physics: the scene's model with the env's settings, and
:class:`Physics`, the model, data and index arrays of the env's fast observation path.

``timestep`` 0.002 s, ``frame_skip`` 25 substeps per policy step (20 Hz, the
thesis' policy rate); the hand model's own timestep is 0.001 s, and
``python -m envs.bench`` compares the two (the policy sees the same motion).
Contacts with torsional friction (``condim`` 4, see ``torsional``). Elliptic friction cone
with ``impratio`` 100 and no noslip pass (see the hand model's "Physics" note), solved by PGS
instead of the model's Newton solver: the same convex problem, 5x cheaper to solve here, to a
tolerance of 1e-4 (``SOLVER_TOLERANCE``; MuJoCo's 1e-8 takes about 60 % more iterations, and
one policy step differs from it by under 1 % of what halving the timestep changes: tested;
at rest it changes MuJoCo's creep of a held object by up to 1e-4 m/s per contact;
docs/bench/four_finger_env.md). The 34 contacts the scene's ``contype``/``conaffinity`` allow (the
object with the 8 links, palm and catch plane; links of different fingers) are explicit
``<pair>``s with the parameters MuJoCo would mix for them, so that no broadphase runs: the
same contacts in the same order with the same parameters, hence the same motion bit for bit
(tested), in about 5 % less time per step.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

import ihm.scenes
from ihm.contacts import object_contact_ids
from ihm.hands import four_finger as ff

__all__ = [
    "CONTACT_LINKS",
    "DROP_Z",
    "FRAME_SKIP",
    "HELDOUT_OBJECTS",
    "MAX_FORCE",
    "OBJECTS",
    "OUT_RADIUS",
    "SOLVERS",
    "SOLVER_TOLERANCE",
    "TIMESTEP",
    "TORSIONAL_FRICTION",
    "TRAIN_OBJECTS",
    "FourFingerError",
    "Physics",
    "dynamic_pairs",
    "mixed_contact",
    "scene_name",
]

TRAIN_OBJECTS = ("sphere", "cylinder", "cube")
"""The objects the shipped policies were trained on (70 mm wide, 0.1 kg)."""
HELDOUT_OBJECTS = ("capsule", "ellipsoid")
"""Objects no shipped policy was trained on, for evaluation (``python -m train.heldout
--object``): an upright capsule 60 mm wide and an ellipsoid of 80 x 66 x 60 mm, 0.1 kg each
(the scenes ``four_finger_capsule`` and ``four_finger_ellipsoid``)."""
OBJECTS = TRAIN_OBJECTS + HELDOUT_OBJECTS
CONTACT_LINKS = ff.BODY_NAMES  # f1_proximal, f1_distal, ..., f4_distal: observed links
DROP_Z = 0.05  # [m] object centre below this: dropped
OUT_RADIUS = 0.045  # [m] object centre farther than this from the palm axis: out of the hand
TORSIONAL_FRICTION = 0.005  # [m] the collision class' friction[1]; acts with torsional=True
MAX_FORCE = 50.0  # [N] observed normal forces are clipped here (impact spikes only)


class FourFingerError(ValueError):
    """Bad option or action of :class:`FourFingerRotate` (unknown object, wrong shape, NaN)."""


def scene_name(obj: str) -> str:
    """The scene of object ``obj`` (``four_finger_<obj>``); :class:`FourFingerError` if unknown."""
    if obj not in OBJECTS:
        raise FourFingerError(f"unknown object {obj!r}; choose one of {', '.join(OBJECTS)}")
    return f"four_finger_{obj}"


SOLVERS = {"pgs": mujoco.mjtSolver.mjSOL_PGS, "newton": mujoco.mjtSolver.mjSOL_NEWTON}
TIMESTEP = 0.002  # s: 5 steps per contact time constant (solref 0.01 s)
FRAME_SKIP = 25  # substeps per policy step: dt = 0.05 s, 20 Hz
SOLVER_TOLERANCE = 1e-4  # PGS; MuJoCo's 1e-8: ~60 % more iterations, no change the policy sees


def mixed_contact(m: mujoco.MjModel, g1: int, g2: int) -> dict[str, Any]:
    """The contact parameters MuJoCo gives a dynamic contact of geoms ``g1, g2``.

    MuJoCo's rules (``mj_contactParam``): a geom of higher ``priority`` gives all of them;
    at equal priority ``condim`` and friction are the maxima, ``solref`` and ``solimp`` the
    ``solmix``-weighted means (``solref`` in the direct, negative format: the minimum). The
    margins and gaps must be zero (as in the scenes): MuJoCo 3.3 takes the larger margin,
    3.17 and 4.0 add them."""
    if m.geom_margin[[g1, g2]].any() or m.geom_gap[[g1, g2]].any():
        raise FourFingerError(
            f"geoms {g1} and {g2} have a margin or gap; explicit pairs expect none (MuJoCo's "
            "mixing of margins differs between versions)"
        )
    if m.geom_priority[g1] != m.geom_priority[g2]:
        g = g1 if m.geom_priority[g1] > m.geom_priority[g2] else g2
        condim, fr = int(m.geom_condim[g]), m.geom_friction[g]
        solref, solimp = m.geom_solref[g].copy(), m.geom_solimp[g].copy()
    else:
        condim = int(max(m.geom_condim[g1], m.geom_condim[g2]))
        fr = np.maximum(m.geom_friction[g1], m.geom_friction[g2])
        s1, s2 = m.geom_solmix[g1], m.geom_solmix[g2]
        tiny = mujoco.mjMINVAL
        if s1 >= tiny and s2 >= tiny:
            mix = s1 / (s1 + s2)
        else:
            mix = 0.5 if s1 < tiny and s2 < tiny else (0.0 if s1 < tiny else 1.0)
        r1, r2 = m.geom_solref[g1], m.geom_solref[g2]
        if r1[0] > 0 and r2[0] > 0:
            solref = mix * r1 + (1 - mix) * r2
        else:
            solref = np.minimum(r1, r2)
        solimp = mix * m.geom_solimp[g1] + (1 - mix) * m.geom_solimp[g2]
    return {
        "condim": condim,
        "friction": [fr[0], fr[0], fr[1], fr[2], fr[2]],
        "solref": solref,
        "solimp": solimp,
    }


def dynamic_pairs(m: mujoco.MjModel) -> list[tuple[int, int]]:
    """Every geom pair that MuJoCo's broadphase may pass to collision (``g1 < g2``).

    MuJoCo's filters (``mj_collision``): ``contype``/``conaffinity`` compatible, on bodies
    that are not welded together, not parent and child (the ``filterparent`` rule, which
    spares the world body, unless disabled), and not excluded by ``<exclude>``. Scenes with
    explicit pairs or mocap bodies (which MuJoCo filters further) are refused."""
    if m.npair or m.nmocap:
        raise FourFingerError(
            "the scene has explicit <pair>s or mocap bodies; the env expects none"
        )
    filterparent = not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    weld, parent = m.body_weldid, m.body_parentid
    excluded = {(int(b >> 16), int(b & 0xFFFF)) for b in m.exclude_signature}
    out = []
    for g1 in range(m.ngeom):
        for g2 in range(g1 + 1, m.ngeom):
            if not (
                m.geom_contype[g1] & m.geom_conaffinity[g2]
                or m.geom_contype[g2] & m.geom_conaffinity[g1]
            ):
                continue
            b1, b2 = int(m.geom_bodyid[g1]), int(m.geom_bodyid[g2])
            w1, w2 = int(weld[b1]), int(weld[b2])
            if w1 == w2:
                continue
            if filterparent and w1 and w2 and (w1 == weld[parent[w2]] or w2 == weld[parent[w1]]):
                continue
            if (min(b1, b2), max(b1, b2)) in excluded:
                continue
            out.append((g1, g2))
    return out


def _load_model(
    obj: str,
    gravity: bool,
    timestep: float,
    solver: str = "pgs",
    torsional: bool = True,
    explicit_pairs: bool = True,
) -> mujoco.MjModel:
    """The scene's model with the env's physics settings (module doc).

    ``explicit_pairs``: every contact the scene's ``contype``/``conaffinity`` allow becomes an
    explicit ``<pair>`` with the parameters MuJoCo would mix for it, and the geoms' own
    collision bits are cleared, so that no broadphase runs. The same contacts in the same
    order with the same parameters, the same trajectories bit for bit (tested), about 5 % less
    time per substep (docs/bench/four_finger_env.md)."""
    if solver not in SOLVERS:
        raise FourFingerError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    spec = mujoco.MjSpec.from_file(str(ihm.scenes.scene_path(scene_name(obj))))
    model = spec.compile()
    if torsional:  # condim 4: the skin's torsional friction (friction[1]) acts
        obj_body = model.body("object").id
        for g in range(model.ngeom):
            if model.geom_bodyid[g] == obj_body or model.geom_contype[g] == 2:
                model.geom_condim[g] = 4
    if explicit_pairs:
        names = [model.geom(g).name for g in range(model.ngeom)]
        pairs = dynamic_pairs(model)
        if any(not names[g] for pair in pairs for g in pair):
            raise FourFingerError("a colliding geom of the scene has no name")
        for g1, g2 in pairs:
            spec.add_pair(geomname1=names[g1], geomname2=names[g2], **mixed_contact(model, g1, g2))
        for g in spec.geoms:
            g.contype = g.conaffinity = 0
        geom_condim = model.geom_condim.copy()
        model = spec.compile()
        model.geom_condim[:] = geom_condim  # documents the skin; the pairs carry it
    model.opt.timestep = timestep
    model.opt.solver = SOLVERS[solver]
    model.opt.tolerance = SOLVER_TOLERANCE
    if not gravity:
        model.opt.gravity[:] = 0.0
    return model


class Physics:
    """Model, data and the index arrays of the fast observation path."""

    def __init__(
        self,
        obj: str,
        gravity: bool,
        timestep: float,
        solver: str = "pgs",
        torsional: bool = True,
        explicit_pairs: bool = True,
    ) -> None:
        self.model = m = _load_model(obj, gravity, timestep, solver, torsional, explicit_pairs)
        self.data = mujoco.MjData(m)
        if m.opt.cone != mujoco.mjtCone.mjCONE_ELLIPTIC:
            raise FourFingerError("the fast contact path needs the elliptic friction cone")
        self.obj_body = m.body("object").id
        jnt = m.joint("object")
        self.obj_qpos = int(m.jnt_qposadr[jnt.id])
        # per geom: observed link slot (-1: none), and whether it is the object's (plain lists:
        # link_contacts indexes them with Python ints)
        colliding = set(m.pair_geom1.tolist()) | set(m.pair_geom2.tolist())
        colliding |= {g for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]}
        self.slot = [-1] * m.ngeom
        for k, name in enumerate(CONTACT_LINKS):
            body = m.body(name).id
            for g in colliding:
                if m.geom_bodyid[g] == body:
                    self.slot[g] = k
        self.is_obj = (m.geom_bodyid == self.obj_body).tolist()
        self.ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        self.ctrl_hi = m.actuator_ctrlrange[:, 1].copy()

    def object_pos(self) -> NDArray[np.float64]:
        return self.data.qpos[self.obj_qpos : self.obj_qpos + 3]

    def object_quat(self) -> NDArray[np.float64]:
        return self.data.qpos[self.obj_qpos + 3 : self.obj_qpos + 7]

    def dropped(self) -> bool:
        p = self.object_pos()
        return bool(p[2] < DROP_Z or p[0] * p[0] + p[1] * p[1] > OUT_RADIUS * OUT_RADIUS)

    def object_slip(self) -> float:
        """Mean tangential sliding speed [m/s] of the finger-object contacts: ``|(v_t1, v_t2)|``
        of each contact's tangential constraint rows of ``efc_vel`` (the relative velocity of
        the two bodies at the contact point in the contact frame, from the last substep), 0
        without such a contact."""
        d = self.data
        v, adr, slot = d.efc_vel, d.contact.efc_address, self.slot
        total, n = 0.0, 0
        for i, other, _ in object_contact_ids(d, self.is_obj):
            if slot[other] < 0:
                continue
            a = int(adr[i])
            total += math.hypot(v[a + 1], v[a + 2])
            n += 1
        return total / n if n else 0.0

    def link_contacts(self) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
        """Per observed link: mean contact position (8, 3) [m], normal force sum (8,) [N], and
        the number of link-object contacts.

        A plain Python loop over the (few) contacts: about 10 us, 4x faster than the
        vectorised numpy version at these sizes."""
        n_links = len(CONTACT_LINKS)
        pos = np.zeros((n_links, 3))
        fn = np.zeros(n_links)
        d = self.data
        p, adr, ef, slot = d.contact.pos, d.contact.efc_address, d.efc_force, self.slot
        count = [0] * n_links
        k = 0
        for i, other, _ in object_contact_ids(d, self.is_obj):
            s = slot[other]
            if s < 0:
                continue
            pos[s] += p[i]
            fn[s] += ef[int(adr[i])]
            count[s] += 1
            k += 1
        for s, cnt in enumerate(count):
            if cnt > 1:
                pos[s] /= cnt
        return pos, fn, k
