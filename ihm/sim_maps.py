"""Resistible-force maps of the thesis' scenes simulated in MuJoCo: ``python -m ihm map``.

For a scene, a plane of two world force axes (the palm frame of the hands: MuJoCo's world
frame) and commands, the simulated resistance (:func:`ihm.resistance.simulated_resistance`)
per direction ``u = cos(a) e_1 + sin(a) e_2``, ``a`` from the plane's first axis towards its
second. The directions are independent and run in parallel (``workers``): the scene is
settled once, in the calling process, and every worker restores that state for each of
its directions (the same numbers for any number of workers). The result is a
:class:`stability.maps.ResistibleMap` (method ``"sim"``), written as CSV and drawn on a
polar PNG with :func:`stability.maps.plot_resistible`.

Any stability method that answers MaxDisturbance on spatial grasps (``modesearch``, the
default, ``refinement``, ``iterative``, ``no_mdp``, ``exact``, ``gws``) maps the same
directions on the grasp read off the settled scene (:func:`ihm.contacts.grasp_from_mujoco`):
the load is the same force through the object's centre of mass, written in the object
frame as the wrench ``(R^T u, c x R^T u)`` about the object origin (``c`` the centre of
mass in the object frame), the object's weight is the query's base load
(``SceneGrasp.gravity_wrench``) and the commands are the preload the scene was settled
with. Directions whose solve fails (time-out) are NaN in the map.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from stability import GraspError
from stability.api import DEFAULT_SPATIAL_METHOD, RENAMED_METHODS
from stability.io import write_csv
from stability.maps import ResistibleMap, plane_axes, plot_resistible, radial_top

from . import scenes
from .contact_law import CONTACT_LAWS
from .resistance import ResistanceOptions, simulated_resistance

__all__ = [
    "METHODS",
    "MapError",
    "MapSpec",
    "agreement",
    "analysis_map",
    "check_options",
    "map_value",
    "plot_maps",
    "ramp_limit",
    "scene_preload",
    "scene_map_rows",
    "simulated_map",
    "write_map_csv",
]

METHODS = ("sim", "modesearch", "refinement", "iterative", "no_mdp", "exact", "gws")


class MapError(GraspError):
    """Bad map options: unknown plane or method, bad direction count, workers or cap."""


FRAMES = ("world", "object")


@dataclass(frozen=True)
class MapSpec:
    """One resistible-force map of a scene: the settled grasp and the forces that load it.

    ``scene``: a scene of ``assets/scenes`` (:func:`ihm.scenes.available_scenes`) or an MJCF
    file's path (:func:`ihm.scenes.is_scene_file`); ``object_body``: its grasped free body;
    ``plane``: two force axes (``"xy"``, ``"xz"``, ``"yz"``, ...); ``directions``: how many
    unit forces ``u = cos(a) e_1 + sin(a) e_2``, ``a = 2 pi k / directions`` [rad] from the
    plane's first axis towards its second; ``frame``: the plane's axes are the world's
    (``"world"``: the palm frame) or the object's at rest (``"object"``: the thesis' axes, as
    each scene documents them); ``preload``: commanded actuator forces, one per actuator, in
    each actuator's unit (N m for joint motors, N for tendons; None: the scene's default,
    :func:`ihm.scenes.load_scene`); ``nonbackdrivable``: ratchet the motor joints and
    actuated tendons (:mod:`ihm.ratchet`); ``seat``: settle with these commands first, then
    load with ``preload`` against the ratchet (:func:`ihm.scenes.load_scene`);
    ``gravity=False``: no gravity anywhere (the mapped force stands for the object's weight
    turned around, and the stability methods get no base load); ``cap``: the largest force
    tried or asked [N]; ``compliance``: the grasp model's springs, ``"unit"`` (the thesis')
    or ``"mujoco"`` (MuJoCo's stiffness, :func:`ihm.grasp_from_mujoco`; the contacts then
    start preloaded with the settled forces: :func:`scene_disturbance`); ``motion_limit``:
    ``(shift [m], turn [rad])``, with ``"mujoco"`` the stability methods' answers keep the
    object's centre of mass within ``shift`` and its rotation within ``turn`` of the settled
    state (None: the simulated ramp's 2 mm and 0.05 rad, :func:`scene_disturbance`);
    ``near`` [m]: with ``"mujoco"``, hand geoms this close to the object that do not touch it
    become contacts at their gap (:mod:`ihm.near`; 0: none); ``contact_law``: with
    ``"mujoco"``, ``"slope"`` (each contact a linear spring of its slope at the state) or
    ``"fitted"`` (MuJoCo's static law as a convex piecewise-linear spring,
    :mod:`ihm.contact_law`)."""

    scene: str
    plane: str = "xy"
    directions: int = 360
    preload: ArrayLike | None = None
    nonbackdrivable: bool = False
    seat: ArrayLike | None = None
    frame: str = "world"
    gravity: bool = True
    cap: float = 10.0
    object_body: str = "object"
    compliance: str = "unit"
    motion_limit: tuple[float, float] | None = None
    near: float = 0.0
    contact_law: str = "slope"

    def check(self, method: str, workers: int = 1) -> None:
        """:func:`check_options` on this map, for ``method`` on ``workers`` processes, and its
        ``compliance`` and ``motion_limit``."""
        check_options(self.plane, method, self.directions, workers, self.cap, self.frame)
        if self.compliance not in ("unit", "mujoco"):
            raise MapError(f"compliance must be 'unit' or 'mujoco', got {self.compliance!r}")
        lim = self.motion_limit
        if lim is not None and (len(lim) != 2 or not all(x > 0 for x in lim)):
            raise MapError(f"motion_limit must be (shift [m], turn [rad]) > 0 (inf: free), "
                           f"got {lim!r}")  # fmt: skip
        if lim is not None and self.compliance != "mujoco":
            raise MapError("motion_limit is in metres and radians: it needs compliance "
                           "'mujoco' (the unit model measures motion in newtons)")  # fmt: skip
        if not (np.isfinite(self.near) and self.near >= 0):
            raise MapError(f"near must be a finite number >= 0 [m], got {self.near!r}")
        if self.near > 0 and self.compliance != "mujoco":
            raise MapError("near is a distance in metres: it needs compliance 'mujoco'")
        if self.contact_law not in CONTACT_LAWS:
            raise MapError(
                f"contact_law must be {' or '.join(map(repr, CONTACT_LAWS))}, "
                f"got {self.contact_law!r}"
            )
        if self.contact_law == "fitted" and self.compliance != "mujoco":
            raise MapError("contact_law 'fitted' is MuJoCo's law: it needs compliance 'mujoco'")

    @property
    def label(self) -> str:
        """The scene's name in file names, titles and batch ids (a file's stem)."""
        return scenes.scene_label(self.scene)

    def load(self) -> scenes.LoadedScene:
        """The scene loaded and settled as this map asks (:func:`ihm.scenes.load_scene`)."""
        pre = None if self.preload is None else np.asarray(self.preload, dtype=float)
        return scenes.load_scene(self.scene, preload=pre, nonbackdrivable=self.nonbackdrivable,
                                 seat=self.seat, gravity=self.gravity,
                                 object_body=self.object_body)  # fmt: skip


def check_options(plane: str, method: str, directions: int, workers: int, cap: float,
                  frame: str = "world") -> None:  # fmt: skip
    """:class:`MapError` unless the plane, method, direction count, workers, force cap and
    frame of a map are valid."""
    try:
        plane_axes(plane)
    except GraspError as exc:
        raise MapError(str(exc)) from None
    if method not in METHODS and method not in RENAMED_METHODS:  # old names: solve() warns
        raise MapError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if int(directions) < 1 or int(workers) < 1:
        raise MapError(f"directions and workers must be >= 1, got {directions}, {workers}")
    if not (np.isfinite(cap) and cap > 0):
        raise MapError(f"cap must be a finite number > 0, got {cap}")
    if frame not in FRAMES:
        raise MapError(f"unknown frame {frame!r}; choose one of {', '.join(FRAMES)}")


def _directions(plane: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` angles from the plane's first axis towards its second, and the unit force
    directions ``cos(a) e_1 + sin(a) e_2`` (n, 3) in world axes."""
    angles = np.linspace(0.0, 2 * np.pi, int(n), endpoint=False)
    i, j = plane_axes(plane)
    units = np.zeros((len(angles), 3))
    units[:, i] = np.cos(angles)
    units[:, j] = np.sin(angles)
    return angles, units


