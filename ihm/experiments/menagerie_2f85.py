"""A user's model as it comes: MuJoCo Menagerie's Robotiq 2F-85 pinching a box.

The model is not shipped (it belongs to MuJoCo Menagerie); pass the path of
``robotiq_2f85/2f85.xml`` from a Menagerie checkout::

    python -m ihm.experiments.menagerie_2f85 PATH/robotiq_2f85/2f85.xml --out docs/experiments

What is changed, and only this: every mesh geom and mesh asset is removed (the STL files
need not be present; the links' collision meshes never touch a box between the pads, and
each body keeps its explicit ``<inertial>``), a 30 mm, 0.05 kg box (friction 0.7, the
pads') is added between the pads as body ``object``, and gravity points along +z (the
fingers hang down). Solver settings stay Menagerie's (pyramidal cone, impratio 10, no
noslip). Then the recipe of ``docs/linkage.md``: ``settle`` with the actuator's
``forcerange`` bound (5: saturated), and per axis push (six directions, on top of the
weight):

* ``simulated``: :func:`ihm.resistance.simulated_resistance` on a fresh settle, with
  Menagerie's settings (``variant`` "impratio 10": the box creeps, and where creep ends
  the run first the figure is creep, rate dependent) and with MuJoCo's ``noslip``
  post-processor (:data:`NOSLIP_ITERATIONS`) switched on for the ramp only, from the same
  settled state (``variant`` "noslip 20": no creep, the breakaway);
* ``grasp_from_mujoco``: the default read (``reduce="line"``), accepted or refused;
* ``weight`` / ``predicted`` with ``compliance="unit"`` (the thesis' model, preload 0,
  ``spring_held="warn"``, ``stop_gap`` 0 and 0.02), ``refinement``;
* ``predicted`` with ``compliance="mujoco"`` (MuJoCo's contact, servo and spring
  stiffness, limits within ``near_limit`` as stops with their gaps) asked from the settled
  state (:func:`ihm.sim_maps.scene_disturbance`: contacts preloaded with MuJoCo's normal
  forces, the weight as base load), one row per method (``--methods``; default
  ``modesearch``) and motion limit: variant ``"mujoco, line"`` within the ramp's hard end
  (the object's centre of mass within 2 mm, its rotation within 0.05 rad: the question
  the ramp answers), ``"mujoco, line, free"`` without a limit (the first-order model's
  largest load, whatever its motion). Each row has the answer's bracket and its motion
  (``shift_m``, ``turn_rad``: the object's; ``hand_rad``: the largest independent joint
  motion) in physical units.

``ratio_noslip`` / ``ratio_menagerie``: a prediction over the simulated figure with
noslip / with Menagerie's settings. Writes ``OUT/menagerie_2f85.csv`` and prints the
rows.
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import Existence, MaxDisturbance, Solution, solve
from stability.io import write_csv

from ..contacts import HandModelError, HandOptions, SceneGrasp, grasp_from_mujoco
from ..resistance import ResistanceOptions, simulated_resistance
from ..scenes import settle
from ..sim_maps import map_value, scene_disturbance, scene_preload
from . import MUJOCO_READ

__all__ = ["NOSLIP_ITERATIONS", "build", "main", "run"]

BOX_HALF_M = 0.015
BOX_MASS_KG = 0.05
BOX_Z_M = 0.145  # between the pads' halves (their seam is at z = 0.1415 m, open)
FORCE = 5.0  # the actuator's forcerange bound
DIRECTIONS = ("+x", "-x", "+y", "-y", "+z", "-z")
CAP = 100.0  # the solvers' and the ramps' cap [N]
#: MuJoCo's noslip iterations for the creep-free ramp (``linkage_box``'s setting)
NOSLIP_ITERATIONS = 20


def build(path: str | Path) -> mujoco.MjModel:
    """Menagerie's 2F-85 without meshes, with the box (module docstring)."""
    spec = mujoco.MjSpec.from_file(str(path))
    for g in list(spec.geoms):
        if g.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(g)
    for m in list(spec.meshes):
        spec.delete(m)
    spec.option.gravity = [0.0, 0.0, 9.81]
    body = spec.worldbody.add_body(name="object", pos=[0.0, 0.0, BOX_Z_M])
    body.add_freejoint(name="object")
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[BOX_HALF_M] * 3, mass=BOX_MASS_KG,
                  friction=[0.7, 0.005, 0.0001])  # fmt: skip
    return spec.compile()


