"""Grasp scenes: load an MJCF scene and settle the grasp.

A scene is one file ``assets/scenes/<name>.xml`` (the thesis' scenes, by name) or any
MJCF file given by its path (:func:`is_scene_file`); it includes a hand model and adds
the grasped object. Everything :func:`load_scene` needs is in that file, so that adding
a scene is adding a file:

* a free body (default name ``object``, ``load_scene``'s ``object_body``): the object;
* optionally a keyframe named ``init``: the hand slightly open around the object
  (without one the scene starts from the model's default pose, ``qpos0``);
* optionally ``<custom><numeric name="ihm_preload" data="..."/></custom>``: the default
  commanded actuator forces, one per actuator, in the actuator's own unit (N m for a
  joint motor, N for a tendon); without it the scene settles with the ``init`` keyframe's
  controls ``ctrl`` (zeros without a keyframe) held, as MuJoCo would simulate the file;
* ``<custom><text name="ihm_hand" data="..."/></custom>``: the hand's name (our scenes);
* optionally ``<custom><text name="ihm_about" data="..."/></custom>``: what grasp it is.

Settling (:func:`settle`) is documented there; it ends when every velocity of
the model is below ``vtol`` for ``hold_s`` seconds of simulated time (both fields of
:class:`SettleOptions`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .contacts import body_subtree
from .ratchet import Ratchet, actuated_joints, actuated_tendons
from .scene_files import (
    SceneError,
    as_forces,
    check_free_body,
    custom_text,
    default_preload,
    is_scene_file,
    scene_label,
    seat_forces,
    start_commands,
)

__all__ = [
    "SCENES_DIR",
    "LoadedScene",
    "SceneError",
    "SettleInfo",
    "SettleOptions",
    "available_scenes",
    "default_preload",
    "is_scene_file",
    "load_scene",
    "scene_about",
    "scene_label",
    "scene_path",
    "settle",
    "transmission_ratchet",
]

SCENES_DIR = Path(__file__).resolve().parent.parent / "assets" / "scenes"


def available_scenes() -> list[str]:
    """Names of the scenes in ``assets/scenes`` (file stems), sorted."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.xml"))


def scene_path(name: str) -> Path:
    """Path of scene ``name``: the file itself, absolute, when ``name`` is a path
    (:func:`is_scene_file`), else ``assets/scenes/<name>.xml``; :class:`SceneError` for a
    missing file or an unknown name (listing the known scenes)."""
    if is_scene_file(name):
        path = Path(name).expanduser()
        if not path.is_file():
            raise SceneError(f"scene file {name!r} not found")
        return path.resolve()
    known = available_scenes()
    if name not in known:
        raise SceneError(f"unknown scene {name!r}; known scenes: {', '.join(known) or '(none)'}")
    return SCENES_DIR / f"{name}.xml"


def scene_about(name: str) -> str:
    """The one-line description stored in the scene file (``ihm_about``)."""
    model = mujoco.MjModel.from_xml_path(str(scene_path(name)))
    return custom_text(model, "ihm_about") or ""


@dataclass
class SettleInfo:
    """What :func:`settle` did.

    Attributes
    ----------
    time_s : simulated time until rest [s]
    wall_s : wall-clock time of the settle [s]
    steps : simulation steps taken
    max_vel : largest ``|qvel|`` at the end [m/s or rad/s]
    commands : actuator forces commanded [actuator units]
    rounds : setpoint rounds (position actuators only; 1 otherwise)
    force_error : ``max |actuator_force - commands|`` at rest [actuator units];
        0 for motors. For servos it stays nonzero when the rounds run out:
        fixed joint torques cannot balance a fully actuated fingertip grasp
        (the thesis' argument for position control), so the servo springs
        carry the object's weight share.
    contacts : MuJoCo contacts at rest (``data.ncon``)
    """

    time_s: float
    wall_s: float
    steps: int
    max_vel: float
    commands: NDArray[np.float64]
    rounds: int = 1
    force_error: float = 0.0
    contacts: int = 0


