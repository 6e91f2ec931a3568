"""The thesis' Barrett-hand experiments (chapters 5 and 6), predicted and simulated.

Every experiment here uses the nonbackdrivable protocol of :func:`ihm.scenes.load_scene`
(``nonbackdrivable=True, seat=...``): the fingers close lightly with gravity off, their
worm gears are ratcheted (:mod:`ihm.ratchet`), then the commanded torques are applied; a
finger commanded 0 is a passive support, as the thesis models the hand. Directions are in
the object frame (``frame="object"``: the thesis' axes, as each scene documents them).
Predictions use the grasp read off the same settled state (:func:`ihm.sim_maps.analysis_map`).
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from stability import OptimalCommands, solve
from stability.io import write_csv
from stability.maps import ResistibleMap, plot_resistible

from .. import scenes
from ..contacts import grasp_from_mujoco
from ..resistance import ResistanceOptions, simulated_resistance, touching_bodies
from ..sim_maps import (
    MapSpec,
    agreement,
    analysis_map,
    map_value,
    scene_disturbance,
    simulated_map,  # fmt: skip
    write_map_csv,
)
from . import MUJOCO_READ

__all__ = ["box", "box_3d", "cube", "flask", "seated"]

#: refinement's per-solve time limit in the experiments [s]
TIME_LIMIT = 20.0
ETA = float(np.radians(2.5))  # the thesis' contact-normal uncertainty
FLASK_REF = {"levels": 2, "backend": "highs", "time_limit": 60.0}
#: the predictions with MuJoCo's stiffness (``compliance="mujoco"``), by the default 3D method
MUJOCO_LABEL = "modesearch, mujoco"


def _maps(
    scene: str,
    plane: str,
    n: int,
    preload: list[float],
    seat: list[float],
    methods: list[tuple[str, str, dict[str, Any]]],
    cap: float,
    workers: int,
    gravity: bool = True,
) -> tuple[list[tuple[str, ResistibleMap]], dict[str, float]]:
    """One map per (label, method, options) on the same settled grasp; wall times [s]."""
    out, walls = [], {}
    spec = MapSpec(scene, plane, n, preload=preload, nonbackdrivable=True, seat=seat,
                   frame="object", gravity=gravity, cap=cap)  # fmt: skip
    for label, method, opts in methods:
        t = time.perf_counter()
        if method == "sim":
            rm = simulated_map(spec, workers=workers, progress=False)
        else:
            opts = dict(opts)
            read = {k: opts.pop(k) for k in ("compliance", "near", "contact_law") if k in opts}
            model_spec = replace(spec, **read)
            rm = analysis_map(model_spec, method=method, workers=workers, progress=False, **opts)
        walls[label] = time.perf_counter() - t
        out.append((label, rm))
    return out, walls


def _agreements(maps: list[tuple[str, ResistibleMap]]) -> dict[str, dict[str, float]]:
    sim = dict(maps)["sim"]
    return {label: agreement(rm, sim) for label, rm in maps if label != "sim"}


def _panels(path: Path, panels: list[tuple[str, list[tuple[str, ResistibleMap]]]],
            title: str) -> Path:  # fmt: skip
    """Polar panels side by side, each overlaying its maps (capped directions at the cap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), subplot_kw={"projection": "polar"},
                             figsize=(4.6 * len(panels), 5.2))  # fmt: skip
    from matplotlib.lines import Line2D

    axes = np.atleast_1d(axes)
    for ax, (name, maps) in zip(axes, panels, strict=True):
        handles = []
        for k, (label, rm) in enumerate(maps):
            plot_resistible(ax, rm, name, color=f"C{k}")
            n_nan = int(np.isnan(rm.magnitudes).sum())
            extra = f" ({n_nan} unanswered)" if n_nan else ""
            if not np.any(rm.magnitudes > 0):
                extra += " (0 everywhere)"
            handles.append(Line2D([], [], color=f"C{k}", label=label + extra))
        handles.append(Line2D([], [], color="k", lw=3, label=">= cap"))
        ax.legend(handles=handles, loc="upper center", fontsize=7, ncol=2,
                  bbox_to_anchor=(0.5, -0.08))  # fmt: skip
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def _map_methods(eta: bool = True) -> list[tuple[str, str, dict[str, Any]]]:
    m = [
        ("sim", "sim", {}),
        ("refinement", "refinement", {"time_limit": TIME_LIMIT}),
    ]
    if eta:
        m.append(("refinement 2.5 deg", "refinement",
                  {"time_limit": TIME_LIMIT, "normal_uncertainty": ETA}))  # fmt: skip
    m.append(("iterative", "iterative", {"time_limit": TIME_LIMIT}))
    m.append((MUJOCO_LABEL, "modesearch", {"time_limit": TIME_LIMIT, **MUJOCO_READ}))
    return m