def settled(path: str | Path) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A fresh scene (:func:`build`) closed with the saturated actuator (``settle``)."""
    model = build(path)
    data = mujoco.MjData(model)
    settle(model, data, [FORCE])
    return model, data


def axis(name: str) -> NDArray[np.float64]:
    """The unit wrench (force first, world axes) of an axis push such as ``"+x"``."""
    u = np.zeros(6)
    u["xyz".index(name[1])] = 1.0 if name[0] == "+" else -1.0
    return u


def object_direction(g: SceneGrasp, name: str) -> NDArray[np.float64]:
    """The axis push ``name`` in the grasp's object frame (the solvers' wrench frame)."""
    u = axis(name)
    return np.r_[g.object_mat.T @ u[:3], g.object_mat.T @ u[3:]]


def motion_size(sol: Solution) -> tuple[float, float, float]:
    """``(shift [m], turn [rad], largest |joint motion| [rad or m])`` of an answer's exact
    point (NaN without one); physical units under ``compliance="mujoco"``."""
    if sol.motion is None:
        return np.nan, np.nan, np.nan
    r = np.asarray(sol.motion, dtype=float)
    q = np.zeros(1) if sol.hand_motion is None else np.abs(np.asarray(sol.hand_motion, float))
    return float(np.linalg.norm(r[:3])), float(np.linalg.norm(r[3:])), float(q.max(initial=0))


def ask(g: SceneGrasp, name: str, method: str, time_limit: float) -> Solution:
    """``MaxDisturbance`` along the axis push ``name`` on top of the weight, with every
    column's command (``g.commands``: one per column of ``R``), unit springs unloaded (the
    thesis' protocol)."""
    q = MaxDisturbance(object_direction(g, name), commands=g.commands, cap=CAP,
                       base=g.gravity_wrench)  # fmt: skip
    return solve(g, q, method=method, time_limit=time_limit)


def simulated(path: str | Path, noslip: int = 0) -> list[dict[str, Any]]:
    """One ``simulated`` row per axis push: the ramp on a fresh settle, with the model's
    settings, or with ``noslip`` iterations switched on after the settle."""
    rows = []
    for name in DIRECTIONS:
        model, data = settled(path)
        if noslip:
            model.opt.noslip_iterations = noslip
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r = simulated_resistance(model, data, axis(name), options=ResistanceOptions(cap=CAP))
        variant = f"noslip {noslip}" if noslip else f"impratio {model.opt.impratio:g}"
        rows.append({"kind": "simulated", "variant": variant, "direction": name,
                     "value": r.value, "reason": r.reason, "creep_m": r.creep_shift,
                     "turn_rad": r.creep_turn,
                     "slow_value": (r.rate_check or {}).get("slow_value"),
                     "warning": "; ".join(str(w.message) for w in caught)})  # fmt: skip
    return rows


def _ratios(value: float, sim: dict[str, dict[str, float]], name: str) -> dict[str, float]:
    """``ratio_noslip`` and ``ratio_menagerie``: ``value`` over either simulated figure."""
    return {f"ratio_{k}": value / v[name] if v[name] > 0 else np.nan for k, v in sim.items()}


def unit_rows(model: mujoco.MjModel, data: mujoco.MjData, sim: dict[str, dict[str, float]],
              time_limit: float) -> list[dict[str, Any]]:  # fmt: skip
    """``compliance="unit"`` (the thesis' model, preload 0): the default read, then
    ``refinement`` with ``spring_held="warn"`` and ``stop_gap`` 0 and 0.02."""
    try:
        grasp_from_mujoco(model, data, reduce="line")
        refusal = ""
    except HandModelError as exc:
        refusal = str(exc)
    rows: list[dict[str, Any]] = [{"kind": "grasp_from_mujoco", "variant": "defaults",
                                   "status": "refused" if refusal else "accepted",
                                   "warning": refusal}]  # fmt: skip
    for gap in (0.0, 0.02):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            g = grasp_from_mujoco(
                model, data, reduce="line", hand=HandOptions(stop_gap=gap, spring_held="warn")
            )
        note = "; ".join(str(w.message).split(": ", 2)[-1][:90] for w in caught)
        variant = f"unit, line, stop_gap {gap:g}"
        t0 = time.perf_counter()
        w = solve(g, Existence(g.gravity_wrench, commands=g.commands), method="refinement",
                  time_limit=time_limit)  # fmt: skip
        rows.append({"kind": "weight", "variant": variant, "method": "refinement",
                     "status": w.status, "value": w.stable,
                     "seconds": time.perf_counter() - t0, "hand_residual": g.hand_residual,
                     "warning": note})  # fmt: skip
        for name in DIRECTIONS:
            t0 = time.perf_counter()
            sol = ask(g, name, "refinement", time_limit)
            value, _ = map_value(sol)  # NaN: no answer (time-out, not converged)
            rows.append({"kind": "predicted", "variant": variant, "method": "refinement",
                         "direction": name, "value": value, "status": sol.status,
                         "lower": sol.lower, "upper": sol.upper,
                         "seconds": time.perf_counter() - t0,
                         **_ratios(value, sim, name)})  # fmt: skip
    return rows