@dataclass(frozen=True)
class LoadedScene:
    """What :func:`load_scene` returns: the compiled ``model``, its ``data`` at rest, the
    ``settle_info`` of the settle that brought it there (None with ``settle_grasp=False``),
    the ``ratchet`` on its nonbackdrivable transmission (None unless ``nonbackdrivable``)
    and the ``commands``: the actuator forces the grasp is held with, (nu,) in each
    actuator's unit (the preload; a scene settled by its controls: the actuator forces at
    rest). It unpacks as ``model, data``."""

    model: mujoco.MjModel
    data: mujoco.MjData
    settle_info: SettleInfo | None
    ratchet: Ratchet | None
    commands: NDArray[np.float64]

    def __iter__(self) -> Iterator[mujoco.MjModel | mujoco.MjData]:
        return iter((self.model, self.data))


def _affine(model: mujoco.MjModel) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per actuator, at rest (velocity 0), ``force = g(L) ctrl + b(L)`` with ``L`` the
    actuator length: returns ``(gain_coefficients, bias_coefficients)``, each (nu, 2) as
    ``(c0, c1)`` in ``c0 + c1 L``. Raises :class:`SceneError` naming an actuator whose
    force the commands cannot set this way (muscle or user gain/bias, integrator or
    muscle dynamics: at rest its force is not a function of ``ctrl``)."""
    G = np.zeros((model.nu, 2))
    B = np.zeros((model.nu, 2))
    for a in range(model.nu):
        name = model.actuator(a).name or f"#{a}"
        gt, bt, dt = (
            model.actuator_gaintype[a],
            model.actuator_biastype[a],
            model.actuator_dyntype[a],
        )
        if gt not in (int(mujoco.mjtGain.mjGAIN_FIXED), int(mujoco.mjtGain.mjGAIN_AFFINE)):
            raise SceneError(f"actuator {name}: gain type {mujoco.mjtGain(int(gt)).name} is not "
                             "supported by settle (fixed or affine are)")  # fmt: skip
        if bt not in (int(mujoco.mjtBias.mjBIAS_NONE), int(mujoco.mjtBias.mjBIAS_AFFINE)):
            raise SceneError(f"actuator {name}: bias type {mujoco.mjtBias(int(bt)).name} is not "
                             "supported by settle (none or affine are)")  # fmt: skip
        if dt not in (int(mujoco.mjtDyn.mjDYN_NONE), int(mujoco.mjtDyn.mjDYN_FILTER),
                      int(mujoco.mjtDyn.mjDYN_FILTEREXACT)):  # fmt: skip
            raise SceneError(
                f"actuator {name}: dynamics {mujoco.mjtDyn(int(dt)).name}: its force at rest is "
                "not set by ctrl; settle supports none and filter"
            )
        g = model.actuator_gainprm[a]
        G[a] = (g[0], g[1] if gt == int(mujoco.mjtGain.mjGAIN_AFFINE) else 0.0)
        if bt == int(mujoco.mjtBias.mjBIAS_AFFINE):
            B[a] = model.actuator_biasprm[a, :2]
    return G, B


def _commanded_ctrl(
    model: mujoco.MjModel, data: mujoco.MjData, f_c: NDArray[np.float64],
    G: NDArray[np.float64], B: NDArray[np.float64],
) -> NDArray[np.float64]:  # fmt: skip
    """The ``ctrl`` that makes each actuator give force ``f_c`` at its present length at
    rest: ``(f_c - b(L)) / g(L)``. A force at a bound of the actuator's ``forcerange`` asks
    for saturation: ``ctrl`` goes to the end of ``ctrlrange`` that drives it there (a
    gripper's "close with full force")."""
    L = data.actuator_length
    gain = G[:, 0] + G[:, 1] * L
    bias = B[:, 0] + B[:, 1] * L
    ctrl = (f_c - bias) / np.where(np.abs(gain) > 1e-12, gain, 1.0)
    for a in np.flatnonzero(model.actuator_forcelimited.astype(bool)):
        lo, hi = model.actuator_forcerange[a]
        if hi <= lo or not (np.isclose(f_c[a], lo) or np.isclose(f_c[a], hi)):
            continue
        up = np.isclose(f_c[a], hi) == (gain[a] > 0)
        if model.actuator_ctrllimited[a]:
            ctrl[a] = model.actuator_ctrlrange[a, 1 if up else 0]
        else:
            ctrl[a] = ctrl[a] + (1.0 if up else -1.0) * 10.0 * (1.0 + abs(f_c[a]) / abs(gain[a]))
    return ctrl


@contextmanager
def _gravity_off(model: mujoco.MjModel) -> Iterator[None]:
    """Gravity switched off inside the block, restored after it (also on errors)."""
    gravity = model.opt.gravity.copy()
    model.opt.gravity[:] = 0.0
    try:
        yield
    finally:
        model.opt.gravity[:] = gravity


def _step(model: mujoco.MjModel, data: mujoco.MjData, ratchet: Ratchet | None) -> None:
    """One physics step; with a ratchet, its stops follow (:meth:`Ratchet.step`)."""
    if ratchet is None:
        mujoco.mj_step(model, data)
    else:
        ratchet.step()


def _run_until_rest(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    vtol: float,
    hold_s: float,
    min_s: float,
    max_s: float,
    ratchet: Ratchet | None = None,
) -> tuple[int, float]:
    """Step until ``max |qvel| < vtol`` for ``hold_s`` [s]; returns (steps, max |qvel|)."""
    dt = model.opt.timestep
    hold_steps = max(1, int(round(hold_s / dt)))
    min_steps = int(round(min_s / dt))
    max_steps = int(round(max_s / dt))
    calm = 0
    vmax = np.inf
    for k in range(max_steps):
        _step(model, data, ratchet)
        vmax = float(np.abs(data.qvel).max()) if model.nv else 0.0
        if not np.isfinite(vmax):
            raise SceneError(f"simulation diverged (qvel not finite) at t = {data.time:.3f} s")
        calm = calm + 1 if vmax < vtol else 0
        if calm >= hold_steps and k + 1 >= min_steps:
            return k + 1, vmax
    return max_steps, vmax


@dataclass(frozen=True)
class SettleOptions:
    """Tolerances and time limits of :func:`settle` (its steps 1-4), in simulated time.

    vtol : rest is every generalized velocity below this [m/s, rad/s] (> 0)
    hold_s : ... for this many consecutive seconds [s] (>= 0)
    grip_s : the grip with gravity off before rest is sought [s] (>= 0)
    max_s : the longest wait for rest, per force round [s] (> 0)
    rounds : force rounds at most (an integer >= 1)
    ftol : a round ends the rounds when every ``|actuator_force - f_c| <= ftol (1 + |f_c|)``
        [actuator units per unit of ``1 + |f_c|``]
    force_tol : an actuator whose ``ctrl`` is at the end of ``ctrlrange`` and that misses
        its command by more than ``force_tol (1 + |f_c|)`` raises (> 0, same units)

    Invalid values raise :class:`SceneError` when the options are made.
    """

    vtol: float = 1e-4
    hold_s: float = 0.05
    grip_s: float = 0.3
    max_s: float = 10.0
    rounds: int = 6
    ftol: float = 1e-3
    force_tol: float = 0.05

    def __post_init__(self) -> None:
        times = (("vtol", self.vtol), ("hold_s", self.hold_s), ("grip_s", self.grip_s),
                 ("max_s", self.max_s))  # fmt: skip
        for key, value in times:
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise SceneError(f"{key} must be a finite number >= 0, got {value!r}")
        if self.vtol <= 0 or self.max_s <= 0:
            raise SceneError(
                f"vtol and max_s must be > 0, got vtol={self.vtol!r}, max_s={self.max_s!r}"
            )
        if not isinstance(self.rounds, (int, np.integer)) or self.rounds < 1:
            raise SceneError(f"rounds must be an integer >= 1, got {self.rounds!r}")
        if not (np.isfinite(self.force_tol) and self.force_tol > 0):
            raise SceneError(f"force_tol must be a finite number > 0, got {self.force_tol!r}")


@dataclass(frozen=True)
class _Drive:
    """How :func:`settle` sets ``data.ctrl``: the commands ``f_c`` taken as controls
    (``by_ctrl``) or as actuator forces through the rest-state gain and bias coefficients
    ``G``, ``B`` (:func:`_affine`). ``feedback``: (nu,) actuators whose force depends on
    their length (force rounds needed)."""

    f_c: NDArray[np.float64]
    G: NDArray[np.float64]
    B: NDArray[np.float64]
    by_ctrl: bool
    feedback: NDArray[np.bool_]

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Set ``data.ctrl`` for the commands at the present actuator lengths."""
        data.ctrl[:] = self.f_c if self.by_ctrl else _commanded_ctrl(model, data, self.f_c,
                                                                      self.G, self.B)  # fmt: skip


def _settle_commands(
    model: mujoco.MjModel, commands: ArrayLike, command: str
) -> NDArray[np.float64]:
    """``commands`` as (nu,) floats, checked: finite, ``command`` "force" or "ctrl", within
    ``ctrlrange`` (controls) or ``forcerange`` (forces); :class:`SceneError` otherwise."""
    f_c = as_forces(commands, model.nu).reshape(-1)
    if f_c.shape != (model.nu,):
        raise SceneError(f"commands has {f_c.size} values for {model.nu} actuators")
    if not np.all(np.isfinite(f_c)):
        raise SceneError("commands contain NaN or inf")
    if command not in ("force", "ctrl"):
        raise SceneError(f"command must be 'force' or 'ctrl', got {command!r}")
    by_ctrl = command == "ctrl"
    if by_ctrl:
        lo_c, hi_c = model.actuator_ctrlrange.T
        out = model.actuator_ctrllimited.astype(bool) & ((f_c < lo_c) | (f_c > hi_c))
        if out.any():
            a = int(np.flatnonzero(out)[0])
            raise SceneError(f"actuator {model.actuator(a).name or a}: ctrl {f_c[a]:g} is "
                             f"outside its ctrlrange [{lo_c[a]:g}, {hi_c[a]:g}]")  # fmt: skip
    for a in np.flatnonzero(model.actuator_forcelimited.astype(bool) & (not by_ctrl)):
        flo, fhi = model.actuator_forcerange[a]
        if fhi > flo and not (flo - 1e-9 <= f_c[a] <= fhi + 1e-9):
            raise SceneError(
                f"actuator {model.actuator(a).name or a}: command {f_c[a]:g} is outside its "
                f"forcerange [{flo:g}, {fhi:g}]"
            )
    return f_c


def _drive(model: mujoco.MjModel, f_c: NDArray[np.float64], by_ctrl: bool) -> _Drive:
    """The :class:`_Drive` of the commands; an actuator with zero gain raises
    :class:`SceneError` (its force cannot be commanded)."""
    G, B = _affine(model)
    if np.any(np.abs(G[:, 0]) + np.abs(G[:, 1]) < 1e-12):
        bad = [model.actuator(a).name for a in np.flatnonzero(np.abs(G).sum(axis=1) < 1e-12)]
        raise SceneError(f"actuator(s) {bad} have zero gain; cannot command their force")
    feedback = np.abs(B[:, 1]) + np.abs(G[:, 1]) > 0  # force depends on length: rounds
    if by_ctrl:
        feedback[:] = False  # controls are set once: no force rounds
    return _Drive(f_c, G, B, by_ctrl, feedback)


def _grip(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    drive: _Drive,
    grip_s: float,
    ratchet: Ratchet | None,
) -> int:
    """Step 1: ``grip_s`` [s] of steps with gravity off, the controls reset every step;
    returns the steps taken."""
    with _gravity_off(model):
        n_grip = int(round(grip_s / model.opt.timestep))
        for _ in range(n_grip):
            drive.apply(model, data)  # servos act as pure force sources while the fingers close
            _step(model, data, ratchet)
    return n_grip


def _force_rounds(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    drive: _Drive,
    opts: SettleOptions,
    ratchet: Ratchet | None,
) -> tuple[int, int, float]:
    """Steps 2 and 3: rest, then (where a force depends on its actuator's length) reset
    the controls and rest again until the forces match or the rounds run out. Returns
    (steps, rounds, max ``|qvel|`` at the end); :class:`SceneError` if a round does not
    come to rest within ``opts.max_s``."""
    steps = 0
    done_rounds = 0
    vmax = np.inf
    for done_rounds in range(1, opts.rounds + 1):  # noqa: B007
        k, vmax = _run_until_rest(model, data, opts.vtol, opts.hold_s, 0.0, opts.max_s, ratchet)
        steps += k
        if vmax >= opts.vtol:
            raise SceneError(
                f"grasp not at rest after {opts.max_s:.1f} s simulated (max |qvel| = {vmax:.3g} "
                f"> {opts.vtol:g}); the object may have slipped out"
            )
        if not drive.feedback.any():
            break
        err = np.abs(data.actuator_force - drive.f_c)
        if np.all(err <= opts.ftol * (1 + np.abs(drive.f_c))) or done_rounds == opts.rounds:
            break  # converged, or out of rounds: keep the state at rest
        drive.apply(model, data)
    return steps, done_rounds, vmax


def _check_reached(
    model: mujoco.MjModel, data: mujoco.MjData, drive: _Drive, force_tol: float
) -> None:
    """Step 4's force check: an actuator whose ``ctrl`` sits at the end of ``ctrlrange``
    and misses its commanded force by more than ``force_tol (1 + |f_c|)`` raises
    :class:`SceneError` (the command needs a ``ctrl`` beyond the range)."""
    f_c = drive.f_c
    err = np.abs(data.actuator_force - f_c) if model.nu else np.zeros(0)
    lo, hi = model.actuator_ctrlrange.T
    pinned = model.actuator_ctrllimited.astype(bool) & (
        np.isclose(data.ctrl, lo) | np.isclose(data.ctrl, hi)
    )
    bad = np.flatnonzero(pinned & (err > force_tol * (1 + np.abs(f_c))) & (not drive.by_ctrl))
    if bad.size:
        a = int(bad[0])
        raise SceneError(
            f"actuator {model.actuator(a).name or a} gives {data.actuator_force[a]:.4g} at "
            f"rest, not the commanded {f_c[a]:.4g}: its ctrl {data.ctrl[a]:.4g} is at the end "
            f"of ctrlrange [{lo[a]:g}, {hi[a]:g}] (force_tol {force_tol:g})"
        )


def settle(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    commands: ArrayLike,
    *,
    options: SettleOptions | None = None,
    ratchet: Ratchet | None = None,
    object_body: str | None = "object",
    command: str = "force",
) -> SettleInfo:
    """Close the hand with actuator forces ``commands`` until the grasp is at rest.

    ``options``: the tolerances and time limits (:class:`SettleOptions`; its defaults when
    None). ``command="ctrl"`` takes ``commands`` as MuJoCo controls instead (``data.ctrl``:
    a position servo's target position, a gripper's 0-255 closing command), set once;
    steps 3 and 4's force rounds and force checks are skipped, the others are the same.

    Procedure (simulated time, ``model.opt.timestep`` per step):

    1. *Grip* for ``grip_s`` seconds with gravity switched off, so that the
       fingers close on the object before it can fall (servos track
       ``ctrl = length + f_c / kp`` every step: a pure force source).
    2. Switch gravity back on and step until every generalized velocity is
       below ``vtol`` [m/s, rad/s] for ``hold_s`` consecutive seconds.
    3. Every actuator is driven to its commanded *force*, whatever its gain and bias
       (MuJoCo ``general``: ``force = (g0 + g1 L) ctrl + b0 + b1 L`` at rest, ``L`` its
       length: motors, position servos such as the four-finger hand's series-elastic
       joints, a rescaled servo with ``gain != kp`` such as a Robotiq gripper's, on
       joints or tendons): ``ctrl = (f_c - b(L)) / g(L)``. A command at a bound of the
       actuator's ``forcerange`` drives it to saturation (``ctrl`` at the end of its
       ``ctrlrange``). Where the force depends on ``L`` each round resets ``ctrl`` and
       repeats step 2, until ``|actuator_force - f_c| <= ftol (1 + |f_c|)`` or ``rounds``
       rounds; the remaining error is :attr:`SettleInfo.force_error`.
    4. Checks: a command outside the actuator's ``forcerange``, or one that needs a
       ``ctrl`` beyond ``ctrlrange`` (missed by more than ``force_tol (1 + |f_c|)`` with
       ``ctrl`` at the range's end) raises :class:`SceneError` naming the actuator.
       With ``object_body`` (default ``"object"``, None to skip; skipped when the
       model has no such body), the object touches a moving hand body (else "the
       fingers did not close" or "the object fell": it rests on static bodies only).

    With ``ratchet`` (:class:`ihm.ratchet.Ratchet`) every step is ``ratchet.step()``: the
    ratcheted joints and tendons can close but not open, so an actuator commanded 0 is a
    passive, nonbackdrivable support (the thesis' preload protocol of grasp example 2).

    Raises :class:`SceneError` if the grasp is not at rest after ``max_s``
    simulated seconds (per round), the simulation diverges, an actuator's force cannot
    be set by ``ctrl`` (muscle, integrator dynamics) or misses its command, or the
    object is not held (step 4).
    """
    opts = SettleOptions() if options is None else options
    f_c = _settle_commands(model, commands, command)
    t0 = time.perf_counter()
    drive = _drive(model, f_c, command == "ctrl")
    mujoco.mj_forward(model, data)
    drive.apply(model, data)
    steps = _grip(model, data, drive, opts.grip_s, ratchet)
    k, done_rounds, vmax = _force_rounds(model, data, drive, opts, ratchet)
    steps += k
    mujoco.mj_forward(model, data)
    _check_reached(model, data, drive, opts.force_tol)
    if object_body is not None:
        _check_held(model, data, object_body)
    return SettleInfo(
        time_s=float(data.time),
        wall_s=time.perf_counter() - t0,
        steps=steps,
        max_vel=vmax,
        commands=f_c,
        rounds=done_rounds,
        force_error=float(np.abs(data.actuator_force - f_c).max())
        if model.nu and not drive.by_ctrl
        else 0.0,
        contacts=int(data.ncon),
    )


def _check_held(model: mujoco.MjModel, data: mujoco.MjData, object_body: str) -> None:
    """:class:`SceneError` unless the object touches a hand body that can move."""
    obj = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, object_body)
    if obj < 0:
        return
    inside = body_subtree(model, obj)
    moving, static = set(), set()
    for c in data.contact[: data.ncon]:
        b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
        if inside[b1] == inside[b2]:
            continue
        other = int(b2 if inside[b1] else b1)
        (moving if _moves(model, other) else static).add(model.body(other).name or str(other))
    if moving:
        return
    if static:
        raise SceneError(f"the object fell: at rest it touches only static bodies "
                         f"{sorted(static)}, no finger")  # fmt: skip
    raise SceneError(
        "the fingers did not close: at rest the object touches nothing "
        "(commands too small, the wrong sign, or the object out of reach)"
    )


def _moves(model: mujoco.MjModel, b: int) -> bool:
    """Body ``b`` or one of its ancestors has a degree of freedom."""
    while b > 0:
        if model.body_dofnum[b]:
            return True
        b = int(model.body_parentid[b])
    return False


def _compile(name: str) -> mujoco.MjModel:
    """The compiled model of scene ``name``; :class:`SceneError` (one line) if MuJoCo
    cannot compile it."""
    path = scene_path(name)
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:  # mujoco reports XML errors as ValueError
        why = " ".join(str(exc).split())
        raise SceneError(f"scene {name!r} ({path}) does not compile: {why}") from exc


def load_scene(
    name: str,
    preload: ArrayLike | None = None,
    *,
    settle_grasp: bool = True,
    nonbackdrivable: bool = False,
    seat: ArrayLike | None = None,
    gravity: bool = True,
    object_body: str = "object",
    **settle_kwargs: float,
) -> LoadedScene:
    """Load scene ``name`` and settle its grasp.

    Parameters
    ----------
    name : a scene in ``assets/scenes`` (see :func:`available_scenes`) or an MJCF file's
        path (:func:`is_scene_file`).
    preload : commanded actuator forces, shape (nu,), in each actuator's unit
        (N m for joint motors and servos, N for tendons). Default: the scene's
        ``ihm_preload``; without one, the ``init`` keyframe's controls (module doc).
    settle_grasp : if False, return the start state (the ``init`` keyframe, else the
        model's defaults) without simulating, ``ctrl`` 0.
    nonbackdrivable : after settling, put a :class:`ihm.ratchet.Ratchet` on every joint
        driven by a plain motor (the Barrett fingers' worm gears) and every actuated tendon
        (the tendon gripper's transmission): the stops sit at the settled pose and follow
        as the fingers close when the ratchet's ``update`` or ``step`` is used. The
        ratchet is the result's ``ratchet``.
    seat : with ``nonbackdrivable``, the thesis' protocol for preloading chosen actuators
        only (grasp example 2: "preload applied exclusively by finger 1"; the tendon
        gripper's "actively loading the distal tendon only"): first settle with the
        commands ``seat`` (a light closing force on every actuator, so that every finger
        touches; gravity off, so that the seat carries no weight and its own load stays
        small), put the ratchet on at that pose, then switch (gravity on) to ``preload`` and
        settle again with the ratchet following. An actuator commanded 0 in ``preload`` is
        then a passive, nonbackdrivable support: its joint (tendon) cannot open, and the
        reaction it carries is what the commanded ones produce. ``preload`` must be >= 0
        where it is ratcheted. Position servos (the Barrett spread) hold the pose of the
        ``init`` keyframe throughout (no grip phase, one round: the thesis models them
        rigid), where a plain settle drives them toward their commanded force in rounds.
        Without ``seat`` the grasp settles with ``preload`` and the ratchet goes on after.
    gravity : False switches the scene's gravity off (``model.opt.gravity = 0``) for good,
        e.g. to map loads that stand for the object's own weight turned around (pouring).
    object_body : the grasped free body (:func:`settle` checks that the hand holds it).
    settle_kwargs : fields of :class:`SettleOptions` for :func:`settle` (``vtol``,
        ``hold_s``, ...); the seated protocol's settles default to ``grip_s=0``,
        ``rounds=1`` (and ``vtol=1e-3`` for the ratcheted one).

    Returns
    -------
    :class:`LoadedScene`: the model, ``data`` at rest (``data.ctrl`` holds the controls), the
    settle report, the ratchet and the commands; it unpacks as ``model, data``.
    """
    model = _compile(name)
    check_free_body(model, object_body, name)
    if not gravity:
        model.opt.gravity[:] = 0.0
    data = mujoco.MjData(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "init")
    if key >= 0:  # else MjData's defaults: qpos0, ctrl 0
        mujoco.mj_resetDataKeyframe(model, data, key)
    f_c, command = start_commands(model, data, preload, name)
    if seat is not None and not (nonbackdrivable and settle_grasp):
        raise SceneError("seat is the nonbackdrivable preload protocol: it needs "
                         "nonbackdrivable=True and settle_grasp=True")  # fmt: skip
    seat_c = None if seat is None else seat_forces(seat, model.nu, name)
    report: SettleInfo | None = None
    ratchet: Ratchet | None = None
    if not settle_grasp:
        data.ctrl[:] = 0.0
        mujoco.mj_forward(model, data)
    else:
        try:
            report, ratchet = _settle_scene(model, data, f_c, seat_c, command, object_body,
                                            settle_kwargs)  # fmt: skip
        except SceneError as exc:
            if command == "force":
                raise
            hint = f"no ihm_preload: it settled with its start state's controls {f_c.tolist()}"
            raise SceneError(f"{exc} (scene {name!r} has {hint}; give a preload)") from exc
    if nonbackdrivable and ratchet is None:
        ratchet = transmission_ratchet(model, data)
    forces = f_c if command == "force" else data.actuator_force.copy()
    return LoadedScene(model, data, report, ratchet, forces)


def _settle_scene(
    model: mujoco.MjModel, data: mujoco.MjData, f_c: NDArray[np.float64],
    seat_c: NDArray[np.float64] | None, command: str, object_body: str,
    settle_kwargs: dict[str, float],
) -> tuple[SettleInfo, Ratchet | None]:  # fmt: skip
    """:func:`load_scene`'s settle: with the commands ``f_c`` (``command``: forces or
    controls), or the seated protocol when ``seat_c`` is given (its ratchet returned)."""
    held = {"object_body": object_body, "command": command}
    if seat_c is None:
        return settle(model, data, f_c, options=SettleOptions(**settle_kwargs), **held), None
    seated = replace(SettleOptions(grip_s=0.0, rounds=1), **settle_kwargs)
    with _gravity_off(model):  # the object placed in the hand, the fingers closed lightly
        settle(model, data, seat_c, options=seated, object_body=object_body)
    ratchet = transmission_ratchet(model, data)
    # the loaded, ratcheted grasp jitters at up to ~5e-4 rad/s (measured on barrett_cube:
    # spread servo and thumb, the elliptic friction cones against the stiff stops) while
    # positions stay within micrometres: rest means |qvel| < 1e-3 here
    loaded = replace(SettleOptions(grip_s=0.0, rounds=1, vtol=1e-3), **settle_kwargs)
    return settle(model, data, f_c, options=loaded, ratchet=ratchet, **held), ratchet


def transmission_ratchet(model: mujoco.MjModel, data: mujoco.MjData) -> Ratchet:
    """The scene's nonbackdrivable transmission: motor joints and actuated tendons."""
    return Ratchet(model, data, actuated_joints(model), tendons=actuated_tendons(model))
