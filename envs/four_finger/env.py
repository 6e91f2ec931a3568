"""Four-finger in-hand rotation (thesis ch. 7, sec. "In-hand manipulation with pure RL").

The 12-DOF four-finger hand (``assets/four_finger``) holds an object and the policy is
rewarded for turning it about the world vertical axis: one of the training objects
(:data:`~envs.four_finger.physics.TRAIN_OBJECTS`: ``sphere``, ``cylinder`` or ``cube``,
0.1 kg, 70 mm) or of the held-out ones (:data:`~envs.four_finger.physics.HELDOUT_OBJECTS`:
``capsule``, 60 mm wide, and ``ellipsoid``, 80 x 66 x 60 mm, 0.1 kg each), the scenes
``four_finger_<object>``. Gymnasium ``MujocoEnv`` conventions (``model``, ``data``,
``frame_skip``, ``dt``, ``render_mode="rgb_array"``), without its ``imageio`` dependency.

## Settings

The env's settings come in groups (:mod:`envs.four_finger.settings`), each a frozen
dataclass that checks its values: ``reward`` (:class:`RewardSettings`), ``sim``
(:class:`SimSettings`), ``starts`` (:class:`StartSettings`), ``observation``
(:class:`ObservationSettings`), ``render`` (:class:`RenderSettings`), and the randomised
physics ``randomize`` (:class:`Randomization`, drawn per episode) or ``physics``
(:class:`PhysicsSample`, fixed). A trainer keeps the groups in its config and passes them as
they are; any field can also be given by name on its own
(``FourFingerRotate(drop_weight=1.0, history=3)``, ``gym.make(..., grip="firm")``), set on
top of its group. Below, ``history=k``, ``replay_prob=p`` etc. name such fields.

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
| 12-23 | commanded setpoints (``data.ctrl``) | actuators ``f1_j0 .. f4_j2`` | rad |
| 24-55 | 8 links x (x, y, z, c_n) | geoms ``f1_proximal .. f4_distal`` | m, N |

With ``history=k`` (default 1) the observation is the last ``k`` such frames, oldest first
(``(56 k,)``; after a reset every slot holds the first frame): what a controller that keeps
its last few readings knows, enough to sense slip and the object's response (velocities)
that one frame does not show.

With ``privileged=True`` :data:`N_PRIVILEGED` (18) entries follow the frames, for an
asymmetric critic only (the actor of ``train.ppo --privileged-critic`` never reads them;
a tactile hand does not sense them): the object's position (3, m) and orientation
quaternion (4, wxyz) in the palm frame, its free joint's velocity (6: linear m/s in the
world frame, angular rad/s in the body frame, MuJoCo's ``qvel``), and the episode's
physics: friction, torsional friction and mass scales, mean servo gain scale, latency
(policy steps). Bounds: +-0.25 m, +-1, +-20 (clipped), [0, 5], [0, 5].

Link ``k`` (0-7, order of :data:`CONTACT_LINKS`) fills ``24 + 4k .. 27 + 4k``: the
mean position of that link's contacts with the object and the sum of their
normal forces (the hand pushing on the object, ``c_n >= 0``; MuJoCo's elliptic
cone stores it as the contact's first ``efc_force`` row, the value
``mj_contactForce`` returns); all four zero when the link does not touch the
object. Contacts between fingers, or of the object with the palm or floor, are
not observed. Contact data come from the last physics substep's collision
detection, as in every MuJoCo env. With one step of action latency (randomised physics) the
servos still run on ``data.ctrl`` while the setpoint slots show what the controller last
commanded, ``clip(data.ctrl + a_t * max_setpoint_step)`` for the action ``a_t`` not yet
applied: a real controller knows what it sent, and without it the pending action is hidden
state (the observation is not Markov).

## Rewards

``reward = rotation + drop + action + height + slip + tilt`` with every term in ``info``:

- ``rotation``: the object's mean angular velocity about the world +z axis over
  the policy step, ``[log(R_t R_{t-1}^T)]_z / dt`` [rad/s] (positive:
  counter-clockwise seen from above; the thesis' reward), clipped to
  ``[-rotation_cap, rotation_cap]`` (default ``inf``: the thesis' uncapped reward);
- ``drop``: ``-drop_weight`` on the step that ends the episode by a drop
  (default weight 0, the thesis' setup);
- ``action``: ``-action_weight * |a|^2 / 12`` (default 0);
- ``height``: ``-height_weight * max(0, HOLD_Z - z) / (HOLD_Z - DROP_Z)``, the object's sag
  below ``HOLD_Z`` (0.07 m; the start grasps hold it at about 0.077 m) as a fraction of the way
  to the drop threshold ``DROP_Z`` (default weight 0). It penalises holding the object low,
  just above the drop threshold, where a small sag ends the episode (docs/four_finger.md).
  With ``height_from="start"`` the reference is the object's height at the episode's start,
  ``z_0``, instead of ``HOLD_Z``:
  ``-height_weight * max(0, z_0 - z) / (z_0 - DROP_Z)``, so every millimetre of sag counts
  (with ``HOLD_Z`` the first 7 mm cost nothing: a slow sag of 1-2 mm/s gives no signal
  inside a 3.2 s training episode);
- ``slip``: ``-slip_weight * v_slip``, the mean tangential sliding speed [m/s] of the
  finger-object contacts at the end of the step (``Physics.object_slip``; default weight 0):
  a sliding contact's friction acts along the slip, so it holds less against the weight;
- ``tilt``: ``-tilt_weight * tilt``, the object's tilt since the episode's start [rad]
  (:func:`z_tilt`: the angle by which its rotation since then turns the vertical; default
  weight 0). It penalises tipping over an upright object such as the cylinder
  (docs/four_finger.md).

## Episode End

Terminated when the object is dropped or out of the hand: its centre below
``DROP_Z`` (0.05 m above the palm; held at about 0.077 m, lying on the palm at
0.035 m) or more than ``OUT_RADIUS`` (0.045 m) from the palm axis horizontally.
Truncated by the registration's time limit (``ihm/FourFingerRotate-v0``: 64
steps, the thesis' episode length). ``info["rotation_angle"]`` accumulates the
per-step rotations about +z (uncapped) [rad]; ``info["net_turn"]`` is the net turn: the
twist about +z of the object's orientation relative to its start (:func:`z_twist`),
unwrapped step by step [rad]. The two agree for a rotation about z; when the object
tumbles the summed rotation overstates the net turn (tested).

## Starting State

A state drawn uniformly from a cache of varied stable grasps (the thesis found
initial-state randomisation decisive): see :mod:`envs.four_finger.cache` for the generator
and the cache. Each cached grasp is verified to hold for ``VERIFY_STEPS`` policy steps with
zero actions. The cache is built on first use (about 10-30 s per object and gravity setting)
and kept on disk under ``$IHM_CACHE`` (default ``~/.cache/ihm``). ``grasps="test"`` starts
from the held-out set instead (a generator seed no training run uses,
:data:`envs.four_finger.GRASP_SETS`). ``grip="firm"`` makes the start grasps press up and
1 N harder and keeps only those that hold still under the worst randomised physics as well
(half the friction, twice the mass, weak servos), where half the nominal grip's drop.

## Physics

:mod:`envs.four_finger.physics`: 2 ms x 25 substeps, PGS to a tolerance of 1e-4, torsional
friction, explicit contact pairs. ``randomize=Randomization()`` draws friction, torsional
friction, object mass, servo gains, one step of action latency and sensor noise per episode;
``physics=PhysicsSample(...)`` fixes them (:mod:`envs.four_finger.randomize`).
``reset(options={"physics": PhysicsSample(...)})`` sets the physics from that episode on, in
place of a ``randomize`` draw (an evaluation that gives each episode its own physics).

## Failure replay

``replay_prob=p > 0``: every episode that drops the object puts its start (grasp index and
physics sample) into a buffer of the last ``REPLAY_SIZE`` such starts; a reset without
``options["grasp"]`` then restarts, with probability ``p``, one of them drawn uniformly
(it leaves the buffer, and comes back if it drops again). It is Prioritized Level Replay's
idea (Jiang et al. 2021) for start states: the rare starts that a policy drops are trained
on more often. Each env keeps its own buffer (in memory: a resumed run starts it empty);
``p = 0`` (the default) draws nothing extra.

## Turned cube starts

``turned_prob=p > 0`` (cube only): a reset without ``options["grasp"]`` that does not replay
starts, with probability ``p``, from a cached grasp whose cube is turned by at least
``TURNED`` (22.5 degrees) from the hand's square, :func:`cube_turn`; otherwise from any grasp.
Settled start grasps are rarely turned that far (the fingers square the cube up), and the
robust cube's drops come from them (docs/four_finger.md).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from envs.four_finger.cache import GRASP_SETS, grasp_cache
from envs.four_finger.physics import (
    CONTACT_LINKS,
    DROP_Z,
    MAX_FORCE,
    FourFingerError,
    Physics,
    scene_name,
)
from envs.four_finger.randomize import ModelScaler, PhysicsSample, Randomization
from envs.four_finger.settings import (
    HEIGHT_FROM,
    ObservationSettings,
    RenderSettings,
    RewardSettings,
    SimSettings,
    StartSettings,
    apply_overrides,
)
from ihm.hands import four_finger as ff

__all__ = ["HEIGHT_FROM", "HOLD_Z", "N_OBS", "FourFingerRotate", "yaw_rate", "z_tilt", "z_twist"]

N_OBS = 2 * ff.NU + 4 * len(CONTACT_LINKS)
N_PRIVILEGED = 18  # privileged=True: object pose (7) and velocity (6), episode physics (5)
HOLD_Z = 0.07  # [m] object centre height below which the height term penalises sag
TURNED = math.pi / 8  # [rad] turned_prob: a start with |cube_turn| >= this is "turned"
REPLAY_SIZE = 64  # failure replay: dropped starts an env remembers (the last ones)


def _relative(q0: NDArray[np.float64], q1: NDArray[np.float64]) -> tuple[float, ...]:
    """``q_1 * conj(q_0)`` (MuJoCo ``wxyz``), the rotation from ``q0`` to ``q1`` in the world
    frame, in plain float arithmetic (4x cheaper than ``mju_mulQuat`` here)."""
    w0, x0, y0, z0 = q0.tolist()
    w1, x1, y1, z1 = q1.tolist()
    return (
        w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0,
        -w1 * x0 + x1 * w0 - y1 * z0 + z1 * y0,
        -w1 * y0 + x1 * z0 + y1 * w0 - z1 * x0,
        -w1 * z0 - x1 * y0 + y1 * x0 + z1 * w0,
    )


def yaw_rate(quat_before: NDArray[np.float64], quat_after: NDArray[np.float64], dt: float) -> float:
    """World-z component of the mean angular velocity taking ``quat_before`` to ``quat_after``
    (MuJoCo ``wxyz`` quaternions) in ``dt`` seconds [rad/s]: ``[log(R_1 R_0^T)]_z / dt``.

    ``mju_quat2Vel(q_1 * conj(q_0), dt)[2]`` in plain float arithmetic (4x cheaper here)."""
    w, x, y, z = _relative(quat_before, quat_after)
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < mujoco.mjMINVAL:
        return 0.0
    angle = 2.0 * math.atan2(sin_half, w)
    if angle > math.pi:
        angle -= 2.0 * math.pi
    return z / sin_half * angle / dt


def z_twist(quat_start: NDArray[np.float64], quat: NDArray[np.float64]) -> float:
    """Twist about world +z of the rotation taking ``quat_start`` to ``quat`` (MuJoCo ``wxyz``
    quaternions) [rad], in ``(-pi, pi]``: the angle of the swing-twist decomposition
    ``q_rel = q * conj(q_start) = swing * twist``, ``twist = (w, 0, 0, z) / |(w, 0, 0, z)|``,
    ``angle = 2 atan2(z, w)`` of ``q_rel``. For a rotation about z it is that rotation's
    angle; a tumble (rotation about a horizontal axis) adds nothing. Undefined (0 returned)
    for a half turn about a horizontal axis, where ``w = z = 0``."""
    w, _, _, z = _relative(quat_start, quat)
    if w * w + z * z < 1e-24:
        return 0.0
    a = 2.0 * math.atan2(z, w)
    return a - 2.0 * math.pi if a > math.pi else (a + 2.0 * math.pi if a <= -math.pi else a)


def z_tilt(quat_start: NDArray[np.float64], quat: NDArray[np.float64]) -> float:
    """Tilt of the object since ``quat_start`` [rad], in ``[0, pi]``: the angle by which the
    rotation ``q_rel = q * conj(q_start)`` (MuJoCo ``wxyz``) turns the world +z axis, the
    swing of the swing-twist decomposition (:func:`z_twist` is the twist),
    ``cos(tilt) = w^2 + z^2 - x^2 - y^2 = 1 - 2 (x^2 + y^2)``. Zero for any rotation about z."""
    w, x, y, z = _relative(quat_start, quat)
    return 2.0 * math.atan2(math.sqrt(x * x + y * y), math.sqrt(w * w + z * z))


def cube_turn(quat: NDArray[np.float64]) -> float:
    """How far a cube with orientation ``quat`` (MuJoCo ``wxyz``, from the scene's keyframe
    orientation) is turned about the vertical from the hand's square [rad], in
    ``[-pi/4, pi/4]``: its twist about z (:func:`z_twist` from the identity) modulo the
    cube's quarter-turn symmetry. 0: faces square to the fingers; +-pi/4: edge first."""
    return math.remainder(z_twist(np.array([1.0, 0.0, 0.0, 0.0]), quat), math.pi / 2)