def mujoco_rows(model: mujoco.MjModel, data: mujoco.MjData, sim: dict[str, dict[str, float]],
                methods: tuple[str, ...], time_limit: float) -> list[dict[str, Any]]:  # fmt: skip
    """``compliance="mujoco"`` from the settled state (preload: MuJoCo's normal forces), one
    ``predicted`` row per method, motion limit (the ramp's, and free) and direction."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        g = grasp_from_mujoco(model, data, reduce="line", **MUJOCO_READ)
    note = "; ".join(str(w.message).split(": ", 2)[-1][:90] for w in caught)
    rows: list[dict[str, Any]] = []
    for method in methods:  # the weight alone, from the settled state: nothing moves
        t0 = time.perf_counter()
        w = solve(g, Existence(g.gravity_wrench, commands=g.commands, preload=scene_preload(g)),
                  method=method, time_limit=time_limit)  # fmt: skip
        rows.append({"kind": "weight", "variant": "mujoco, line", "method": method,
                     "status": w.status, "value": w.stable,
                     "seconds": time.perf_counter() - t0, "hand_residual": g.hand_residual,
                     "warning": note})  # fmt: skip
    limits = {"mujoco, line": None, "mujoco, line, free": (np.inf, np.inf)}
    for method, (variant, limit) in itertools.product(methods, limits.items()):
        for name in DIRECTIONS:
            t0 = time.perf_counter()
            q = scene_disturbance(g, object_direction(g, name), g.commands, CAP, limit)
            sol = solve(g, q, method=method, time_limit=time_limit)
            seconds = time.perf_counter() - t0
            value, _ = map_value(sol)
            shift, turn, hand = motion_size(sol)
            states = " ".join(() if sol.states is None else sol.states)
            rows.append({"kind": "predicted", "variant": variant, "method": method,
                         "direction": name, "value": value, "status": sol.status,
                         "lower": sol.lower, "upper": sol.upper, "seconds": seconds,
                         "capped": bool(sol.stats.get("capped", False)),
                         **_ratios(value, sim, name), "shift_m": shift, "turn_rad": turn,
                         "hand_rad": hand, "states": states})  # fmt: skip
    return rows


def run(path: str | Path, time_limit: float = 30.0,
        methods: tuple[str, ...] = ("modesearch",)) -> list[dict[str, Any]]:  # fmt: skip
    """Every row of the recipe (module docstring); ``time_limit`` [s] per query."""
    rows = simulated(path) + simulated(path, NOSLIP_ITERATIONS)
    by = {k: [r for r in rows if r["variant"].startswith(v)]
          for k, v in (("noslip", "noslip"), ("menagerie", "impratio"))}  # fmt: skip
    sim = {k: {r["direction"]: r["value"] for r in v} for k, v in by.items()}
    model, data = settled(path)
    rows += unit_rows(model, data, sim, time_limit)
    rows += mujoco_rows(model, data, sim, methods, time_limit)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ihm.experiments.menagerie_2f85",
                                 description=__doc__.split("\n\n")[0])  # fmt: skip
    ap.add_argument("path", help="robotiq_2f85/2f85.xml of a MuJoCo Menagerie checkout")
    ap.add_argument("--out", default="docs/experiments", help="folder for the CSV")
    ap.add_argument("--time-limit", type=float, default=30.0, help="per query [s]")
    ap.add_argument("--methods", nargs="+", default=["modesearch"],
                    help="3D methods for the compliance='mujoco' rows")  # fmt: skip
    args = ap.parse_args(argv)
    if not Path(args.path).is_file():
        ap.error(f"no such file: {args.path}")
    rows = run(args.path, args.time_limit, tuple(args.methods))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "menagerie_2f85.csv", rows)
    for r in rows:
        print({k: v for k, v in r.items() if k != "warning"})
    print(f"wrote {out / 'menagerie_2f85.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
