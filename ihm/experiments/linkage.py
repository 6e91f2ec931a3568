"""A user's gripper: the closed-linkage parallel jaw (``linkage_box``) against MuJoCo.

The scene (``assets/scenes/linkage_box.xml``) is a parallel-jaw gripper with two closed
four-bar fingers (``connect`` equalities, a ``joint`` equality between the drivers, one
saturated position servo on a fixed tendon, couplers resting on their joint limits,
spring links, no gravity compensation) pinching a 30 mm, 0.05 kg box: the kind of model
a user brings (MuJoCo Menagerie's Robotiq 2F-85 is built the same way). What is
measured, for the six axis force directions ``+-x, +-y, +-z`` (world = object axes),
with the box's weight as base load:

* predicted resistance: ``MaxDisturbance`` by ``refinement`` on the grasp read off MuJoCo
  (:func:`ihm.grasp_from_mujoco`: linkages folded, stops, constant forces), for four
  contact sets: each pad's patch as two points on the line through its centre of
  pressure (``reduce="line"``, 4 contacts), reduced to its 2 and 3 extreme points
  (``reduce="extremes"``, 4 and 6), and all contacts after merging (12), each query
  within ``TIME_LIMIT_S``;
* the weight alone (``Existence``): never "unstable" where MuJoCo holds the box;
* simulated resistance (:func:`ihm.resistance.simulated_resistance`) with the scene's own
  solver settings (elliptic cone, impratio 100, noslip), and with impratio 10 (MuJoCo
  Menagerie's value for its grippers) to show how the simulated figure moves.

Outputs: ``OUT/linkage_box.csv`` (one row per number), ``OUT/linkage_box.png`` and the
summary (per contact set: answered directions, median time, ratios to the simulation,
how many within a factor 2).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from stability import Existence, solve
from stability.io import write_csv

from .. import scenes
from ..contacts import grasp_from_mujoco
from ..resistance import ResistanceOptions, simulated_resistance
from ..sim_maps import map_value, scene_disturbance
from . import MUJOCO_READ

__all__ = ["CONTACT_SETS", "DIRECTIONS", "linkage_box"]

SCENE = "linkage_box"
CAP_N = 100.0
TIME_LIMIT_S = 30.0
DIRECTIONS = {"+x": 0, "-x": 0, "+y": 1, "-y": 1, "+z": 2, "-z": 2}
#: name -> grasp_from_mujoco options
CONTACT_SETS: dict[str, dict[str, Any]] = {
    "line": {"reduce": "line"},
    "extremes2": {"reduce": "extremes", "patch_points": 2},
    "extremes3": {"reduce": "extremes", "patch_points": 3},
    "merged": {},
    "line, mujoco": {"reduce": "line", **MUJOCO_READ},
    "rect, mujoco": {"reduce": "rect", **MUJOCO_READ},
}


def _unit(name: str) -> np.ndarray:
    w = np.zeros(6)
    w[DIRECTIONS[name]] = 1.0 if name[0] == "+" else -1.0
    return w


def predict(contact_set: str, direction: str, time_limit: float = TIME_LIMIT_S) -> dict[str, Any]:
    """The MaxDisturbance along ``direction`` on top of the weight [N]: ``refinement``'s
    with the thesis' unit springs, ``modesearch``'s with MuJoCo's stiffness (a set with
    ``compliance="mujoco"``, contacts preloaded with the settled forces:
    :func:`ihm.sim_maps.scene_disturbance`)."""
    _, _, g = _settled(contact_set)
    w = _unit(direction)
    d = np.r_[g.object_mat.T @ w[:3], g.object_mat.T @ w[3:]]
    t0 = time.perf_counter()
    method = "modesearch" if g.compliant else "refinement"
    sol = solve(g, scene_disturbance(g, d, g.commands, CAP_N), method=method,
                time_limit=time_limit)  # fmt: skip
    value, _ = map_value(sol)
    return {
        "contacts": g.m,
        "value": value,
        "lower": sol.lower,
        "upper": sol.upper,
        "status": str(sol.status),
        "certified": sol.stats.get("certified"),
        "seconds": time.perf_counter() - t0,
    }


_CACHE: dict[str, tuple] = {}


def _settled(contact_set: str) -> tuple:
    if contact_set not in _CACHE:
        model, data = scenes.load_scene(SCENE)
        g = grasp_from_mujoco(model, data, **CONTACT_SETS[contact_set])
        _CACHE[contact_set] = (model, data, g)
    return _CACHE[contact_set]


def simulate(direction: str, impratio: float | None = None) -> dict[str, Any]:
    """MuJoCo's resistance along ``direction`` [N] (weight on), the scene's settings or
    ``impratio`` changed before settling."""
    path = scenes.scene_path(SCENE)
    model = mujoco.MjModel.from_xml_path(str(path))
    if impratio is not None:
        model.opt.impratio = impratio
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("init").id)
    scenes.settle(model, data, scenes.default_preload(model))
    t0 = time.perf_counter()
    res = simulated_resistance(model, data, _unit(direction),
                               options=ResistanceOptions(cap=CAP_N))  # fmt: skip
    rc = res.rate_check or {}
    return {
        "value": float(res.value),
        "reason": res.reason,
        "capped": bool(res.capped),
        "creep_m": float(res.creep_shift),
        "slow_value": float(rc.get("slow_value", np.nan)),
        "rate_difference": float(rc.get("relative_difference", np.nan)),
        "impratio": float(model.opt.impratio),
        "seconds": time.perf_counter() - t0,
    }


def linkage_box(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Run the experiment (module docstring); ``quick`` uses the line set only."""
    rows: list[dict[str, Any]] = []
    sets = ["line", "line, mujoco", "rect, mujoco"] if quick else list(CONTACT_SETS)
    sim: dict[tuple[str, float], float] = {}
    for imp in (None, 10.0):
        for dname in DIRECTIONS:
            r = simulate(dname, imp)
            sim[(dname, r["impratio"])] = r["value"]
            rows.append({"kind": "simulated", "variant": f"impratio {r['impratio']:g}",
                         "direction": dname, **r})  # fmt: skip
    own = float(scenes_impratio())
    summary: dict[str, Any] = {"scene": SCENE, "time_limit_s": TIME_LIMIT_S, "cap_n": CAP_N,
                               "simulated_impratio": own, "sets": {}}  # fmt: skip
    for cs in sets:
        _, _, g = _settled(cs)
        weight = solve(g, Existence(g.gravity_wrench, commands=g.commands),
                       method="refinement", time_limit=TIME_LIMIT_S)  # fmt: skip
        stable = np.nan if weight.stable is None else float(weight.stable)  # 1 held, 0 not
        rows.append({"kind": "weight", "variant": cs, "contacts": g.m,
                     "status": weight.status, "value": stable})  # fmt: skip
        ratios, times, answered = [], [], 0
        for dname in DIRECTIONS:
            p = predict(cs, dname)
            rows.append({"kind": "predicted", "variant": cs, "direction": dname, **p})
            times.append(p["seconds"])
            if np.isfinite(p["value"]):
                answered += 1
                s = sim[(dname, own)]
                ratios.append(p["value"] / s if s > 0 else float("inf"))
        ratios_a = np.array(ratios)
        summary["sets"][cs] = {
            "contacts": g.m,
            "hand_residual": g.hand_residual,
            "weight_stable": weight.stable,
            "answered": answered,
            "median_seconds": float(np.median(times)),
            "max_seconds": float(np.max(times)),
            "ratios": ratios,
            "within_factor_2": int(np.sum((ratios_a >= 0.5) & (ratios_a <= 2.0))),
        }
    write_csv(out / f"{SCENE}.csv", rows)
    _chart(out / f"{SCENE}.png", rows, sets, own)
    return summary


def scenes_impratio() -> float:
    return float(mujoco.MjModel.from_xml_path(str(scenes.scene_path(SCENE))).opt.impratio)


def _chart(path: Path, rows: list[dict[str, Any]], sets: list[str], own: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(DIRECTIONS)
    x = np.arange(len(names))
    series = [(f"simulated, impratio {own:g}", "simulated", f"impratio {own:g}"),
              ("simulated, impratio 10", "simulated", "impratio 10")] + [
                 (f"predicted, {cs}", "predicted", cs) for cs in sets]  # fmt: skip
    width = 0.8 / len(series)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for k, (label, kind, variant) in enumerate(series):
        vals = [next((r["value"] for r in rows if r["kind"] == kind and r["variant"] == variant
                      and r["direction"] == d), np.nan) for d in names]  # fmt: skip
        ax.bar(x + (k - (len(series) - 1) / 2) * width, vals, width, label=label)
    ax.set_xticks(x, names)
    ax.set_ylabel("resistible force on top of the weight [N]")
    ax.set_title("linkage_box: predicted (refinement, unit springs; modesearch, MuJoCo's "
                 "stiffness) and simulated resistance")  # fmt: skip
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
