"""modesearch on barrett_box's grasp read with MuJoCo's contact law (``MUJOCO_READ``): the
four maps of the experiment at 12 directions, one process, per direction the answer, its
bracket, the tree's nodes and the wall time. Run on two commits to compare them::

    git checkout REV && python docs/bench/colocated/run.py OUT.csv
    python docs/bench/colocated/run.py --chart BEFORE.csv AFTER.csv   # the PNG beside them
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

import stability
from ihm.experiments import MUJOCO_READ
from ihm.sim_maps import MapSpec, _directions, _settled_grasp, scene_disturbance

PRELOADS = {"none": [0.0, 0.0, 0.0, 0.0], "pre": [0.0, 0.1, 0.1, 0.0]}


def measure(out: Path, directions: int = 12, time_limit: float = 60.0) -> None:
    rows = []
    for plane in ("xy", "xz"):
        for tag, pre in PRELOADS.items():
            spec = MapSpec("barrett_box", plane, directions, preload=pre, nonbackdrivable=True,
                           seat=[0.0, 0.01, 0.01, 0.0], frame="object", cap=10.0,
                           **MUJOCO_READ)  # fmt: skip
            g, cmds, com = _settled_grasp(spec)
            angles, units = _directions(plane, directions)
            for a, u in zip(angles, units @ g.object_mat.T, strict=True):
                f = g.object_mat.T @ u[:3]
                q = scene_disturbance(g, np.r_[f, np.cross(com, f)], cmds, 10.0)
                t = time.perf_counter()
                s = stability.solve(g, q, method="modesearch", time_limit=time_limit)
                rows.append({"plane": plane, "preload": tag, "deg": round(float(np.degrees(a)), 1),
                             "value": s.value, "status": s.status, "lower": s.lower,
                             "upper": s.upper, "nodes": s.stats.get("nodes"),
                             "time_s": round(time.perf_counter() - t, 3)})  # fmt: skip
                print(rows[-1], flush=True)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def chart(before: Path, after: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b, a = (list(csv.DictReader(open(p))) for p in (before, after))
    fig, ax = plt.subplots(figsize=(5.5, 5))
    for tag, mk in (("xy", "o"), ("xz", "s")):
        tb = [float(r["time_s"]) for r in b if r["plane"] == tag]
        ta = [float(r["time_s"]) for r in a if r["plane"] == tag]
        ax.scatter(tb, ta, marker=mk, label=f"{tag}-plane maps")
    lim = [0.1, 100.0]
    ax.plot(lim, lim, "k--", lw=0.8, label="equal")
    ax.set(xscale="log", yscale="log", xlim=lim, ylim=lim, xlabel=f"{before.stem}: wall time [s]",
           ylabel=f"{after.stem}: wall time [s]",
           title="modesearch per direction, barrett_box with MuJoCo's contact law")  # fmt: skip
    ax.legend()
    path = after.with_suffix(".png")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, nargs="+")
    ap.add_argument("--chart", action="store_true", help="chart two CSVs instead of measuring")
    args = ap.parse_args()
    if args.chart:
        print(chart(*args.out))
    else:
        measure(args.out[0])