_STATE: dict[str, Any] = {}


_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION  # positions, velocities, controls, applied loads


def _settled_state(spec: MapSpec) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Settle the map's scene (errors surface here, in the calling process); its state, the
    ratchet's stops (None unless nonbackdrivable) and the object's orientation at rest."""
    loaded = spec.load()
    model, data = loaded
    state = np.empty(mujoco.mj_stateSize(model, _SPEC))
    mujoco.mj_getState(model, data, state, _SPEC)
    stops = None if loaded.ratchet is None else loaded.ratchet.stops.copy()
    return state, stops, data.xmat[model.body(spec.object_body).id].reshape(3, 3).copy()


def _init(scene: str, state: np.ndarray, stops: np.ndarray | None, gravity: bool = True,
          object_body: str = "object") -> None:  # fmt: skip
    """Worker set-up: the scene's model (``scene``: a name or a file's path), the settled
    state (and ratchet stops) every direction starts from, and the body loaded."""
    model = mujoco.MjModel.from_xml_path(str(scenes.scene_path(scene)))
    if not gravity:
        model.opt.gravity[:] = 0.0
    data = mujoco.MjData(model)
    _STATE.update(model=model, data=data, state=state, spec=_SPEC, stops=stops,
                  object_body=object_body)  # fmt: skip


def _one(args: tuple[np.ndarray, float, dict[str, float]]) -> tuple[float, bool]:
    direction, cap, kw = args
    m, d = _STATE["model"], _STATE["data"]
    mujoco.mj_setState(m, d, _STATE["state"], _STATE["spec"])
    mujoco.mj_forward(m, d)
    ratchet = None
    if _STATE["stops"] is not None:
        ratchet = scenes.transmission_ratchet(m, d)
        ratchet.stops = _STATE["stops"]
    try:
        opts = {"check_rate": False, "stop_rule": "distance", **kw}  # the maps' documented rule
        options = ResistanceOptions(cap=cap, **opts)
        res = simulated_resistance(m, d, direction, ratchet=ratchet, body=_STATE["object_body"],
                                   options=options)  # fmt: skip
    finally:
        if ratchet is not None:
            ratchet.release()
    return res.value, res.capped


def simulated_map(
    spec: MapSpec,
    *,
    workers: int = 1,
    progress: bool = True,
    ray: str | None = None,
    **resistance_kwargs: float,
) -> ResistibleMap:
    """Simulated resistible force per direction of ``spec`` (module doc, :class:`MapSpec`).

    ``workers`` local processes run the directions (the same numbers for any number);
    ``ray``: run them as Ray tasks on that cluster instead (``"auto"``, ``"local"`` or an
    address; :mod:`stability.batch`); ``progress``: a bar; ``resistance_kwargs`` go to
    :class:`ihm.resistance.ResistanceOptions` (``rate``, ``max_shift``, ...).
    """
    spec.check("sim", workers)
    path = scenes.scene_path(spec.scene)  # unknown scene: SceneError before any worker starts
    scene = str(path) if scenes.is_scene_file(spec.scene) else spec.scene  # absolute for workers
    angles, units = _directions(spec.plane, spec.directions)
    state, stops, rot = _settled_state(spec)
    if spec.frame == "object":
        units = units @ rot.T
    cap = float(spec.cap)
    dirs = [(np.r_[u, 0.0, 0.0, 0.0], cap, resistance_kwargs) for u in units]
    init = (scene, state, stops, spec.gravity, spec.object_body)
    out = _map_jobs(_one, dirs, workers, _init, init, progress, f"{spec.label} sim map", ray)
    return _result(angles, out, spec, "sim")


def _result(
    angles: np.ndarray, out: list[tuple[float, bool]], spec: MapSpec, method: str
) -> ResistibleMap:
    """The map of the per-direction ``(value, capped)`` answers ``out``."""
    mags = np.array([v for v, _ in out])
    capped = np.array([c for _, c in out], dtype=bool)
    return ResistibleMap(angles, mags, capped, float(spec.cap), spec.plane, method)


def _init_analysis(grasp: Any, commands: np.ndarray, com: np.ndarray, method: str,
                   options: dict[str, Any], limit: Any) -> None:  # fmt: skip
    _STATE.update(grasp=grasp, rigid=_rigid(grasp), commands=commands, com=com, method=method,
                  options=options, limit=limit)  # fmt: skip


def _one_analysis(args: tuple[np.ndarray, float]) -> tuple[float, bool]:
    from stability import MaxDisturbance, solve

    u, cap = args
    g = _STATE["grasp"]
    f = g.object_mat.T @ u[:3]
    d = np.r_[f, np.cross(_STATE["com"], f)]
    if _STATE["method"] == "gws":  # a rigid-hand method: the contacts only, no commands
        q = MaxDisturbance(d, cap=cap, base=g.gravity_wrench)
        sol = solve(_STATE["rigid"], q, method="gws")  # an LP: no time limit to pass
    else:
        q = scene_disturbance(g, d, _STATE["commands"], cap, _STATE["limit"])
        sol = solve(g, q, method=_STATE["method"], **_STATE["options"])
    return map_value(sol)


def ramp_limit() -> tuple[float, float]:
    """The simulated ramp's hard end ``(max_shift [m], max_turn [rad])``
    (:class:`ihm.resistance.ResistanceOptions`: 2 mm, 0.05 rad): the motion limit under
    which a model with MuJoCo's stiffness answers what the ramp measures."""
    opts = ResistanceOptions()
    return opts.max_shift, opts.max_turn


