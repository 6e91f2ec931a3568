"""Four-finger in-hand rotation (thesis ch. 7, sec. "In-hand manipulation with pure RL").

The 12-DOF four-finger hand (``assets/four_finger``) holds an object (``sphere``,
``cylinder`` or ``cube``, 0.1 kg, 70 mm; the scenes ``four_finger_<object>``) and
the policy is rewarded for turning it about the world vertical axis. Gymnasium
``MujocoEnv`` conventions (``model``, ``data``, ``frame_skip``, ``dt``,
``render_mode="rgb_array"``), without its ``imageio`` dependency.

## Action Space

``Box(-1, 1, (12,), float32)``, one entry per actuator in the order of
:data:`ihm.hands.four_finger.ACTUATOR_NAMES` (``f1_j0, f1_j1, f1_j2, f2_j0, ...``).
The servo setpoints change by ``dq_j = clip(a_j, -1, 1) * max_setpoint_step``
(0.05 rad, thesis eq. "setpoint change") per policy step and are clipped to the
joint ranges (the servos' ``ctrlrange``). A NaN/inf action or one of the wrong
shape raises :class:`FourFingerError`.

## Observation Space

``Box(low, high, (56,), float32)``, the thesis' observation: joint positions,
actuator setpoints, contact positions and contact normal forces. All positions
are in the palm frame (= MuJoCo world frame: palm top at ``z = 0``, +z up).
Bounds: joints ``[-pi, pi]``, setpoints the ``ctrlrange``, contact positions
``[-0.25, 0.25]`` m (the fingers reach 0.17 m), normal forces ``[0, MAX_FORCE]``
(50 N; values are clipped to the box, which only an impact spike can reach).

| index | what | MJCF names | unit |
|-------|------|------------|------|
| 0-11  | joint positions ``q`` | joints ``f1_j0 .. f4_j2`` | rad |
| 12-23 | actuator setpoints (``data.ctrl``) | actuators ``f1_j0 .. f4_j2`` | rad |
| 24-55 | 8 links x (x, y, z, c_n) | geoms ``f1_proximal .. f4_distal`` | m, N |

Link ``k`` (0-7, order of :data:`CONTACT_LINKS`) fills ``24 + 4k .. 27 + 4k``: the
mean position of that link's contacts with the object and the sum of their
normal forces (the hand pushing on the object, ``c_n >= 0``; MuJoCo's elliptic
cone stores it as the contact's first ``efc_force`` row, the value
``mj_contactForce`` returns); all four zero when the link does not touch the
object. Contacts between fingers, or of the object with the palm or floor, are
not observed. Contact data come from the last physics substep's collision
detection, as in every MuJoCo env.

## Rewards

``reward = rotation + drop + action`` with every term in ``info``:

- ``rotation``: the object's mean angular velocity about the world +z axis over
  the policy step, ``[log(R_t R_{t-1}^T)]_z / dt`` [rad/s] (positive:
  counter-clockwise seen from above; the thesis' reward);
- ``drop``: ``-drop_weight`` on the step that ends the episode by a drop
  (default weight 0, the thesis' setup);
- ``action``: ``-action_weight * |a|^2 / 12`` (default 0).

## Episode End

Terminated when the object is dropped or out of the hand: its centre below
``DROP_Z`` (0.05 m above the palm; held at about 0.077 m, lying on the palm at
0.035 m) or more than ``OUT_RADIUS`` (0.045 m) from the palm axis horizontally.
Truncated by the registration's time limit (``ihm/FourFingerRotate-v0``: 64
steps, the thesis' episode length; ``info["rotation_angle"]`` accumulates the
turned angle [rad]).

## Starting State

A state drawn uniformly from a cache of varied stable grasps (the thesis found
initial-state randomisation decisive): see :func:`generate_grasps` for the
generator. Each cached grasp is verified to hold for ``VERIFY_STEPS`` policy
steps with zero actions. The cache is built on first use (about 10-30 s per
object and gravity setting) and kept on disk under ``$IHM_CACHE`` (default
``~/.cache/ihm``), keyed by the model files, the physics settings and the
MuJoCo version.

## Physics

``timestep`` 0.002 s, ``frame_skip`` 25 substeps per policy step (20 Hz, the
thesis' policy rate); the hand model's own timestep is 0.001 s, and
``python -m envs.bench`` compares the two (the policy sees the same motion).
Contacts with torsional friction (``condim`` 4, see ``torsional``). Elliptic friction cone
with ``impratio`` 100 and no noslip pass (see the hand model's "Physics" note), solved by PGS
instead of the model's Newton solver: the same convex problem, 5x cheaper to solve here, to a
tolerance of 1e-4 (``SOLVER_TOLERANCE``; MuJoCo's 1e-8 takes about 60 % more iterations, and
one policy step differs from it by under 1 % of what halving the timestep changes: tested;
at rest it changes MuJoCo's creep of a held object by up to 1e-4 m/s per contact; README,
"Throughput"). The 34 contacts the scene's ``contype``/``conaffinity`` allow (the
object with the 8 links, palm and catch plane; links of different fingers) are explicit
``<pair>``s with the parameters MuJoCo would mix for them, so that no broadphase runs: the
same contacts in the same order with the same parameters, hence the same motion bit for bit
(tested), in about 5 % less time per step.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

import ihm.scenes
from ihm.hands import four_finger as ff

__all__ = [
    "CONTACT_LINKS",
    "DROP_Z",
    "OBJECTS",
    "OUT_RADIUS",
    "FourFingerError",
    "FourFingerRotate",
    "GraspCache",
    "generate_grasps",
    "grasp_cache",
]

OBJECTS = ("sphere", "cylinder", "cube")
CONTACT_LINKS = ff.BODY_NAMES  # f1_proximal, f1_distal, ..., f4_distal: observed links
DROP_Z = 0.05  # [m] object centre below this: dropped
OUT_RADIUS = 0.045  # [m] object centre farther than this from the palm axis: out of the hand
TORSIONAL_FRICTION = 0.005  # [m] the collision class' friction[1]; acts with torsional=True
MAX_FORCE = 50.0  # [N] observed normal forces are clipped here (impact spikes only)
VERIFY_STEPS = 40  # policy steps a cached grasp must hold with zero actions
N_OBS = 2 * ff.NU + 4 * len(CONTACT_LINKS)
_GENERATOR_VERSION = 2  # bump when generate_grasps changes


class FourFingerError(ValueError):
    """Bad option or action of :class:`FourFingerRotate` (unknown object, wrong shape, NaN)."""


def _scene(obj: str) -> str:
    if obj not in OBJECTS:
        raise FourFingerError(f"unknown object {obj!r}; choose one of {', '.join(OBJECTS)}")
    return f"four_finger_{obj}"


SOLVERS = {"pgs": mujoco.mjtSolver.mjSOL_PGS, "newton": mujoco.mjtSolver.mjSOL_NEWTON}
TIMESTEP = 0.002  # s: 5 steps per contact time constant (solref 0.01 s)
FRAME_SKIP = 25  # substeps per policy step: dt = 0.05 s, 20 Hz
SOLVER_TOLERANCE = 1e-4  # PGS; MuJoCo's 1e-8: ~60 % more iterations, no change the policy sees


def _mixed_contact(m: mujoco.MjModel, g1: int, g2: int) -> dict[str, Any]:
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


def _dynamic_pairs(m: mujoco.MjModel) -> list[tuple[int, int]]:
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
    """The scene's model with the env's physics settings (module doc, "Physics").

    ``explicit_pairs``: every contact the scene's ``contype``/``conaffinity`` allow becomes an
    explicit ``<pair>`` with the parameters MuJoCo would mix for it, and the geoms' own
    collision bits are cleared, so that no broadphase runs. The same contacts in the same
    order with the same parameters, the same trajectories bit for bit (tested), about 5 % less
    time per substep (README, "Throughput")."""
    if solver not in SOLVERS:
        raise FourFingerError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    spec = mujoco.MjSpec.from_file(str(ihm.scenes.scene_path(_scene(obj))))
    model = spec.compile()
    if torsional:  # condim 4: the skin's torsional friction (friction[1]) acts
        obj_body = model.body("object").id
        for g in range(model.ngeom):
            if model.geom_bodyid[g] == obj_body or model.geom_contype[g] == 2:
                model.geom_condim[g] = 4
    if explicit_pairs:
        names = [model.geom(g).name for g in range(model.ngeom)]
        pairs = _dynamic_pairs(model)
        if any(not names[g] for pair in pairs for g in pair):
            raise FourFingerError("a colliding geom of the scene has no name")
        for g1, g2 in pairs:
            spec.add_pair(geomname1=names[g1], geomname2=names[g2], **_mixed_contact(model, g1, g2))
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


@dataclass(frozen=True)
class GraspCache:
    """Cached stable grasps: ``qpos`` (n, nq), ``ctrl`` (n, nu), and how they were made."""

    qpos: NDArray[np.float64]
    ctrl: NDArray[np.float64]
    candidates: int  # generator attempts that produced these n grasps

    def __len__(self) -> int:
        return len(self.qpos)


class _Physics:
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

    def link_contacts(self) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
        """Per observed link: mean contact position (8, 3) [m], normal force sum (8,) [N], and
        the number of link-object contacts.

        A plain Python loop over the (few) contacts: about 10 us, 4x faster than the
        vectorised numpy version at these sizes."""
        n_links = len(CONTACT_LINKS)
        pos = np.zeros((n_links, 3))
        fn = np.zeros(n_links)
        d = self.data
        if d.ncon == 0:
            return pos, fn, 0
        c = d.contact
        geom, adr, excl = c.geom.tolist(), c.efc_address.tolist(), c.exclude.tolist()
        p, ef = c.pos, d.efc_force
        slot, is_obj = self.slot, self.is_obj
        count = [0] * n_links
        k = 0
        for i, (g1, g2) in enumerate(geom):
            if is_obj[g2]:
                s = slot[g1]
            elif is_obj[g1]:
                s = slot[g2]
            else:
                continue
            a = adr[i]
            if s < 0 or a < 0 or excl[i]:
                continue
            pos[s] += p[i]
            fn[s] += ef[a]
            count[s] += 1
            k += 1
        for s, cnt in enumerate(count):
            if cnt > 1:
                pos[s] /= cnt
        return pos, fn, k


def generate_grasps(
    obj: str = "sphere",
    gravity: bool = True,
    n: int = 256,
    *,
    seed: int = 0,
    timestep: float = TIMESTEP,
    frame_skip: int = FRAME_SKIP,
    max_candidates: int | None = None,
) -> GraspCache:
    """Varied stable grasps of ``obj``, each verified to hold with zero actions.

    Candidate ``i`` (random stream ``seed``):

    1. the ``init`` keyframe with the object turned by a yaw ``U(-pi, pi)`` about +z,
       and each finger opened or turned: ``j0 ~ U(-0.3, 0.3)``, ``j1 += U(-0.2, 0)``,
       ``j2 += U(-0.2, 0)`` [rad];
    2. the fingers close on it for 0.3 s without gravity, the abduction servos holding
       ``j0`` and the flexion servos acting as force sources (``ctrl = q + f / kp`` every
       substep) with the scene's ``ihm_preload`` flexion torques scaled by
       ``s * U(0.85, 1.15)`` per finger, ``s ~ U(0.7, 2.0)``; then the setpoints are
       frozen, gravity is switched on and the grasp rests for 0.5 s;
    3. with probability 0.3 one random finger lets go (its ``j1`` and ``j2``
       setpoints open by 0.5 rad) and the grasp rests on the other three for 0.5 s;
    4. kept if the object then stays in the hand for :data:`VERIFY_STEPS` policy
       steps with the setpoints fixed (zero actions): not dropped, moved less
       than 5 mm and turned less than 0.1 rad, at least two fingers touching.

    Returns the first ``n`` kept grasps (their state before the check).
    """
    scene = _scene(obj)
    rng = np.random.default_rng(seed)
    ph = _Physics(obj, gravity, timestep)
    m, d = ph.model, ph.data
    key = m.key("init").id
    preload = ihm.scenes.default_preload(m)
    grip_steps = int(round(0.3 / timestep))
    qpos, ctrl = [], []
    tries = 0
    cap = max_candidates if max_candidates is not None else 4 * n + 20
    while len(qpos) < n:
        if tries >= cap:
            raise FourFingerError(
                f"grasp generator for {scene}: only {len(qpos)} of {n} candidates held "
                f"after {tries} tries"
            )
        tries += 1
        mujoco.mj_resetDataKeyframe(m, d, key)
        yaw = rng.uniform(-np.pi, np.pi)
        d.qpos[ph.obj_qpos + 3 : ph.obj_qpos + 7] = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        q = d.qpos[: ff.NQ].reshape(4, 3)
        q[:, 0] = rng.uniform(-0.3, 0.3, 4)
        q[:, 1] += rng.uniform(-0.2, 0.0, 4)
        q[:, 2] += rng.uniform(-0.2, 0.0, 4)
        f_c = preload.reshape(4, 3) * (rng.uniform(0.7, 2.0) * rng.uniform(0.85, 1.15, (4, 1)))
        _close(m, d, q[:, 0].copy(), f_c, grip_steps, gravity)
        if rng.uniform() < 0.3:
            k = int(rng.integers(4))
            d.ctrl[3 * k + 1 : 3 * k + 3] -= 0.5
            d.ctrl[:] = np.clip(d.ctrl, ph.ctrl_lo, ph.ctrl_hi)
            mujoco.mj_step(m, d, nstep=int(round(0.5 / timestep)))
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        if ph.dropped():
            continue
        state_q, state_c = d.qpos.copy(), d.ctrl.copy()
        p0, quat0 = ph.object_pos().copy(), ph.object_quat().copy()
        mujoco.mj_step(m, d, nstep=VERIFY_STEPS * frame_skip)
        rot = np.zeros(3)
        mujoco.mju_subQuat(rot, ph.object_quat(), quat0)
        _, fn, _ = ph.link_contacts()
        fingers = int((fn.reshape(4, 2).sum(axis=1) > 1e-3).sum())
        if (
            ph.dropped()
            or np.linalg.norm(ph.object_pos() - p0) > 5e-3
            or np.linalg.norm(rot) > 0.1
            or fingers < 2
        ):
            continue
        qpos.append(state_q)
        ctrl.append(state_c)
    return GraspCache(np.array(qpos), np.array(ctrl), tries)


def _close(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    j0: NDArray[np.float64],
    f_c: NDArray[np.float64],
    grip_steps: int,
    gravity: bool,
) -> None:
    """Step 2 of :func:`generate_grasps`: close the fingers by force, freeze, rest."""
    g = m.opt.gravity.copy()
    kp = m.actuator_gainprm[:, 0]
    flex = np.ones(ff.NU, dtype=bool)
    flex[0::3] = False
    try:
        m.opt.gravity[:] = 0.0
        d.ctrl[~flex] = j0
        for _ in range(grip_steps):
            d.ctrl[flex] = d.qpos[: ff.NQ][flex] + f_c.reshape(-1)[flex] / kp[flex]
            mujoco.mj_step(m, d)
    finally:
        m.opt.gravity[:] = g
    d.ctrl[:] = np.clip(d.ctrl, m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])
    mujoco.mj_step(m, d, nstep=grip_steps + grip_steps // 2 + 1)


def _cache_dir() -> Path:
    return Path(os.environ.get("IHM_CACHE", Path.home() / ".cache" / "ihm")) / "grasps"


def _cache_key(obj: str, gravity: bool, n: int, seed: int, timestep: float, frame_skip: int) -> str:
    h = hashlib.sha256()
    for path in (ihm.scenes.scene_path(_scene(obj)), ff.XML):
        h.update(Path(path).read_bytes())
    settings = (gravity, n, seed, timestep, frame_skip, "pgs", SOLVER_TOLERANCE, "condim4")
    settings += (mujoco.__version__,)
    h.update(repr(settings).encode())
    h.update(repr(_GENERATOR_VERSION).encode())
    return f"{obj}_{'g' if gravity else 'nog'}_{n}_{h.hexdigest()[:16]}"


_MEMORY: dict[str, GraspCache] = {}


def grasp_cache(
    obj: str = "sphere",
    gravity: bool = True,
    n: int = 256,
    *,
    seed: int = 0,
    timestep: float = TIMESTEP,
    frame_skip: int = FRAME_SKIP,
) -> GraspCache:
    """:func:`generate_grasps`, memoised in the process and on disk (``$IHM_CACHE``)."""
    key = _cache_key(obj, gravity, n, seed, timestep, frame_skip)
    if key in _MEMORY:
        return _MEMORY[key]
    path = _cache_dir() / f"{key}.npz"
    cache = None
    if path.is_file():
        try:
            with np.load(path) as z:
                cache = GraspCache(z["qpos"], z["ctrl"], int(z["candidates"]))
        except (OSError, KeyError, ValueError):
            cache = None  # a broken file is rebuilt
    if cache is None:
        cache = generate_grasps(
            obj, gravity, n, seed=seed, timestep=timestep, frame_skip=frame_skip
        )
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as f:
                np.savez(f, qpos=cache.qpos, ctrl=cache.ctrl, candidates=cache.candidates)
            os.replace(f.name, path)
        except OSError:
            pass  # read-only home: keep it in memory only
    _MEMORY[key] = cache
    return cache


def yaw_rate(quat_before: NDArray[np.float64], quat_after: NDArray[np.float64], dt: float) -> float:
    """World-z component of the mean angular velocity taking ``quat_before`` to ``quat_after``
    (MuJoCo ``wxyz`` quaternions) in ``dt`` seconds [rad/s]: ``[log(R_1 R_0^T)]_z / dt``.

    ``mju_quat2Vel(q_1 * conj(q_0), dt)[2]`` in plain float arithmetic (4x cheaper here)."""
    w0, x0, y0, z0 = quat_before.tolist()
    w1, x1, y1, z1 = quat_after.tolist()
    # rel = q_1 * conj(q_0): the rotation in the world frame
    w = w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0
    x = -w1 * x0 + x1 * w0 - y1 * z0 + z1 * y0
    y = -w1 * y0 + x1 * z0 + y1 * w0 - z1 * x0
    z = -w1 * z0 - x1 * y0 + y1 * x0 + z1 * w0
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < mujoco.mjMINVAL:
        return 0.0
    angle = 2.0 * math.atan2(sin_half, w)
    if angle > math.pi:
        angle -= 2.0 * math.pi
    return z / sin_half * angle / dt


class FourFingerRotate(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Rotate a held object about the vertical axis with the four-finger hand.

    Parameters
    ----------
    object : ``"sphere"`` (the thesis'), ``"cylinder"`` or ``"cube"``.
    gravity : gravity on (-9.81 m/s^2 along -z) or off.
    max_setpoint_step : ``q^max`` of the thesis [rad per policy step].
    frame_skip : physics substeps per policy step.
    timestep : physics timestep [s] (policy period ``dt = frame_skip * timestep``).
    drop_weight, action_weight : weights of the optional reward terms (module doc).
    n_grasps : size of the starting-state cache.
    render_mode : ``None`` or ``"rgb_array"``; ``width``, ``height`` [px];
        ``camera``: ``"side"`` or ``"top"``.
    torsional : contacts with the skin's torsional friction (``condim`` 4, coefficient
        ``TORSIONAL_FRICTION`` = 0.005 m: the torque limit is 0.005 m x the normal force,
        that of a ~7 mm soft contact patch). Off (``condim`` 3, the thesis' point
        contact), a sphere pinched between two antipodal points spins freely about the
        line through them, and PPO learned exactly that (README).
    solver : MuJoCo constraint solver, ``"pgs"`` (default) or ``"newton"`` (the hand
        model's). Both solve the same convex contact problem; PGS is 5x cheaper on it.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        object: str = "sphere",
        gravity: bool = True,
        *,
        max_setpoint_step: float = 0.05,
        frame_skip: int = FRAME_SKIP,
        timestep: float = TIMESTEP,
        drop_weight: float = 0.0,
        action_weight: float = 0.0,
        n_grasps: int = 256,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera: str = "side",
        solver: str = "pgs",
        torsional: bool = True,
    ) -> None:
        _scene(object)
        if not isinstance(gravity, (bool, np.bool_)):
            raise FourFingerError(f"gravity must be True or False, got {gravity!r}")
        for name, v in (
            ("max_setpoint_step", max_setpoint_step),
            ("timestep", timestep),
            ("drop_weight", drop_weight),
            ("action_weight", action_weight),
        ):
            if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
                raise FourFingerError(f"{name} must be a finite number >= 0, got {v!r}")
        if max_setpoint_step <= 0 or timestep <= 0:
            raise FourFingerError("max_setpoint_step and timestep must be > 0")
        if not isinstance(frame_skip, (int, np.integer)) or frame_skip < 1:
            raise FourFingerError(f"frame_skip must be an integer >= 1, got {frame_skip!r}")
        if not isinstance(n_grasps, (int, np.integer)) or n_grasps < 1:
            raise FourFingerError(f"n_grasps must be an integer >= 1, got {n_grasps!r}")
        if render_mode not in (None, "rgb_array"):
            raise FourFingerError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if camera not in ("side", "top"):
            raise FourFingerError(f"camera must be 'side' or 'top', got {camera!r}")
        self.object = object
        self.gravity = bool(gravity)
        self.max_setpoint_step = float(max_setpoint_step)
        self.frame_skip = int(frame_skip)
        self.drop_weight = float(drop_weight)
        self.action_weight = float(action_weight)
        self.render_mode = render_mode
        self.width, self.height, self.camera = width, height, camera
        self._ph = _Physics(object, self.gravity, float(timestep), solver, bool(torsional))
        self.model, self.data = self._ph.model, self._ph.data
        self.dt = self.model.opt.timestep * self.frame_skip
        self.grasps = grasp_cache(
            object,
            self.gravity,
            int(n_grasps),
            timestep=float(timestep),
            frame_skip=self.frame_skip,
        )
        self.action_space = spaces.Box(-1.0, 1.0, (ff.NU,), dtype=np.float32)
        lo = np.concatenate(
            [np.full(ff.NQ, -np.pi), self._ph.ctrl_lo, np.tile([-0.25, -0.25, -0.25, 0.0], 8)]
        )
        hi = np.concatenate(
            [np.full(ff.NQ, np.pi), self._ph.ctrl_hi, np.tile([0.25, 0.25, 0.25, MAX_FORCE], 8)]
        )
        self.observation_space = spaces.Box(lo.astype(np.float32), hi.astype(np.float32))
        self._lo, self._hi = self.observation_space.low, self.observation_space.high
        self._obs = np.zeros(N_OBS, dtype=np.float32)
        self._quat = np.zeros(4)
        self._angle = 0.0
        self._renderer: Any = None

    # -- observation ------------------------------------------------------------------------
    def _observe(self) -> NDArray[np.float32]:
        d, o = self.data, self._obs
        o[: ff.NQ] = d.qpos[: ff.NQ]
        o[ff.NQ : 2 * ff.NU] = d.ctrl
        pos, fn, _ = self._ph.link_contacts()
        c = o[2 * ff.NU :].reshape(len(CONTACT_LINKS), 4)
        c[:, :3] = pos
        c[:, 3] = fn
        return np.minimum(np.maximum(o, self._lo), self._hi)

    def _yaw_rate(self, quat_before: NDArray[np.float64]) -> float:
        """Mean angular velocity about world +z since ``quat_before`` [rad/s]."""
        return yaw_rate(quat_before, self._ph.object_quat(), self.dt)

    # -- gym API ----------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start from a cached stable grasp (``options={"grasp": i}`` picks one)."""
        super().reset(seed=seed)
        i = None if options is None else options.get("grasp")
        if i is None:
            i = int(self.np_random.integers(len(self.grasps)))
        elif not isinstance(i, (int, np.integer)) or not 0 <= i < len(self.grasps):
            raise FourFingerError(f"options['grasp'] must be in [0, {len(self.grasps)}), got {i!r}")
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self.grasps.qpos[i]
        d.ctrl[:] = self.grasps.ctrl[i]
        mujoco.mj_forward(m, d)
        self._angle = 0.0
        return self._observe(), {"grasp": i, "rotation_angle": 0.0}

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (ff.NU,):
            raise FourFingerError(f"action must have shape ({ff.NU},), got {a.shape}")
        if not np.isfinite(a).all():
            raise FourFingerError(f"action contains NaN or inf: {a}")
        a = np.minimum(np.maximum(a, -1.0), 1.0)  # np.clip's Python wrapper costs 3x more
        d, ph = self.data, self._ph
        ctrl = d.ctrl + a * self.max_setpoint_step
        np.minimum(np.maximum(ctrl, ph.ctrl_lo, out=ctrl), ph.ctrl_hi, out=d.ctrl)
        self._quat[:] = ph.object_quat()
        mujoco.mj_step(self.model, d, nstep=self.frame_skip)
        rate = self._yaw_rate(self._quat)
        self._angle += rate * self.dt
        dropped = ph.dropped()
        terms = {
            "rotation": rate,
            "drop": -self.drop_weight if dropped else 0.0,
            "action": -self.action_weight * float(a @ a) / ff.NU,
        }
        reward = terms["rotation"] + terms["drop"] + terms["action"]
        info = {**terms, "dropped": dropped, "rotation_angle": self._angle}
        return self._observe(), reward, dropped, False, info

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB frame (``height, width, 3``) from the side or top camera."""
        if self.render_mode != "rgb_array":
            return None
        from ihm.render import _make_renderer

        if self._renderer is None:
            vis = self.model.vis
            vis.global_.offwidth = max(vis.global_.offwidth, self.width)
            vis.global_.offheight = max(vis.global_.offheight, self.height)
            if self.model.nlight == 0:  # the scenes have no lights: a brighter headlight
                vis.headlight.ambient[:] = np.maximum(vis.headlight.ambient, 0.35)
                vis.headlight.diffuse[:] = np.maximum(vis.headlight.diffuse, 0.6)
            self._renderer = _make_renderer(self.model, self.width, self.height)
        cam = mujoco.MjvCamera()
        cam.lookat[:] = [0.0, 0.0, 0.06]
        cam.distance = 0.32
        cam.azimuth, cam.elevation = (45.0, -20.0) if self.camera == "side" else (90.0, -89.0)
        self._renderer.update_scene(self.data, camera=cam)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