def check_start_sampling(object: str, replay_prob: float, turned_prob: float) -> None:
    """Raise :class:`FourFingerError` unless ``replay_prob`` and ``turned_prob`` are in
    [0, 1] and turned starts are asked only of the cube (module doc, "Failure replay",
    "Turned cube starts"): the env's check, also run by ``python -m train.ppo``."""
    StartSettings(replay_prob=replay_prob, turned_prob=turned_prob).for_object(object)


class FourFingerRotate(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Rotate a held object about the vertical axis with the four-finger hand.

    Parameters
    ----------
    object : ``"sphere"`` (the thesis'), ``"cylinder"``, ``"cube"``, or the held-out
        ``"capsule"`` and ``"ellipsoid"`` (:data:`~envs.four_finger.physics.OBJECTS`).
    reward : :class:`~envs.four_finger.settings.RewardSettings`, the reward's terms (module
        doc, "Rewards"); default: the thesis' uncapped rotation rate alone.
    sim : :class:`~envs.four_finger.settings.SimSettings`: gravity, torsional friction,
        timestep [s], ``frame_skip`` substeps per policy step (policy period
        ``dt = frame_skip * timestep``), solver and the setpoint step ``q^max`` [rad].
    starts : :class:`~envs.four_finger.settings.StartSettings`: the start-grasp set
        (``"train"`` or ``"test"``, held out) and cache size, the grip (``"nominal"``, the
        thesis' inward grip, or ``"firm"``: also lifting the object and 1 N harder, verified to
        hold still under the worst randomised physics), failure replay and turned cube starts
        (module doc).
    observation : :class:`~envs.four_finger.settings.ObservationSettings`: observed frames
        (``history``) and the critic's privileged state (module doc).
    randomize : a :class:`~envs.four_finger.randomize.Randomization` drawn at every reset, or
        ``None``; physics : a fixed :class:`~envs.four_finger.randomize.PhysicsSample`.
    render_mode : ``None`` or ``"rgb_array"``; render : the
        :class:`~envs.four_finger.settings.RenderSettings` (image size [px], camera).
    **overrides : fields of the groups by name, set on top of them (``drop_weight=1.0``,
        ``gravity=False``, ``history=3``, ``grasps="test"``):
        :func:`~envs.four_finger.settings.apply_overrides`.

    The simulation (``sim``): ``torsional`` contacts have the skin's torsional friction
    (``condim`` 4, coefficient ``TORSIONAL_FRICTION`` = 0.005 m: the torque limit is 0.005 m
    x the normal force, that of a ~7 mm soft contact patch). Off (``condim`` 3, the thesis'
    point contact), a sphere pinched between two antipodal points spins freely about the
    line through them, which nothing resists (docs/four_finger.md). ``solver``: MuJoCo's
    ``"pgs"`` (default) or ``"newton"`` (the hand model's); both solve the same convex contact
    problem, PGS 5x cheaper on it.

    Attributes: the groups as given (``reward``, ``sim``, ``starts``, ``observation``, and
    ``render_settings`` beside the method ``render``), ``physics``
    (:class:`~envs.four_finger.physics.Physics`: ``model``, ``data`` and the contact
    observation), ``grasps`` (the :class:`~envs.four_finger.cache.GraspCache`
    of starting states), ``frame_skip``, ``max_setpoint_step`` and ``dt`` (MujocoEnv's names).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        object: str = "sphere",
        *,
        reward: RewardSettings | None = None,
        sim: SimSettings | None = None,
        starts: StartSettings | None = None,
        observation: ObservationSettings | None = None,
        randomize: Randomization | None = None,
        physics: PhysicsSample | None = None,
        render_mode: str | None = None,
        render: RenderSettings | None = None,
        **overrides: Any,
    ) -> None:
        scene_name(object)
        groups = apply_overrides(
            {
                "reward": RewardSettings() if reward is None else reward,
                "sim": SimSettings() if sim is None else sim,
                "starts": StartSettings() if starts is None else starts,
                "observation": ObservationSettings() if observation is None else observation,
                "render": RenderSettings() if render is None else render,
            },
            overrides,
        )
        self.reward: RewardSettings = groups["reward"]
        self.sim: SimSettings = groups["sim"]
        self.starts: StartSettings = groups["starts"].for_object(object)
        self.observation: ObservationSettings = groups["observation"]
        self.render_settings: RenderSettings = groups["render"]
        if randomize is not None and physics is not None:
            raise FourFingerError("give randomize (drawn per episode) or physics (fixed), not both")
        if render_mode not in (None, "rgb_array"):
            raise FourFingerError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.object = object
        self.render_mode = render_mode
        s = self.sim
        self.physics = Physics(object, s.gravity, s.timestep, s.solver, s.torsional)
        self.model, self.data = self.physics.model, self.physics.data
        self.dt = self.model.opt.timestep * self.frame_skip
        self.grasps = grasp_cache(
            object,
            s.gravity,
            self.starts.n_grasps,
            seed=GRASP_SETS[self.starts.grasps],
            timestep=s.timestep,
            frame_skip=self.frame_skip,
            grip=self.starts.grip,
        )
        self._turned = self._turned_starts()
        self._build_spaces()
        self._z_ref = HOLD_Z  # the height term's reference [m] (reset sets it for "start")
        self._failed: list[tuple[int, PhysicsSample | None]] = []  # failure replay's buffer
        self._grasp = 0
        self._obj_dof = int(self.model.jnt_dofadr[self.model.joint("object").id])
        self._frames = np.zeros((self.observation.history, N_OBS), dtype=np.float32)
        self._obs = np.zeros(N_OBS, dtype=np.float32)
        self._quat = np.zeros(4)
        self._quat0 = np.zeros(4)
        self._angle = 0.0
        self._twist = 0.0
        self._net = 0.0
        self._renderer: Any = None
        self.randomize = randomize
        self.scaler: ModelScaler | None = None
        if randomize is not None:
            self._scaled()
        if physics is not None:
            self._scaled().apply(physics)
        self._prev_action = np.zeros(ff.NU)

    def _scaled(self) -> ModelScaler:
        """The model's :class:`ModelScaler`, made on first use (an env on nominal physics
        needs none)."""
        if self.scaler is None:
            self.scaler = ModelScaler(self.model, self.data, self.physics.obj_body)
        return self.scaler

    def set_randomization(self, randomize: Randomization) -> None:
        """Draw the physics of the episodes from the next reset on from ``randomize`` (a
        curriculum widening the ranges as training goes: ``train.adr``). The current episode
        keeps its physics."""
        if not isinstance(randomize, Randomization):
            raise FourFingerError(f"set_randomization takes a Randomization, got {randomize!r}")
        self._scaled()
        self.randomize = randomize

    @property
    def frame_skip(self) -> int:
        """Physics substeps per policy step (``sim.frame_skip``)."""
        return self.sim.frame_skip

    @property
    def max_setpoint_step(self) -> float:
        """The setpoints' change per policy step at a full action [rad] (``sim``)."""
        return self.sim.max_setpoint_step

    def _turned_starts(self) -> NDArray[np.intp]:
        """Cache indices of the start grasps whose cube is turned by at least ``TURNED``
        (``starts.turned_prob``; none asked: empty)."""
        if self.starts.turned_prob <= 0:
            return np.zeros(0, dtype=np.intp)
        q = self.physics.obj_qpos
        quats = self.grasps.qpos[:, q + 3 : q + 7]
        turned = np.flatnonzero([abs(cube_turn(x)) >= TURNED for x in quats])
        if not len(turned):
            raise FourFingerError("turned_prob: no cached start grasp has the cube turned")
        return turned

    def _build_spaces(self) -> None:
        """The action space and the observation space with its bounds (module doc)."""
        self.action_space = spaces.Box(-1.0, 1.0, (ff.NU,), dtype=np.float32)
        lo = np.concatenate(
            [np.full(ff.NQ, -np.pi), self.physics.ctrl_lo, np.tile([-0.25, -0.25, -0.25, 0.0], 8)]
        )
        hi = np.concatenate(
            [np.full(ff.NQ, np.pi), self.physics.ctrl_hi, np.tile([0.25, 0.25, 0.25, MAX_FORCE], 8)]
        )
        self._lo, self._hi = lo.astype(np.float32), hi.astype(np.float32)
        self._priv_hi = np.repeat(np.float32([0.25, 1.0, 20.0, 5.0]), [3, 4, 6, 5])
        self._priv_lo = np.where(np.arange(N_PRIVILEGED) < 13, -self._priv_hi, 0.0).astype(
            np.float32
        )
        history = self.observation.history
        lo, hi = np.tile(self._lo, history), np.tile(self._hi, history)
        if self.observation.privileged:
            lo, hi = np.concatenate([lo, self._priv_lo]), np.concatenate([hi, self._priv_hi])
        self.observation_space = spaces.Box(lo, hi)

    # -- observation ------------------------------------------------------------------------
    def observe(self) -> NDArray[np.float32]:
        """The observation of the current state (module doc, "Observation Space")."""
        d, o = self.data, self._obs
        o[: ff.NQ] = d.qpos[: ff.NQ]
        o[ff.NQ : 2 * ff.NU] = d.ctrl
        if self.scaler is not None and self.scaler.current.latency:
            # the controller knows what it sent: the setpoint of the action still in flight
            self._setpoints_after(self._prev_action, o[ff.NQ : 2 * ff.NU])
        pos, fn, _ = self.physics.link_contacts()
        c = o[2 * ff.NU :].reshape(len(CONTACT_LINKS), 4)
        c[:, :3] = pos
        c[:, 3] = fn
        return np.minimum(np.maximum(o, self._lo), self._hi)

    def _setpoints_after(self, a: NDArray[np.float64], out: NDArray[Any]) -> None:
        """``out[:] = clip(data.ctrl + a * max_setpoint_step)`` to the servos' ctrlrange: the
        setpoints that action ``a`` commands."""
        ph = self.physics
        ctrl = self.data.ctrl + a * self.max_setpoint_step
        np.minimum(np.maximum(ctrl, ph.ctrl_lo, out=ctrl), ph.ctrl_hi, out=out)

    def _sensed(self) -> NDArray[np.float32]:
        """The observation with the episode's sensor noise (none without randomisation)."""
        o = self.observe()
        if self.scaler is None or not any(self.scaler.current.noise):
            return o
        n = self.scaler.noise(self.np_random, ff.NQ, len(CONTACT_LINKS))
        touching = o[2 * ff.NU + 3 :: 4] > 0
        n[2 * ff.NU :].reshape(-1, 4)[~touching] = 0.0
        return np.minimum(np.maximum(o + n, self._lo), self._hi).astype(np.float32)

    def _stacked(self, frame: NDArray[np.float32], first: bool = False) -> NDArray[np.float32]:
        """The returned observation: the last ``history`` sensed frames, oldest first (at a
        reset every slot holds the first frame); the frame itself when ``history`` is 1;
        followed by :meth:`privileged_state` with ``privileged``."""
        if self.observation.history == 1:
            out = frame
        else:
            f = self._frames
            if first:
                f[:] = frame
            else:
                f[:-1] = f[1:]
                f[-1] = frame
            out = f.reshape(-1).copy()
        if self.observation.privileged:
            return np.concatenate([out, self.privileged_state()])
        return out

    def privileged_state(self) -> NDArray[np.float32]:
        """What the critic alone may see (module doc, ``privileged=True``)."""
        ph = self.physics
        s = self.scaler.current if self.scaler is not None else None
        phys = (1.0, 1.0, 1.0, 1.0, 0.0)
        if s is not None:
            phys = (s.friction, s.torsional, s.mass, float(np.mean(s.gain)), float(s.latency))
        v = self.data.qvel[self._obj_dof : self._obj_dof + 6]
        out = np.concatenate([ph.object_pos(), ph.object_quat(), v, phys]).astype(np.float32)
        return np.minimum(np.maximum(out, self._priv_lo), self._priv_hi)

    def _sag(self) -> float:
        """How far the object's centre sits below the reference ``z_ref`` (``HOLD_Z``, or its
        start height with ``height_from="start"``), as a fraction of the way down to
        ``DROP_Z``: ``max(0, z_ref - z) / (z_ref - DROP_Z)`` (1 at the drop threshold)."""
        z = float(self.physics.object_pos()[2])
        return max(0.0, self._z_ref - z) / (self._z_ref - DROP_Z)

    def _yaw_rate(self, quat_before: NDArray[np.float64]) -> float:
        """Mean angular velocity about world +z since ``quat_before`` [rad/s]."""
        return yaw_rate(quat_before, self.physics.object_quat(), self.dt)

    # -- gym API ----------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start from a cached stable grasp (``options={"grasp": i}`` picks one) under the
        episode's physics (``options={"physics": s}``, a :class:`PhysicsSample`, sets it from
        this episode on; else a ``randomize`` draw, or the physics kept)."""
        super().reset(seed=seed)
        i = None if options is None else options.get("grasp")
        replay = None
        starts = self.starts
        if i is None and self._failed and self.np_random.uniform() < starts.replay_prob:
            replay = self._failed.pop(int(self.np_random.integers(len(self._failed))))
            i = replay[0]
        if i is None and starts.turned_prob > 0 and self.np_random.uniform() < starts.turned_prob:
            i = int(self._turned[self.np_random.integers(len(self._turned))])
        if i is None:
            i = int(self.np_random.integers(len(self.grasps)))
        elif not isinstance(i, (int, np.integer)) or not 0 <= i < len(self.grasps):
            raise FourFingerError(f"options['grasp'] must be in [0, {len(self.grasps)}), got {i!r}")
        m, d = self.model, self.data
        given = None if options is None else options.get("physics")
        if given is not None:
            if not isinstance(given, PhysicsSample):
                raise FourFingerError(f"options['physics'] must be a PhysicsSample, got {given!r}")
            self._scaled().apply(given)
        elif self.randomize is not None:  # a replayed start keeps its physics (never None here)
            s = replay[1] if replay is not None else self.randomize.sample(self.np_random, ff.NU)
            self.scaler.apply(s)  # type: ignore[union-attr, arg-type]
        self._grasp = int(i)
        self._prev_action[:] = 0.0
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self.grasps.qpos[i]
        d.ctrl[:] = self.grasps.ctrl[i]
        mujoco.mj_forward(m, d)
        if self.reward.height_from == "start":  # kept above DROP_Z for a user's own grasps
            self._z_ref = max(float(self.physics.object_pos()[2]), DROP_Z + 1e-3)
        self._angle = self._twist = self._net = 0.0
        self._quat0[:] = self.physics.object_quat()
        obs = self._stacked(self._sensed(), first=True)
        return obs, {"grasp": i, "rotation_angle": 0.0, "net_turn": 0.0}

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (ff.NU,):
            raise FourFingerError(f"action must have shape ({ff.NU},), got {a.shape}")
        if not np.isfinite(a).all():
            raise FourFingerError(f"action contains NaN or inf: {a}")
        a = np.minimum(np.maximum(a, -1.0), 1.0)  # np.clip's Python wrapper costs 3x more
        if self.scaler is not None and self.scaler.current.latency:
            a, self._prev_action = self._prev_action, a  # one policy step late
        d, ph = self.data, self.physics
        self._setpoints_after(a, d.ctrl)
        self._quat[:] = ph.object_quat()
        mujoco.mj_step(self.model, d, nstep=self.frame_skip)
        rate = self._yaw_rate(self._quat)
        self._angle += rate * self.dt
        twist = z_twist(self._quat0, ph.object_quat())
        self._net += math.remainder(twist - self._twist, 2.0 * math.pi)
        self._twist = twist
        dropped = ph.dropped()
        if dropped and self.starts.replay_prob > 0:
            self._failed.append((self._grasp, self.scaler.current if self.scaler else None))
            del self._failed[:-REPLAY_SIZE]
        r = self.reward
        cap = r.rotation_cap
        terms = {
            "rotation": rate if -cap <= rate <= cap else math.copysign(cap, rate),
            "drop": -r.drop_weight if dropped else 0.0,
            "action": -r.action_weight * float(a @ a) / ff.NU,
            "height": -r.height_weight * self._sag(),
            "slip": -r.slip_weight * ph.object_slip() if r.slip_weight else 0.0,
            "tilt": -r.tilt_weight * z_tilt(self._quat0, ph.object_quat())
            if r.tilt_weight
            else 0.0,
        }
        reward = sum(terms.values())
        info = {
            **terms,
            "dropped": dropped,
            "rotation_angle": self._angle,
            "net_turn": self._net,
        }
        return self._stacked(self._sensed()), reward, dropped, False, info

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB frame (``height, width, 3``) from the side or top camera."""
        if self.render_mode != "rgb_array":
            return None
        from ihm.render import make_renderer

        view = self.render_settings
        if self._renderer is None:
            vis = self.model.vis
            vis.global_.offwidth = max(vis.global_.offwidth, view.width)
            vis.global_.offheight = max(vis.global_.offheight, view.height)
            if self.model.nlight == 0:  # the scenes have no lights: a brighter headlight
                vis.headlight.ambient[:] = np.maximum(vis.headlight.ambient, 0.35)
                vis.headlight.diffuse[:] = np.maximum(vis.headlight.diffuse, 0.6)
            self._renderer = make_renderer(self.model, view.width, view.height)
        cam = mujoco.MjvCamera()
        cam.lookat[:] = [0.0, 0.0, 0.06]
        cam.distance = 0.32
        cam.azimuth, cam.elevation = (45.0, -20.0) if view.camera == "side" else (90.0, -89.0)
        self._renderer.update_scene(self.data, camera=cam)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