def scene_disturbance(
    grasp: Any,
    direction: np.ndarray,
    commands: np.ndarray | None,
    cap: float,
    motion_limit: tuple[float, float] | None = None,
) -> Any:
    """The MaxDisturbance a settled scene's grasp is asked: ``direction`` (object frame,
    about the object origin) on top of the object's weight, with the settled ``commands``.

    With the thesis' unit springs the contacts start unloaded and the commands and the load
    act together (the thesis' protocol), and the motion is free (it is measured in newtons).
    With MuJoCo's stiffness (``grasp.compliant``) the contacts start preloaded with the
    settled normal forces, so that the model sits at the settled state under the weight
    alone and the load moves it from there; and the answer keeps the object's centre of
    mass (``grasp.object_com``) within ``shift`` [m] and its rotation within ``turn``
    [rad] (:class:`stability.MotionLimit`), ``motion_limit = (shift, turn)``, by default
    the simulated ramp's hard end (:func:`ramp_limit`: 2 mm, 0.05 rad), so that the model
    answers what the ramp measures; ``(inf, inf)``: free.

    Near contacts (``grasp_from_mujoco(near=)``, :mod:`ihm.near`; ``grasp.near``) start at
    their gap: preload ``-k g`` [N] (``k`` their stiffness, ``g`` their gap [m]). Those of
    a body that touches the object nowhere at the settled state must stay open
    (``MotionLimit.open``): the simulated ramp and hold end when the object touches a body
    it did not touch at rest (``stop_on_new_contact``); those of a touching body may
    close."""
    from stability import MaxDisturbance, MotionLimit

    preload, limit = scene_preload(grasp), None
    if grasp.compliant:
        near = np.zeros(grasp.m, dtype=bool) if grasp.near is None else grasp.near
        touching = set(grasp.hand_bodies[~near].tolist())
        new = near & np.array([b not in touching for b in grasp.hand_bodies.tolist()])
        shift, turn = map(float, ramp_limit() if motion_limit is None else motion_limit)
        if np.isfinite(shift) or np.isfinite(turn) or np.any(new):
            limit = MotionLimit(shift, turn, point=grasp.object_com, open=new)
    return MaxDisturbance(direction, commands=commands, cap=cap, base=grasp.gravity_wrench,
                          preload=preload, motion_limit=limit)  # fmt: skip


