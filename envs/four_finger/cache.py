"""The four-finger rotation env's starting states: a cache of varied stable grasps.

A state drawn uniformly from a cache of varied stable grasps (the thesis found
initial-state randomisation decisive): see :func:`generate_grasps` for the
generator. Each cached grasp is verified to hold for ``VERIFY_STEPS`` policy
steps with zero actions. The cache is built on first use (about 10-30 s per
object and gravity setting) and kept on disk under ``$IHM_CACHE`` (default
``~/.cache/ihm``), keyed by the model files, the physics settings and the
MuJoCo version.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

import ihm.scenes
from envs.four_finger.physics import (
    DROP_Z,
    FRAME_SKIP,
    SOLVER_TOLERANCE,
    TIMESTEP,
    FourFingerError,
    Physics,
    scene_name,
)
from envs.four_finger.randomize import ModelScaler, PhysicsSample, Randomization
from ihm.hands import four_finger as ff

__all__ = [
    "FIRM_LIFT",
    "FIRM_SQUEEZE",
    "GRASP_SETS",
    "GRIPS",
    "START_CLEARANCE",
    "VERIFY_STEPS",
    "GraspCache",
    "generate_grasps",
    "grasp_cache",
    "worst_hold",
]

VERIFY_STEPS = 40  # policy steps a cached grasp must hold with zero actions
GRASP_SETS = {"train": 0, "test": 1_000_003}
"""Generator seeds of the start-grasp sets: ``train`` (every training run and the trainers'
own validation) and ``test`` (held-out evaluation: a disjoint random stream, so no training
grasp is ever an evaluation grasp)."""
GRIPS = ("nominal", "firm")
"""How the generator sets the start grasp's squeeze: ``nominal`` (the thesis' inward grip,
the weight carried by the springs' sag and friction) or ``firm`` (setpoints that also lift
the object and squeeze harder, verified under the worst randomised physics too)."""
FIRM_LIFT = 1.2  # firm grip: designed upward force, in object weights (nominal mass)
FIRM_SQUEEZE = 1.0  # [N] firm grip: extra inward force per touching finger
START_CLEARANCE = 0.01  # [m] a kept grasp holds the object's centre this far above DROP_Z
_GENERATOR_VERSION = 3  # bump when generate_grasps changes


def _check_grip(grip: str) -> None:
    if grip not in GRIPS:
        raise FourFingerError(f"grip must be one of {list(GRIPS)}, got {grip!r}")


def worst_hold(r: Randomization | None = None) -> PhysicsSample:
    """The physics under which a still hand holds worst: ``r``'s lowest friction and
    torsional friction, highest mass and lowest gain (no latency or noise: the hand is still).
    Measured: these corners drop 12 of 20 nominal start grasps with the hand still."""
    r = r or Randomization()
    return PhysicsSample(r.friction[0], r.torsional[0], r.mass[1], r.gain[0])


@dataclass(frozen=True)
class GraspCache:
    """Cached stable grasps: ``qpos`` (n, nq), ``ctrl`` (n, nu), and how they were made."""

    qpos: NDArray[np.float64]
    ctrl: NDArray[np.float64]
    candidates: int  # generator attempts that produced these n grasps

    def __len__(self) -> int:
        return len(self.qpos)


def generate_grasps(
    obj: str = "sphere",
    gravity: bool = True,
    n: int = 256,
    *,
    seed: int = 0,
    timestep: float = TIMESTEP,
    frame_skip: int = FRAME_SKIP,
    max_candidates: int | None = None,
    grip: str = "nominal",
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
       than 5 mm and turned less than 0.1 rad, at least two fingers touching, and the
       object's centre at least :data:`START_CLEARANCE` (10 mm) above ``DROP_Z`` at the
       start. That last condition keeps out grasps that hold the object low and tilted just
       above the drop threshold, where any motion of it ends the episode as a drop.

    ``grip="firm"`` adds, before step 4, to each touching finger's setpoints
    ``q_c += J_c^T f_c / kp`` with ``f_c = FIRM_SQUEEZE * h_c + (FIRM_LIFT * m g / n) e_z``:
    ``J_c`` the finger's translational Jacobian at its contact (the distal link's if it
    touches, else the proximal's), ``h_c`` the horizontal unit vector from the contact to
    the object's axis, ``m g`` the object's nominal weight, ``n`` the touching fingers. The
    nominal grip's setpoints press only inward, so the weight is carried by the springs'
    sag and friction alone; this one presses up as well (1.2 weights: between the lightest
    and heaviest randomised masses, so friction carries at most 0.8 weights either way) and
    1 N harder. The grasp rests 0.5 s, and step 4 also runs under :func:`worst_hold`
    physics (from the same state), where the object must not drop or sink 5 mm.

    Returns the first ``n`` kept grasps (their state before the check).
    """
    _check_grip(grip)
    scene = scene_name(obj)
    rng = np.random.default_rng(seed)
    ph = Physics(obj, gravity, timestep)
    m, d = ph.model, ph.data
    key = m.key("init").id
    preload = ihm.scenes.default_preload(m)
    scaler = ModelScaler(m, d, ph.obj_body) if grip == "firm" else None
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
        if scaler is not None:
            _firm(ph)
            mujoco.mj_step(m, d, nstep=int(round(0.5 / timestep)))
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        if ph.dropped():
            continue
        state_q, state_c = d.qpos.copy(), d.ctrl.copy()
        p0, quat0 = ph.object_pos().copy(), ph.object_quat().copy()
        if p0[2] < DROP_Z + START_CLEARANCE:  # held just above the drop line: any motion drops
            continue
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
        if scaler is not None and not _holds_worst(
            ph, scaler, state_q, state_c, VERIFY_STEPS * frame_skip
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


def _firm(ph: Physics) -> None:
    """The firm grip's setpoint change (:func:`generate_grasps`)."""
    m, d = ph.model, ph.data
    centre = ph.object_pos().copy()
    pos, fn, _ = ph.link_contacts()
    fingers = [k for k in range(4) if fn[2 * k] + fn[2 * k + 1] > 1e-3]
    if not fingers:
        return
    lift = FIRM_LIFT * float(m.body_mass[ph.obj_body]) * float(-m.opt.gravity[2]) / len(fingers)
    jac = np.zeros((3, m.nv))
    tau = np.zeros(ff.NU)
    for k in fingers:
        s = 2 * k + 1 if fn[2 * k + 1] > 1e-3 else 2 * k
        h = centre - pos[s]
        h[2] = 0.0
        f = FIRM_SQUEEZE * h / max(float(np.linalg.norm(h)), 1e-9) + np.array([0.0, 0.0, lift])
        mujoco.mj_jac(m, d, jac, None, pos[s], m.body(ff.BODY_NAMES[s]).id)
        tau[3 * k : 3 * k + 3] = (jac[:, 3 * k : 3 * k + 3]).T @ f
    d.ctrl[:] = np.clip(d.ctrl + tau / m.actuator_gainprm[:, 0], ph.ctrl_lo, ph.ctrl_hi)


def _holds_worst(
    ph: Physics,
    scaler: ModelScaler,
    qpos: NDArray[np.float64],
    ctrl: NDArray[np.float64],
    steps: int,
) -> bool:
    """Whether the grasp (``qpos``, ``ctrl``, at rest) holds for ``steps`` substeps under
    :func:`worst_hold` physics: not dropped, sunk less than 5 mm. Leaves nominal physics."""
    m, d = ph.model, ph.data
    scaler.apply(worst_hold())
    try:
        mujoco.mj_resetData(m, d)
        d.qpos[:], d.ctrl[:] = qpos, ctrl
        mujoco.mj_forward(m, d)
        z0 = float(ph.object_pos()[2])
        mujoco.mj_step(m, d, nstep=steps)
        return not ph.dropped() and z0 - float(ph.object_pos()[2]) < 5e-3
    finally:
        scaler.apply(PhysicsSample())


def _cache_dir() -> Path:
    return Path(os.environ.get("IHM_CACHE", Path.home() / ".cache" / "ihm")) / "grasps"


def _cache_key(
    obj: str, gravity: bool, n: int, seed: int, timestep: float, frame_skip: int, grip: str
) -> str:
    h = hashlib.sha256()
    for path in (ihm.scenes.scene_path(scene_name(obj)), ff.XML):
        h.update(Path(path).read_bytes())
    settings = (gravity, n, seed, timestep, frame_skip, "pgs", SOLVER_TOLERANCE, "condim4")
    settings += (mujoco.__version__,)
    if grip != "nominal":  # nominal: no grip fields in the key, so nominal caches stay valid
        settings += (grip, FIRM_LIFT, FIRM_SQUEEZE, worst_hold())
    h.update(repr(settings).encode())
    h.update(repr(_GENERATOR_VERSION).encode())
    tag = "" if grip == "nominal" else f"{grip}_"
    return f"{obj}_{tag}{'g' if gravity else 'nog'}_{n}_{h.hexdigest()[:16]}"


_MEMORY: dict[str, GraspCache] = {}


def grasp_cache(
    obj: str = "sphere",
    gravity: bool = True,
    n: int = 256,
    *,
    seed: int = 0,
    timestep: float = TIMESTEP,
    frame_skip: int = FRAME_SKIP,
    grip: str = "nominal",
) -> GraspCache:
    """:func:`generate_grasps`, memoised in the process and on disk (``$IHM_CACHE``)."""
    _check_grip(grip)
    key = _cache_key(obj, gravity, n, seed, timestep, frame_skip, grip)
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
            obj, gravity, n, seed=seed, timestep=timestep, frame_skip=frame_skip, grip=grip
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
