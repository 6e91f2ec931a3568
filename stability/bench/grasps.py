"""``python -m stability.bench grasps``: the thesis' runtime table (tab:comp_data) for
``method="refinement"`` on twelve generated grasps.

Grasps (a)-(l) have the thesis' contact counts (four with 3 contacts, five with 4, one with
5, two with 6). Each is :func:`stability.examples.random_fingers` (contacts on a 5 cm
sphere, one single-joint finger per contact, ``R = I``) with *balanced* commands: the LP
``min sum c_n`` over internal forces (``G c = 0``, friction within half the cone,
``c_n >= 1`` N) gives contact forces that hold the object with no load, and the commands
are the joint torques that balance them, ``f_c = J^T c`` (the hand pushes the object with
no net wrench, as a grasp planner's output would). A grasp whose internal-force LP is
infeasible (no force closure) or whose torques are not all positive is redrawn.

Per grasp (fixed seed): one stability check (``Existence`` of a random wrench,
:func:`~stability.examples.random_wrench`), the maximum disturbance along ``--directions``
random unit directions (cap 100), and optimal commands (minimise the largest) for
``--wrenches`` random wrenches; each solve limited to ``--time-limit`` seconds (a time-out
counts at the limit in the medians and is reported). Writes ``grasps.csv`` (one row per
solve) and ``grasps.png`` (median time per grasp and task, log scale, with the thesis'
medians), and prints the table beside the thesis'.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import examples as ex
from ..api import solve
from ..grasp import Grasp
from ..io import write_csv
from ..mip import INF, MipModel
from ..mip import solve as mip_solve
from ..queries import Existence, MaxDisturbance, OptimalCommands
from .plots import pyplot, save

CONTACTS = [3, 3, 3, 3, 4, 4, 4, 4, 4, 5, 6, 6]
LABELS = "abcdefghijkl"
# thesis tab:comp_data: (contacts, check s, max-dist median s, optimal-torques median s)
THESIS = {
    "a": (3, 0.246, 0.754, 0.343), "b": (3, 0.234, 0.745, 0.408),
    "c": (3, 0.294, 0.907, 0.345), "d": (3, 0.259, 0.560, 0.281),
    "e": (4, 1.07, 6.39, 3.83), "f": (4, 15.7, 39.5, 9.58), "g": (4, 2.78, 20.8, 12.3),
    "h": (4, 8.02, 23.2, 8.10), "i": (4, 1.66, 11.4, 1.60), "j": (5, 6.06, 105, 19.0),
    "k": (6, 51.0, 344, 80.6), "l": (6, 27.5, 330, 626),
}  # fmt: skip
TARGETS = {3: (0.05, 0.15), 6: (5.0, 30.0)}  # contacts: (check s, max disturbance s)
SEED = 7


def balanced_commands(g: Grasp, cone: float = 0.5, least: float = 1.0) -> np.ndarray | None:
    """Joint torques ``J^T c`` of the least internal force ``c`` (``G c = 0``, friction
    within ``cone`` of the friction cone as an inscribed 8-gon, ``c_n >= least`` N); None if
    there is none or a torque is not positive."""
    m = g.m
    M = MipModel("internal force")
    c = M.add_vars(3 * m, -INF, INF, "C", "c").reshape(m, 3)
    for i in range(m):
        M.lb[int(c[i, 0])] = least
        mu = cone * float(g.mu[i]) * np.cos(np.pi / 8)
        for th in 2 * np.pi * (np.arange(8) + 0.5) / 8:
            M.add_row([int(c[i, 0]), int(c[i, 1]), int(c[i, 2])],
                      [-mu, np.cos(th), np.sin(th)], -INF, 0.0)  # fmt: skip
    for row in range(6):
        M.add_row(c.reshape(-1), g.G[row], 0.0, 0.0)
    M.set_objective(c[:, 0], np.ones(m))
    res = mip_solve(M, backend="highs", polish=False)
    if res.status != "optimal":
        return None
    f = g.J.T @ res.x[c.reshape(-1)]
    return f if np.all(f > 1e-3) else None


def grasps(seed: int = SEED) -> list[tuple[str, Grasp, np.ndarray]]:
    """The twelve (label, grasp, commands)."""
    rng = np.random.default_rng(seed)
    out = []
    for label, m in zip(LABELS, CONTACTS, strict=True):
        while True:
            g = ex.random_fingers(rng, m)
            f = balanced_commands(g)
            if f is not None:
                out.append((label, g, f))
                break
    return out


def _unit(rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=6) * ex.RANDOM_WRENCH_SCALE
    return d / np.linalg.norm(d)


def bench_grasps(
    directions: int = 10, wrenches: int = 10, time_limit: float = 60.0, seed: int = SEED,
    only: str | None = None, progress: bool = True,
) -> list[dict[str, Any]]:  # fmt: skip
    """One row per solve: grasp, contacts, task, time_s, status, answer."""
    from tqdm import tqdm

    rows: list[dict[str, Any]] = []
    items = [x for x in grasps(seed) if only is None or x[0] in only]
    total = len(items) * (1 + directions + wrenches)
    bar = tqdm(total=total, desc="grasps", disable=not progress)
    for label, g, f in items:
        rng = np.random.default_rng(seed * 1000 + ord(label))
        tasks: list[tuple[str, Any]] = [("check", Existence(ex.random_wrench(rng), commands=f))]
        tasks += [("max_disturbance", MaxDisturbance(_unit(rng), commands=f, cap=100.0))
                  for _ in range(directions)]  # fmt: skip
        tasks += [("optimal_commands", OptimalCommands(ex.random_wrench(rng)))
                  for _ in range(wrenches)]  # fmt: skip
        for task, q in tasks:
            t0 = time.perf_counter()
            sol = solve(g, q, method="refinement", time_limit=time_limit)
            t = time.perf_counter() - t0
            ans = sol.value if task != "check" else sol.stable
            rows.append({"grasp": label, "contacts": g.m, "task": task, "time_s": round(t, 4),
                         "status": sol.status, "answer": ans,
                         "rounds": len(sol.stats.get("rounds", [])),
                         "certified": sol.stats.get("certified")})  # fmt: skip
            bar.update(1)
    bar.close()
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per grasp: median time per task (time-outs at the limit), time-outs, thesis'."""
    out = []
    for label in dict.fromkeys(r["grasp"] for r in rows):
        rs = [r for r in rows if r["grasp"] == label]
        row: dict[str, Any] = {"grasp": label, "contacts": rs[0]["contacts"]}
        for task in ("check", "max_disturbance", "optimal_commands"):
            ts = [r["time_s"] for r in rs if r["task"] == task]
            row[task + "_s"] = float(np.median(ts)) if ts else float("nan")
            row[task + "_timeouts"] = sum(r["status"] == "timeout" for r in rs if r["task"] == task)
        th = THESIS[label]
        row["thesis_check_s"], row["thesis_max_s"], row["thesis_opt_s"] = th[1], th[2], th[3]
        out.append(row)
    return out