def scene_preload(grasp: Any) -> np.ndarray | None:
    """The contacts' preloads [N] every query of a settled scene's grasp starts from
    (:func:`scene_disturbance`): None with the thesis' unit springs (unloaded); with
    MuJoCo's stiffness (``grasp.compliant``) the settled normal forces, and ``-k g`` at each
    contact with a gap ``g > 0`` (``grasp.gaps``: its near contacts and the fitted law's
    steps, :mod:`ihm.contact_law`)."""
    if not grasp.compliant:
        return None
    preload = grasp.forces[:, 0].copy()
    if grasp.gaps is not None:
        apart = grasp.gaps > 0
        preload[apart] = -grasp.stiffness[apart] * grasp.gaps[apart]
    return preload


def map_value(sol: Any) -> tuple[float, bool]:
    """A MaxDisturbance solution as a map entry ``(value, capped)``: NaN when the solver
    gave no answer (time-out, error; a time-out's bracket stays in ``sol.lower`` and
    ``sol.upper``), 0 when unstable, else the value [N or N m]."""
    if sol.status not in ("solved", "optimal"):
        return float("nan"), False
    value = sol.value if sol.stable and sol.value is not None else 0.0
    return float(value), bool(sol.stats.get("capped", False))


def analysis_map(
    spec: MapSpec,
    *,
    method: str = DEFAULT_SPATIAL_METHOD,
    workers: int = 1,
    progress: bool = True,
    ray: str | None = None,
    **options: Any,
) -> ResistibleMap:
    """The stability method's resistible force per direction of ``spec`` on the settled
    scene's grasp (module doc); ``options`` go to :func:`stability.solve` (``time_limit``,
    ...). The scene settles as in :func:`simulated_map` (``nonbackdrivable``, ``seat``), so
    that both read the same grasp (the methods model every actuator as nonbackdrivable);
    ``workers``, ``progress`` and ``ray`` as there (no gravity: no base load)."""
    spec.check(method, workers)
    if method == "sim":
        raise MapError("analysis_map takes a stability method; use simulated_map for 'sim'")
    grasp, commands, com = _settled_grasp(spec)
    angles, units = _directions(spec.plane, spec.directions)
    if spec.frame == "object":
        units = units @ grasp.object_mat.T
    jobs = [(u, float(spec.cap)) for u in units]
    args = (grasp, commands, com, method, options, spec.motion_limit)
    out = _map_jobs(_one_analysis, jobs, workers, _init_analysis, args, progress,
                    f"{spec.label} {method} map", ray)  # fmt: skip
    return _result(angles, out, spec, method)