def _summarise_maps(maps, walls) -> dict[str, Any]:
    return {
        "agreement": _agreements(maps),
        "wall_s": {k: round(v, 1) for k, v in walls.items()},
        "values": {label: [round(float(v), 4) for v in rm.magnitudes] for label, rm in maps},
        "capped": {label: [int(c) for c in rm.capped] for label, rm in maps},
    }


def box(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Grasp example 1 (thesis figs. 2dgrasp_xy, 2dgrasp_xz): resistible forces in the object
    xy-plane (the grasp plane) and xz-plane, no preload vs 0.1 N m on fingers 1 and 2."""
    n = 8 if quick else 24
    seat = [0.0, 0.01, 0.01, 0.0]
    preloads = {"no preload": [0.0, 0.0, 0.0, 0.0], "preload 0.1 N m": [0.0, 0.1, 0.1, 0.0]}
    summary: dict[str, Any] = {"directions": n, "seat": seat, "cap_N": 10.0}
    all_maps, panels = [], []
    for plane in ("xy", "xz"):
        for tag, pre in preloads.items():
            maps, walls = _maps("barrett_box", plane, n, pre, seat, _map_methods(), 10.0,
                                workers)  # fmt: skip
            summary[f"{plane}, {tag}"] = _summarise_maps(maps, walls)
            all_maps += [(f"{plane}, {tag}, {label}", rm) for label, rm in maps]
            panels.append((f"{plane}-plane, {tag}", maps))
    write_map_csv(out / "barrett_box.csv", all_maps)
    _panels(out / "barrett_box.png", panels,
            "barrett_box (thesis grasp example 1): resistible force [N] per direction, object "
            "frame (x to finger 2, y to the palm, z out of the grasp plane); cap 10 N")  # fmt: skip
    return summary


def _rest_ok(model: mujoco.MjModel, data: mujoco.MjData, before: np.ndarray,
             touching: set[int]) -> bool:  # fmt: skip
    """The loaded grasp is the seated one: the object moved < 2 mm and touches nothing new."""
    b = model.body("object").id
    now = touching_bodies(model, data, b)
    return bool(np.linalg.norm(data.xipos[b] - before) < 0.002 and now <= touching)


def seated(scene: str, preload: list[float], seat: list[float],
           gravity: bool = True) -> tuple[scenes.LoadedScene, bool]:  # fmt: skip
    """The scene loaded with the experiments' protocol (:func:`ihm.scenes.load_scene` with
    ``nonbackdrivable=True`` and ``seat``), and whether the loaded grasp is still the seated
    one: the object moved less than 2 mm from a seat-only settle and touches nothing new."""
    m0, d0 = scenes.load_scene(scene, preload=[0.0] * len(seat), nonbackdrivable=True,
                               seat=seat, gravity=gravity)  # fmt: skip
    b = m0.body("object").id
    before = d0.xipos[b].copy()
    touching = touching_bodies(m0, d0, b)
    loaded = scenes.load_scene(scene, preload=preload, nonbackdrivable=True, seat=seat,
                               gravity=gravity)  # fmt: skip
    model, data = loaded
    return loaded, _rest_ok(model, data, before, touching)


def _predict(model, g, direction_obj: np.ndarray, commands, cap: float, method: str,
             at_com: bool = True, **opts: Any) -> tuple[float, bool, str, float]:  # fmt: skip
    """MaxDisturbance on the settled grasp ``g`` (:func:`grasp_from_mujoco`) for an
    object-frame direction (force, torque): the force through the centre of mass
    (``at_com``, the thesis' load cell) or through the object origin; (value, capped,
    status, seconds)."""
    com = model.body_ipos[model.body("object").id] if at_com else np.zeros(3)
    f, tq = direction_obj[:3], direction_obj[3:]
    d = np.r_[f, np.cross(com, f) + tq]
    t = time.perf_counter()
    commands = g.full_commands(commands)  # stops, springs: their own columns' commands
    sol = solve(g, scene_disturbance(g, d, commands, cap), method=method, **opts)
    wall = time.perf_counter() - t
    value, capped = map_value(sol)
    return value, capped, sol.status, wall


def _simulate(model, data, ratchet, direction_obj: np.ndarray, cap: float, at_com: bool = True):
    """Simulated resistance for an object-frame direction (rotated to world axes); a force
    through the object origin (``at_com=False``) is the force at the centre of mass plus the
    torque ``(origin - com) x f``."""
    b = model.body("object").id
    R = data.xmat[b].reshape(3, 3)
    f, tq = direction_obj[:3], direction_obj[3:]
    if not at_com:
        tq = tq + np.cross(-model.body_ipos[b], f)
    w = np.r_[R @ f, R @ tq]
    opts = ResistanceOptions(cap=cap, check_rate=False, stop_rule="distance")
    return simulated_resistance(model, data, w, ratchet=ratchet, options=opts)


def box_3d(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Grasp example 2 (thesis table 3dgrasp, fig. outlier): resistance to a force along
    object +x with only finger 1 vs only finger 2 preloaded (0.1 N m; the other fingers
    passive); the thesis predicted a ratio 2.48 (finger 1 / finger 2) and measured 2.23."""
    seat = [0.0, 0.01, 0.01, 0.022]
    cases = {"finger 1": [0.0, 0.1, 0.0, 0.0], "finger 2": [0.0, 0.0, 0.1, 0.0]}
    ex = np.array([1.0, 0, 0, 0, 0, 0])
    rows, summary = [], {"seat": seat, "cap_N": 50.0}
    for case, pre in cases.items():
        loaded, ok = seated("barrett_box_3d", pre, seat)
        (model, data), ratchet = loaded, loaded.ratchet
        g = grasp_from_mujoco(model, data)
        res = {"contact_normal_forces_N": {model.body(b).name: round(float(c), 3) for b, c in
                                           zip(g.hand_bodies, g.forces[:, 0], strict=True)},
               "seated_grasp_kept": ok}  # fmt: skip
        g_mj = grasp_from_mujoco(model, data, **MUJOCO_READ)
        for label, grasp, method in (("refinement", g, "refinement"),
                                     ("iterative", g, "iterative"),
                                     (MUJOCO_LABEL, g_mj, "modesearch")):  # fmt: skip
            v, c, status, wall = _predict(model, grasp, ex, pre, 50.0, method,
                                          time_limit=TIME_LIMIT)  # fmt: skip
            res[label] = {"value": v, "capped": c, "status": status, "wall_s": round(wall, 2)}
            rows.append((case, label, v, c))
        sim = _simulate(model, data, ratchet, ex, 50.0)
        res["sim"] = {"value": sim.value, "capped": sim.capped, "reason": sim.reason}
        rows.append((case, "sim", sim.value, sim.capped))
        summary[case] = res
    for method in ("refinement", "iterative", MUJOCO_LABEL, "sim"):
        a, b = summary["finger 1"][method]["value"], summary["finger 2"][method]["value"]
        summary[f"ratio finger 1 / finger 2, {method}"] = a / b if b > 0 else float("nan")
    summary["ratio thesis"] = {"predicted": 2.48, "measured": 2.23}
    n = 8 if quick else 24
    panels, all_maps = [], []
    for case, pre in cases.items():
        maps, walls = _maps("barrett_box_3d", "xy", n, pre, seat, _map_methods(eta=False), 20.0,
                            workers)  # fmt: skip
        summary[f"xy map, {case}"] = _summarise_maps(maps, walls)
        panels.append((f"xy-plane, preload {case} only", maps))
        all_maps += [(f"{case}, {label}", rm) for label, rm in maps]
    cols = ["case", "method", "direction", "value", "capped"]
    write_csv(out / "barrett_box_3d.csv",
              [dict(zip(cols, (case, method, "+x", v, int(c)), strict=True))
               for case, method, v, c in rows], cols)  # fmt: skip
    write_map_csv(out / "barrett_box_3d_xy.csv", all_maps)
    _panels(out / "barrett_box_3d.png", panels,
            "barrett_box_3d (thesis grasp example 2): resistible force [N], object xy-plane, "
            "0.1 N m on one finger, the others passive; cap 20 N")  # fmt: skip
    return summary