def print_grasps(summ: list[dict[str, Any]]) -> None:
    print(f"{'grasp':>5} {'m':>2} | {'check s':>8} {'thesis':>7} | {'max dist s':>10} "
          f"{'thesis':>7} | {'opt cmd s':>9} {'thesis':>7} | time-outs")  # fmt: skip
    for r in summ:
        to = (r["check_timeouts"], r["max_disturbance_timeouts"], r["optimal_commands_timeouts"])
        print(f"{r['grasp']:>5} {r['contacts']:>2} | {r['check_s']:8.3f} "
              f"{r['thesis_check_s']:7.3g} | {r['max_disturbance_s']:10.3f} "
              f"{r['thesis_max_s']:7.3g} | {r['optimal_commands_s']:9.3f} "
              f"{r['thesis_opt_s']:7.3g} | {to}")  # fmt: skip
    for m, (tc, tm) in TARGETS.items():
        rs = [r for r in summ if r["contacts"] == m]
        if rs:
            c = float(np.median([r["check_s"] for r in rs]))
            d = float(np.median([r["max_disturbance_s"] for r in rs]))
            print(f"{m} contacts: median check {c:.3f} s (target {tc}), median max "
                  f"disturbance {d:.3f} s (target {tm})")  # fmt: skip


def write_grasps(rows: list[dict[str, Any]], out: Path) -> tuple[Path, Path]:
    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    path = write_csv(out / "grasps.csv", rows)
    summ = summary(rows)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    x = np.arange(len(summ))
    tasks = [("check_s", "thesis_check_s", "stability check", "C0"),
             ("max_disturbance_s", "thesis_max_s", "max disturbance", "C1"),
             ("optimal_commands_s", "thesis_opt_s", "optimal commands", "C2")]  # fmt: skip
    for k, (ours, theirs, name, col) in enumerate(tasks):
        ax.bar(x + (k - 1) * 0.27, [r[ours] for r in summ], 0.27, color=col,
               label=f"{name} (ours, median)")  # fmt: skip
        lab = "thesis (Gurobi, desktop)" if k == 0 else None
        ax.scatter(x + (k - 1) * 0.27, [r[theirs] for r in summ], marker="_", s=120,
                   color="k", zorder=3, label=lab)  # fmt: skip
    ax.set_xticks(x, [f"({r['grasp']})\n{r['contacts']}" for r in summ])
    ax.set_yscale("log")
    ax.set_ylabel("time per query [s]")
    ax.set_xlabel("grasp / contacts")
    ax.set_title("refinement on twelve grasps: medians per task (this 2-core machine)")
    ax.legend(fontsize=8, ncol=2)
    ax.grid(True, which="both", axis="y", alpha=0.3)
    png = save(fig, out / "grasps.png", dpi=120)
    return path, png


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench grasps``: options ``--directions``, ``--wrenches``,
    ``--time-limit`` (default 60 s), ``--only``, ``--out``."""
    rows = bench_grasps(args.directions, args.wrenches, args.time_limit or 60.0,
                        only=args.only)  # fmt: skip
    print_grasps(summary(rows))
    csv_path, png = write_grasps(rows, Path(args.out))
    print(f"wrote {csv_path} and {png}")