def _settled_grasp(spec: MapSpec) -> tuple[Any, np.ndarray, np.ndarray]:
    """The map's settled scene's grasp (:class:`ihm.contacts.SceneGrasp`), the commands it was
    settled with (one per column of its ``R``: ``SceneGrasp.full_commands``) and the object's
    centre of mass in the object frame."""
    from .contacts import grasp_from_mujoco

    loaded = spec.load()
    model, data = loaded
    if loaded.ratchet is not None:
        loaded.ratchet.release()
    grasp = grasp_from_mujoco(model, data, spec.object_body, compliance=spec.compliance,
                              near=float(spec.near), contact_law=spec.contact_law)  # fmt: skip
    commands = loaded.commands
    if hasattr(grasp, "full_commands"):  # one per actuator -> one per column of R
        commands = grasp.full_commands(commands)
    return grasp, commands, model.body_ipos[model.body(spec.object_body).id].copy()


def _rigid(grasp: Any) -> Any:
    """The grasp's contacts alone (no hand): what the rigid-hand method ``gws`` answers."""
    from stability import Grasp

    return Grasp(points=grasp.points, normals=grasp.normals, mu=grasp.mu)


def scene_map_rows(
    spec: MapSpec,
    *,
    method: str = DEFAULT_SPATIAL_METHOD,
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """The queries of :func:`analysis_map` as batch rows (:mod:`stability.batch`): one
    MaxDisturbance per direction on the settled scene's grasp, the force through the object's
    centre of mass, its weight as base load, the settled commands (``gws``: the rigid grasp,
    no commands); ``method`` and ``options`` are written into each row. Ids
    ``"<scene>-<plane>-<k>"``. ``python -m stability.batch`` on them gives the map's values
    (tested)."""
    from stability.batch import MapPlane, map_rows

    spec.check(method)
    if method == "sim":
        raise MapError("batch rows take a stability method, not 'sim'")
    if spec.compliance != "unit":
        raise MapError("batch rows carry the unit model only (compliance 'unit')")
    g, commands, com = _settled_grasp(spec)
    rigid = method == "gws"  # a rigid-hand method: the contacts only, no commands
    rotation = None if spec.frame == "object" else g.object_mat
    where = MapPlane(spec.plane, spec.directions, torque_point=com, rotation=rotation)
    return map_rows(_rigid(g) if rigid else g, where, cap=spec.cap, base=g.gravity_wrench,
                    commands=None if rigid else commands, id_prefix=f"{spec.label}-{spec.plane}",
                    method=method, options=options)  # fmt: skip


def _with_init(token: str, init: Any, initargs: tuple, fn: Any, job: Any) -> Any:
    """``fn(job)`` after ``init(*initargs)``, which runs once per worker process and map
    (``token``): a worker's set-up before its first direction (the executors reuse workers)."""
    if _STATE.get("_token") != token:
        init(*initargs)
        _STATE["_token"] = token
    return fn(job)


def _map_jobs(fn: Any, jobs: list, workers: int, init: Any, initargs: tuple, progress: bool,
              desc: str, ray: str | None = None) -> list:  # fmt: skip
    """``fn`` over ``jobs`` in this process (``workers`` 1), in ``workers`` local processes
    (:class:`stability.batch.LocalExecutor`: a worker that dies is replaced and its direction
    retried), or as Ray tasks on the cluster at ``ray`` (:class:`stability.batch.RayExecutor`;
    ``workers`` then sizes a new local cluster), in order, with a bar. ``init(*initargs)``
    runs once per worker process."""
    closer: Any = None
    if ray is None and workers == 1:
        init(*initargs)
        it: Any = enumerate(map(fn, jobs))
    else:
        import functools
        import uuid

        from stability.batch import make_executor

        closer = make_executor(workers if workers > 1 else None, ray)
        task = functools.partial(_with_init, uuid.uuid4().hex, init, initargs, fn)
        it = _values(closer.run(task, enumerate(jobs)))
        desc += " (ray)" if ray is not None else ""
    if progress:
        from tqdm import tqdm

        it = tqdm(it, total=len(jobs), desc=desc, unit="dir")
    try:
        out = dict(it)  # job index -> result (they arrive in completion order)
        return [out[k] for k in range(len(jobs))]
    finally:
        if closer is not None:
            closer.close()


def _values(outcomes: Any) -> Any:
    """``(k, value)`` per executor outcome; :class:`MapError` for a direction that failed."""
    for k, outcome in outcomes:
        if outcome.status != "ok":
            raise MapError(f"direction {k}: {outcome.status}: {outcome.message}")
        yield k, outcome.value


def agreement(pred: ResistibleMap, sim: ResistibleMap) -> dict[str, float]:
    """How a predicted map agrees with a simulated one over the same directions.

    ``direction_agreement``: the fraction of directions (both answered) where both say
    "capped" (resisted up to the cap) or both say "finite"; ``median_abs_log_ratio``:
    over directions finite and positive in both, the median ``|ln(pred / sim)|`` (0.15 is
    about 16 %); ``finite``: how many such directions; ``answered``: directions with a
    number in both (NaN = a solver gave no answer)."""
    if len(pred.angles) != len(sim.angles) or not np.allclose(pred.angles, sim.angles):
        raise MapError("the two maps must have the same directions")
    ok = np.isfinite(pred.magnitudes) & np.isfinite(sim.magnitudes)
    same = pred.capped == sim.capped
    finite = ok & ~pred.capped & ~sim.capped & (pred.magnitudes > 0) & (sim.magnitudes > 0)
    ratio = np.abs(np.log(pred.magnitudes[finite] / sim.magnitudes[finite]))
    return {
        "direction_agreement": float(same[ok].mean()) if ok.any() else float("nan"),
        "median_abs_log_ratio": float(np.median(ratio)) if finite.any() else float("nan"),
        "finite": int(finite.sum()),
        "answered": int(ok.sum()),
    }


def write_map_csv(path: Path, maps: Sequence[tuple[str, ResistibleMap]]) -> Path:
    """One row per (label, direction): label, method, plane, angle_deg, force_N, capped."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = [
        {"label": label, "method": rm.method, "plane": rm.plane,
         "angle_deg": round(float(np.degrees(a)), 4), "force_N": v, "capped": int(c)}
        for label, rm in maps
        for a, v, c in zip(rm.angles, rm.magnitudes, rm.capped, strict=True)
    ]  # fmt: skip
    cols = ["label", "method", "plane", "angle_deg", "force_N", "capped"]
    return write_csv(path, rows, columns=cols)


def plot_maps(path: Path, maps: Sequence[tuple[str, ResistibleMap]], title: str) -> Path:
    """All maps overlaid on one polar chart (capped directions drawn at the cap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(subplot_kw={"projection": "polar"}, figsize=(6, 6))
    for k, (label, rm) in enumerate(maps):
        plot_resistible(ax, rm, "", color=f"C{k}")
        ax.plot([], [], color=f"C{k}", label=label)
    ax.set_ylim(0, max(radial_top(rm) for _, rm in maps))  # every overlaid map fits
    ax.legend(loc="lower center", fontsize=8, bbox_to_anchor=(0.5, -0.22))
    ax.set_title(title, fontsize=9, pad=18)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run(
    spec: MapSpec,
    preloads: Sequence[ArrayLike | None],
    out: Path,
    *,
    methods: Sequence[str] = ("sim",),
    workers: int = 1,
    progress: bool = True,
    ray: str | None = None,
    **options: Any,
) -> tuple[Path, Path, list[float], list[tuple[str, str, dict[str, float]]]]:
    """The CLI's work: one map of ``spec`` per method and per entry of ``preloads`` (each
    replaces ``spec.preload``; None: the scene's own), CSV + PNG in ``out``; returns their
    paths, the wall time of each map [s] and, for every stability-method map with a ``sim``
    map of the same commands, its :func:`agreement` with it (also written to
    ``*_agreement.csv``). ``workers``, ``progress`` and ``ray`` as in :func:`simulated_map`;
    ``options`` go to :func:`analysis_map`."""
    maps, walls, keys = [], [], []
    for method in methods:
        for pre in preloads:
            t = time.perf_counter()
            one = replace(spec, preload=pre)
            if method == "sim":
                rm = simulated_map(one, workers=workers, progress=progress, ray=ray)
            else:
                rm = analysis_map(one, method=method, workers=workers, progress=progress,
                                  ray=ray, **options)  # fmt: skip
            walls.append(time.perf_counter() - t)
            what = (
                "default commands" if pre is None else "commands " + " ".join(f"{x:g}" for x in pre)
            )
            tag = ", ratcheted" if (method == "sim" and spec.nonbackdrivable) else ""
            maps.append((f"{method}, {what}{tag}", rm))
            keys.append((method, what))
    stem = f"{spec.label}_{spec.plane}" + ("_object" if spec.frame == "object" else "")
    csv_path = write_map_csv(out / f"{stem}.csv", maps)
    title = (f"{spec.label}: resistible force in the {spec.frame} {spec.plane} plane [N] "
             f"(cap {spec.cap:g} N)")  # fmt: skip
    png = plot_maps(out / f"{stem}.png", maps, title)
    agree = _agreements(maps, keys)
    if agree:
        write_csv(
            out / f"{stem}_agreement.csv",
            [{"map": label, "commands": what, **a} for label, what, a in agree],
        )
    return csv_path, png, walls, agree


def _agreements(
    maps: list[tuple[str, ResistibleMap]], keys: list[tuple[str, str]]
) -> list[tuple[str, str, dict[str, float]]]:
    """``(label, commands, agreement)`` of every stability-method map (``keys``: its method
    and commands) with the ``sim`` map of the same commands, where there is one."""
    sims = {what: rm for (method, what), (_, rm) in zip(keys, maps, strict=True) if method == "sim"}
    agree = []
    for (method, what), (label, rm) in zip(keys, maps, strict=True):
        if method != "sim" and what in sims:
            agree.append((label, what, agreement(rm, sims[what])))
    return agree