def cube(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Thesis figs. cube / preload_test: fingers 1 and 2 at 0.1 N m, the thumb swept from 0
    to 0.09 N m; resistance to a force along object +z through the object origin (the
    midpoint of contacts 1 and 2, as the thesis' analysis: no torque) and to a torque about
    object x.
    Analysis (rigid, equal arms a = 0.05 m, mu = 0.45): +z force (2 mu tau12 - tau3) / a."""
    seat = [0.0, 0.02, 0.02, 0.005]
    taus = [0.0, 0.03, 0.06, 0.09] if quick else [0.0, 0.015, 0.03, 0.045, 0.06, 0.075, 0.09]
    loads = {"force +z [N]": (np.array([0, 0, 1.0, 0, 0, 0]), 5.0),
             "torque about +x [N m]": (np.array([0, 0, 0, 1.0, 0, 0]), 0.2),
             "torque about -x [N m]": (np.array([0, 0, 0, -1.0, 0, 0]), 0.2)}  # fmt: skip
    rows = []
    for tau3 in taus:
        pre = [0.0, 0.1, 0.1, tau3]
        loaded, ok = seated("barrett_cube", pre, seat)
        (model, data), ratchet = loaded, loaded.ratchet
        state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        stops = ratchet.stops.copy()
        g = grasp_from_mujoco(model, data)  # the settled grasp, before any ramp moves it
        g_mj = grasp_from_mujoco(model, data, **MUJOCO_READ)
        for name, (d, cap) in loads.items():
            for label, grasp, method in (("refinement", g, "refinement"),
                                         (MUJOCO_LABEL, g_mj, "modesearch")):  # fmt: skip
                v, c, status, wall = _predict(model, grasp, d, pre, cap, method, at_com=False,
                                              time_limit=TIME_LIMIT)  # fmt: skip
                rows.append((tau3, name, label, v, c, status, wall))
            mujoco.mj_setState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
            ratchet.stops = stops
            mujoco.mj_forward(model, data)
            if ok:
                sim = _simulate(model, data, ratchet, d, cap, at_com=False)
                rows.append((tau3, name, "sim", sim.value, sim.capped, sim.reason, 0.0))
            else:  # the thumb pushed the object out before any load
                rows.append((tau3, name, "sim", 0.0, False, "slid out at rest", 0.0))
    cols = ["tau3_Nm", "load", "method", "value", "capped", "status", "wall_s"]
    write_csv(out / "barrett_cube.csv", [dict(zip(cols, r, strict=True)) for r in rows], cols)
    _cube_plot(out / "barrett_cube.png", rows, taus)
    summary: dict[str, Any] = {"seat": seat, "tau3": taus}
    for name in loads:
        sim = np.array([r[3] for r in rows if r[1] == name and r[2] == "sim"])
        summary[name] = {"sim": sim.round(4).tolist()}
        for label in ("refinement", MUJOCO_LABEL):
            pred = np.array([r[3] for r in rows if r[1] == name and r[2] == label])
            both = (pred > 0) & (sim > 0)
            summary[name][label] = {
                "values": pred.round(4).tolist(),
                "median_abs_log_ratio": float(np.median(np.abs(np.log(pred[both] / sim[both]))))
                if both.any() else float("nan"),
                "both_zero_or_both_positive": float(np.mean((pred > 0) == (sim > 0))),
            }  # fmt: skip
    summary["force +z [N]"]["analytic"] = [round((0.09 - t) / 0.05, 4) for t in taus]
    return summary


def _cube_plot(path: Path, rows, taus) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    groups = (["force +z [N]"], ["torque about +x [N m]", "torque about -x [N m]"])
    for ax, names in zip(axes, groups, strict=True):
        for k, method in enumerate(("refinement", MUJOCO_LABEL, "sim")):
            for name, style in zip(names, ("o-", "s--"), strict=False):
                v = [r[3] for r in rows if r[1] == name and r[2] == method]
                sign = f" ({name.split()[2]})" if len(names) > 1 else ""
                ax.plot(taus, v, style, color=f"C{k}", label=method + sign)
        name = names[0] if len(names) == 1 else "torque about x [N m]"
        if name.startswith("force"):
            t = np.linspace(0, 0.09, 10)
            ax.plot(t, (0.09 - t) / 0.05, "k--", lw=1, label="(2 mu tau12 - tau3) / a")
        ax.set_xlabel("thumb command tau3 [N m]")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("barrett_cube (thesis fig. preload_test): fingers 1, 2 at 0.1 N m, thumb swept")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def flask(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Thesis figs. flasks / flask_map: the pouring map (forces in the object xy-plane, the
    flask's own weight turned around: no gravity in the scene) with no preload and with
    0.1 N m on every proximal joint, and the optimal commands
    for the largest resistible -y force (thesis: [0, 0.042, 0.073] N m), checked in MuJoCo."""
    n = 4 if quick else 12
    seat = [0.0, 0.01, 0.01, 0.01]
    naive = [0.0, 0.1, 0.1, 0.1]
    # refinement with 2 levels (edges down to gamma/4) and HiGHS: with the default levels,
    # or eta = 2.5 deg as the thesis, this 4-contact grasp's directions do not finish within
    # the experiment's time limits; 2 levels answer (an over-estimate: coarser cones)
    methods = [("sim", "sim", {}), ("refinement, 2 levels", "refinement", FLASK_REF),
               ("iterative", "iterative", {"time_limit": 30.0}),
               (MUJOCO_LABEL, "modesearch",
                {"time_limit": 30.0, **MUJOCO_READ})]  # fmt: skip
    summary: dict[str, Any] = {"directions": n, "seat": seat, "cap_N": 10.0}
    panels, all_maps = [], []
    for tag, pre in (("no preload", [0.0] * 4), ("0.1 N m per finger", naive)):
        maps, walls = _maps("barrett_flask", "xy", n, pre, seat, methods, 10.0, workers,
                            gravity=False)  # fmt: skip
        summary[f"xy, {tag}"] = _summarise_maps(maps, walls)
        panels.append((f"xy-plane, {tag}", maps))
        all_maps += [(f"{tag}, {label}", rm) for label, rm in maps]
    write_map_csv(out / "barrett_flask.csv", all_maps)
    _panels(out / "barrett_flask.png", panels,
            "barrett_flask (thesis fig. flask_map): resistible force [N] while pouring "
            "(object xy-plane; y along the flask axis); cap 10 N")  # fmt: skip
    # optimal commands for the largest -y force under the naive preload
    down = np.array([0, -1.0, 0, 0, 0, 0])
    loaded, _ = seated("barrett_flask", naive, seat, gravity=False)
    (model, data), ratchet = loaded, loaded.ratchet
    g = grasp_from_mujoco(model, data)
    W, _, status, _ = _predict(model, g, down, naive, 10.0, "refinement", **FLASK_REF)
    com = model.body_ipos[model.body("object").id]
    res: dict[str, Any] = {"W_N": W, "status": status, "optimal_commands": None,
                           "optimal_status": "not asked: no value for -y"}  # fmt: skip
    opt = None
    if np.isfinite(W):
        wrench = W * np.r_[down[:3], np.cross(com, down[:3])]
        sol = solve(g, OptimalCommands(wrench, upper=[0.0, 3.0, 3.0, 3.0]),
                    method="refinement", **{**FLASK_REF, "time_limit": 180.0})  # fmt: skip
        opt = None if sol.commands is None else [round(float(x), 4) for x in sol.commands]
        res.update(optimal_commands=opt, optimal_status=sol.status)
    sim_naive = _simulate(model, data, ratchet, down, 10.0)
    res["sim_naive"] = {"value": sim_naive.value, "reason": sim_naive.reason}
    if opt is not None:
        loaded2, ok = seated("barrett_flask", list(sol.commands), seat, gravity=False)
        (m2, d2), r2 = loaded2, loaded2.ratchet
        s2 = _simulate(m2, d2, r2, down, 10.0)
        res["sim_optimal"] = {"value": s2.value, "reason": s2.reason, "seated_kept": ok}
    summary["optimal commands for -y"] = res
    return summary
