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
``forcerange`` bound (5: saturated), ``grasp_from_mujoco(reduce="line")`` (refused: the
couplers rest off their stops, held by the spring links), then with
``spring_held="warn"``, with and without ``stop_gap``, ``refinement`` along the six axis
forces on top of the weight, and :func:`ihm.resistance.simulated_resistance` on fresh
settles. Writes
``OUT/menagerie_2f85.csv`` and prints the table and the warnings.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from stability import Existence, MaxDisturbance, solve
from stability.io import write_csv

from ..contacts import HandModelError, HandOptions, grasp_from_mujoco
from ..resistance import ResistanceOptions, simulated_resistance
from ..scenes import settle

__all__ = ["build", "main"]

BOX_HALF_M = 0.015
BOX_MASS_KG = 0.05
BOX_Z_M = 0.145  # between the pads' halves (their seam is at z = 0.1415 m, open)
FORCE = 5.0  # the actuator's forcerange bound
DIRECTIONS = ("+x", "-x", "+y", "-y", "+z", "-z")


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


def _unit(name: str) -> np.ndarray:
    u = np.zeros(6)
    u["xyz".index(name[1])] = 1.0 if name[0] == "+" else -1.0
    return u


def run(path: str | Path, time_limit: float = 30.0) -> list[dict[str, Any]]:
    def fresh() -> tuple[mujoco.MjModel, mujoco.MjData]:
        model = build(path)
        data = mujoco.MjData(model)
        settle(model, data, [FORCE])
        return model, data

    model, data = fresh()
    rows: list[dict[str, Any]] = []
    sim = {}
    for name in DIRECTIONS:
        m2, d2 = fresh()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r = simulated_resistance(m2, d2, _unit(name), options=ResistanceOptions(cap=100.0))
        sim[name] = r.value
        rows.append({"kind": "simulated", "variant": f"impratio {m2.opt.impratio:g}",
                     "direction": name, "value": r.value, "reason": r.reason,
                     "creep_m": r.creep_shift,
                     "slow_value": (r.rate_check or {}).get("slow_value"),
                     "warning": "; ".join(str(w.message) for w in caught)})  # fmt: skip
    try:  # the recipe as it stands: refused, naming what is not supported
        grasp_from_mujoco(model, data, reduce="line")
        refusal = ""
    except HandModelError as exc:
        refusal = str(exc)
    rows.append({"kind": "grasp_from_mujoco", "variant": "defaults", "status":
                 "refused" if refusal else "accepted", "warning": refusal})  # fmt: skip
    for gap in (0.0, 0.02):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            g = grasp_from_mujoco(
                model, data, reduce="line", hand=HandOptions(stop_gap=gap, spring_held="warn")
            )
        note = "; ".join(str(w.message).split(": ", 2)[-1][:90] for w in caught)
        variant = f"line, stop_gap {gap:g}"
        t0 = time.perf_counter()
        w = solve(g, Existence(g.gravity_wrench, commands=g.commands), method="refinement",
                  time_limit=time_limit)  # fmt: skip
        rows.append({"kind": "weight", "variant": variant, "status": w.status,
                     "value": w.stable, "seconds": time.perf_counter() - t0,
                     "hand_residual": g.hand_residual, "warning": note})  # fmt: skip
        for name in DIRECTIONS:
            u = _unit(name)
            d = np.r_[g.object_mat.T @ u[:3], g.object_mat.T @ u[3:]]
            t0 = time.perf_counter()
            sol = solve(g, MaxDisturbance(d, commands=g.commands, cap=100.0,
                                          base=g.gravity_wrench),
                        method="refinement", time_limit=time_limit)  # fmt: skip
            value = np.nan  # no answer (time-out, not converged)
            if sol.status == "solved":
                value = float(sol.value) if sol.stable else 0.0  # 0: unstable
            rows.append({"kind": "predicted", "variant": variant, "direction": name,
                         "value": value, "status": sol.status,
                         "seconds": time.perf_counter() - t0,
                         "ratio": value / sim[name] if sim[name] > 0 else np.nan})  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ihm.experiments.menagerie_2f85",
                                 description=__doc__.split("\n\n")[0])  # fmt: skip
    ap.add_argument("path", help="robotiq_2f85/2f85.xml of a MuJoCo Menagerie checkout")
    ap.add_argument("--out", default="docs/experiments", help="folder for the CSV")
    ap.add_argument("--time-limit", type=float, default=30.0, help="per query [s]")
    args = ap.parse_args(argv)
    if not Path(args.path).is_file():
        ap.error(f"no such file: {args.path}")
    rows = run(args.path, args.time_limit)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "menagerie_2f85.csv", rows)
    for r in rows:
        print({k: v for k, v in r.items() if k != "warning"})
    print(f"wrote {out / 'menagerie_2f85.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
