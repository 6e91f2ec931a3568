"""Resistible-force maps of the thesis' scenes simulated in MuJoCo: ``python -m ihm map``.

For a scene, a plane of two world force axes (the palm frame of the hands: MuJoCo's world
frame) and commands, the simulated resistance (:func:`ihm.resistance.simulated_resistance`)
per direction ``u = cos(a) e_1 + sin(a) e_2``, ``a`` from the plane's first axis towards its
second. The directions are independent and run in parallel (``workers``): the scene is
settled once, in the calling process, and every worker restores that state for each of
its directions (the same numbers for any number of workers). The result is a
:class:`stability.maps.ResistibleMap` (method ``"sim"``), written as CSV and drawn on a
polar PNG with :func:`stability.maps.plot_resistible`.

The stability methods' maps of the same scenes need the object's weight as a base load
of MaxDisturbance (every scene has gravity); they are not offered here yet.
"""

from __future__ import annotations

import csv
import multiprocessing as mp
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from stability import GraspError
from stability.maps import ResistibleMap, plot_resistible

from . import scenes
from .ratchet import Ratchet
from .resistance import simulated_resistance

__all__ = ["MapError", "simulated_map", "write_map_csv", "plot_maps", "METHODS"]

METHODS = ("sim",)
_AXES = {"x": 0, "y": 1, "z": 2}


class MapError(GraspError):
    """Bad map options: unknown plane or method, bad direction count, workers or cap."""


def _check(plane: str, method: str, directions: int, workers: int, cap: float) -> None:
    if len(plane) != 2 or any(a not in _AXES for a in plane) or plane[0] == plane[1]:
        raise MapError(f"plane must name two distinct axes of x, y, z (e.g. 'xy'), got {plane!r}")
    if method not in METHODS:
        raise MapError(
            f"unknown method {method!r}; choose one of {', '.join(METHODS)} (the stability "
            "methods need a base load for the scenes' gravity: not yet)"
        )
    if int(directions) < 1 or int(workers) < 1:
        raise MapError(f"directions and workers must be >= 1, got {directions}, {workers}")
    if not (np.isfinite(cap) and cap > 0):
        raise MapError(f"cap must be a finite number > 0, got {cap}")


_STATE: dict[str, Any] = {}


_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION  # positions, velocities, controls, applied loads


def _settled_state(scene: str, preload: Any) -> np.ndarray:
    """Settle the scene (errors surface here, in the calling process) and return its state."""
    model, data = scenes.load_scene(scene, preload=preload)
    state = np.empty(mujoco.mj_stateSize(model, _SPEC))
    mujoco.mj_getState(model, data, state, _SPEC)
    return state


def _init(scene: str, state: np.ndarray, nonbackdrivable: bool) -> None:
    """Worker set-up: the scene's model and the settled state every direction starts from."""
    model = mujoco.MjModel.from_xml_path(str(scenes.scene_path(scene)))
    data = mujoco.MjData(model)
    _STATE.update(model=model, data=data, state=state, spec=_SPEC, nb=nonbackdrivable)


def _one(args: tuple[np.ndarray, float, dict[str, float]]) -> tuple[float, bool]:
    direction, cap, kw = args
    m, d = _STATE["model"], _STATE["data"]
    mujoco.mj_setState(m, d, _STATE["state"], _STATE["spec"])
    mujoco.mj_forward(m, d)
    ratchet = None
    if _STATE["nb"]:
        from .ratchet import actuated_joints, actuated_tendons

        ratchet = Ratchet(m, d, actuated_joints(m), tendons=actuated_tendons(m))
    try:
        res = simulated_resistance(m, d, direction, cap=cap, ratchet=ratchet, **kw)
    finally:
        if ratchet is not None:
            ratchet.release()
    return res.value, res.capped


def simulated_map(
    scene: str,
    plane: str = "xy",
    directions: int = 360,
    *,
    preload: ArrayLike | None = None,
    nonbackdrivable: bool = False,
    cap: float = 10.0,
    workers: int = 1,
    progress: bool = True,
    **resistance_kwargs: float,
) -> ResistibleMap:
    """Simulated resistible force per direction in ``plane`` (module doc).

    ``preload``: commanded actuator forces (default: the scene's ``ihm_preload``);
    ``nonbackdrivable``: ratchet the motor joints and actuated tendons
    (:mod:`ihm.ratchet`); ``resistance_kwargs`` go to
    :func:`ihm.resistance.simulated_resistance` (``rate``, ``max_shift``, ...).
    """
    _check(plane, "sim", directions, workers, cap)
    scenes.scene_path(scene)  # unknown scene: SceneError before any worker starts
    angles = np.linspace(0.0, 2 * np.pi, int(directions), endpoint=False)
    i, j = _AXES[plane[0]], _AXES[plane[1]]
    dirs = []
    for a in angles:
        w = np.zeros(6)
        w[i], w[j] = np.cos(a), np.sin(a)
        dirs.append((w, float(cap), resistance_kwargs))
    pre = None if preload is None else np.asarray(preload, dtype=float)
    state = _settled_state(scene, pre)
    it: Any
    if workers == 1:
        _init(scene, state, nonbackdrivable)
        it = map(_one, dirs)
        pool = None
    else:
        method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx = mp.get_context(method)
        pool = ctx.Pool(workers, initializer=_init, initargs=(scene, state, nonbackdrivable))
        it = pool.imap(_one, dirs)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, total=len(dirs), desc=f"{scene} sim map", unit="dir")
    try:
        out = list(it)
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    mags = np.array([v for v, _ in out])
    capped = np.array([c for _, c in out], dtype=bool)
    return ResistibleMap(angles, mags, capped, float(cap), plane, "sim")


def write_map_csv(path: Path, maps: Sequence[tuple[str, ResistibleMap]]) -> Path:
    """One row per (label, direction): label, method, plane, angle_deg, force_N, capped."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["label", "method", "plane", "angle_deg", "force_N", "capped"])
        for label, rm in maps:
            for a, v, c in zip(rm.angles, rm.magnitudes, rm.capped, strict=True):
                w.writerow([label, rm.method, rm.plane, round(float(np.degrees(a)), 4), v, int(c)])
    return path


def plot_maps(path: Path, maps: Sequence[tuple[str, ResistibleMap]], title: str) -> Path:
    """All maps overlaid on one polar chart (capped directions drawn at the cap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(subplot_kw={"projection": "polar"}, figsize=(6, 6))
    for k, (label, rm) in enumerate(maps):
        plot_resistible(ax, rm, "", color=f"C{k}")
        ax.plot([], [], color=f"C{k}", label=label)
    ax.legend(loc="lower center", fontsize=8, bbox_to_anchor=(0.5, -0.22))
    ax.set_title(title, fontsize=9, pad=18)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run(
    scene: str,
    plane: str,
    directions: int,
    preloads: Sequence[ArrayLike | None],
    nonbackdrivable: bool,
    cap: float,
    workers: int,
    out: Path,
    progress: bool = True,
) -> tuple[Path, Path, list[float]]:
    """The CLI's work: one simulated map per preload, CSV + PNG; returns their paths and the
    wall time of each map [s]."""
    maps, walls = [], []
    for pre in preloads:
        t = time.perf_counter()
        rm = simulated_map(
            scene, plane, directions, preload=pre, nonbackdrivable=nonbackdrivable, cap=cap,
            workers=workers, progress=progress,
        )  # fmt: skip
        walls.append(time.perf_counter() - t)
        what = "default commands" if pre is None else "commands " + " ".join(f"{x:g}" for x in pre)
        maps.append((f"sim, {what}{', ratcheted' if nonbackdrivable else ''}", rm))
    stem = f"{scene}_{plane}"
    csv_path = write_map_csv(out / f"{stem}.csv", maps)
    title = f"{scene}: resistible force in the {plane} plane [N] (MuJoCo, cap {cap:g} N)"
    png = plot_maps(out / f"{stem}.png", maps, title)
    return csv_path, png, walls
