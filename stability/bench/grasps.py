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

Variants, in the same run: the default (``refinement`` with SCIP), ``--backends`` (e.g.
``gurobi``: the same method on the thesis' solver, where installed), and ``--baseline REV``:
the same benchmark run by the code of git revision ``REV`` (a detached worktree under the
system's temporary folder, its own process, side by side with ours: one process per core).
Rows carry the bracket ``lower``/``upper`` and ``certified`` (closed to 1e-4 relative).
``grasps_summary.csv`` has per variant, contact count and task the median and worst time,
the time-outs and the share of closed brackets; ``grasps.png`` charts the medians against
the contact count (log scale) with the thesis' Gurobi figures as markers.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
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
from .hands import BOUND_RTOL, reach
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
# the profile of a query: refinement's model building, rounds' MIPs, rounds (MIP plus its
# least-motion LP) and certification (exact LPs); the rest is Python around them
PROFILE = (
    "build_time_s",
    "mip_time_s",
    "round_time_s",
    "certify_time_s",
    # modesearch's: its node LPs and their count, its polishes (exact points)
    "lp_time_s",
    "lps",
    "polish_time_s",
    "quick_time_s",
)


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


TASKS = ("check", "max_disturbance", "optimal_commands")


def queries_of(label: str, commands: np.ndarray, directions: int = 10, wrenches: int = 10,
               seed: int = SEED) -> list[tuple[str, int, Any]]:  # fmt: skip
    """Grasp ``label``'s queries as the benchmark draws them, ``(task, k, query)`` with
    ``k`` the index within the task: one check, ``directions`` max disturbances, ``wrenches``
    optimal commands (a smaller count gives the first ones of a larger)."""
    rng = np.random.default_rng(seed * 1000 + ord(label))
    out: list[tuple[str, int, Any]] = [
        ("check", 0, Existence(ex.random_wrench(rng), commands=commands))
    ]
    out += [("max_disturbance", k, MaxDisturbance(_unit(rng), commands=commands, cap=100.0))
            for k in range(directions)]  # fmt: skip
    out += [("optimal_commands", k, OptimalCommands(ex.random_wrench(rng)))
            for k in range(wrenches)]  # fmt: skip
    return out


def bench_grasps(
    directions: int = 10, wrenches: int = 10, time_limit: float = 60.0, seed: int = SEED,
    only: str | None = None, progress: bool = True, backend: str | None = None,
    levels: int | None = None, queries: set[tuple[str, str, int]] | None = None,
    method: str = "refinement",
) -> list[dict[str, Any]]:  # fmt: skip
    """One row per solve of ``method``: grasp, contacts, task, its index ``k`` within the
    task, time_s, status, answer, bracket. The variant is the method's name, with its
    ``backend`` where one is given and ``" q<levels>"`` with ``levels`` (refinement's ``q``;
    default 9); with ``queries`` (``(grasp, task, k)``) only those run."""
    from tqdm import tqdm

    rows: list[dict[str, Any]] = []
    items = [x for x in grasps(seed) if only is None or x[0] in only]
    total = len(items) * (1 + directions + wrenches) if queries is None else len(queries)
    bar = tqdm(total=total, desc=f"grasps ({method})", disable=not progress)
    for label, g, f in items:
        for task, k, q in queries_of(label, f, directions, wrenches, seed):
            if queries is not None and (label, task, k) not in queries:
                continue
            t0 = time.perf_counter()
            opts: dict[str, Any] = {} if backend is None else {"backend": backend}
            if levels is not None:
                opts["levels"] = levels
            sol = solve(g, q, method=method, time_limit=time_limit, **opts)
            t = time.perf_counter() - t0
            ans = sol.value if task != "check" else sol.stable
            variant = method + ("" if backend is None else f" {backend}")
            variant += "" if levels is None else f" q{levels}"
            rows.append({"variant": variant, "grasp": label, "contacts": g.m,
                         "task": task, "k": k, "time_s": round(t, 4), "status": sol.status,
                         "answer": ans, "lower": sol.lower, "upper": sol.upper,
                         "rounds": len(sol.stats.get("rounds", [])),
                         "certified": sol.stats.get("certified"),
                         **{k: round(float(sol.stats.get(k, 0.0)), 4) for k in PROFILE},
                         "nodes": sol.stats.get("nodes"),
                         "force_bound": sol.stats.get("force_bound"),
                         "reach": reach(sol)})  # fmt: skip
            bar.update(1)
    bar.close()
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per grasp: median time per task (time-outs at the limit), time-outs, thesis'."""
    out = []
    for label in dict.fromkeys(r["grasp"] for r in rows):
        rs = [r for r in rows if r["grasp"] == label]
        row: dict[str, Any] = {"grasp": label, "contacts": rs[0]["contacts"]}
        for task in TASKS:
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
    png = save(fig, out / "grasps_per_grasp.png", dpi=120)
    return path, png


def baseline(rev: str, args: argparse.Namespace) -> tuple[subprocess.Popen, Path, Path]:
    """Start this benchmark at git revision ``rev`` in a detached worktree (its own
    process); returns the process, its output folder and the worktree."""
    root = Path(__file__).resolve().parents[2]
    sha = subprocess.run(["git", "rev-parse", "--short", rev], cwd=root, check=True,
                         capture_output=True, text=True).stdout.strip()  # fmt: skip
    tree = Path(tempfile.gettempdir()) / f"ihm-baseline-{sha}"
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), sha], cwd=root,
                       check=True, capture_output=True)  # fmt: skip
    out = Path(tempfile.mkdtemp(prefix=f"ihm-baseline-{sha}-"))
    cmd = [sys.executable, "-m", "stability.bench", "grasps", "--directions",
           str(args.directions), "--wrenches", str(args.wrenches), "--time-limit",
           str(args.time_limit or 60.0), "--out", str(out)]  # fmt: skip
    if args.only:
        cmd += ["--only", args.only]
    env = dict(os.environ, PYTHONPATH=str(tree))
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    return proc, out, tree


def read_baseline(out: Path, rev: str) -> list[dict[str, Any]]:
    """The baseline's rows, as ours (the old CSV has no bracket columns)."""
    rows = []
    with open(out / "grasps.csv", newline="") as fh:
        for r in csv.DictReader(fh):
            rows.append({"variant": f"landed {rev}", "grasp": r["grasp"],
                         "contacts": int(r["contacts"]), "task": r["task"],
                         "time_s": float(r["time_s"]), "status": r["status"],
                         "answer": r["answer"], "lower": None, "upper": None,
                         "rounds": r.get("rounds"), "certified": r.get("certified")})  # fmt: skip
    return rows


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a ``grasps.csv`` this benchmark wrote (``--merge``), typed as written; a
    file without the ``k`` column gets it from the rows' order (the benchmark's)."""

    def num(v: str) -> float | None:
        return None if v in ("", "None") else float(v)

    rows = []
    seen: dict[tuple[str, str, str], int] = {}
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            key = (r["variant"], r["grasp"], r["task"])
            seen[key] = seen.get(key, -1) + 1
            typed = {
                "contacts": int(r["contacts"]),
                "k": int(r["k"]) if r.get("k") not in (None, "") else seen[key],
                "time_s": float(r["time_s"]),
                "lower": num(r.get("lower", "")),
                "upper": num(r.get("upper", "")),
                "force_bound": num(r.get("force_bound", "")),
                "reach": num(r.get("reach", "")),
            }
            rows.append({**r, **typed})
    return rows


def merge_rows(files: list[Path]) -> list[dict[str, Any]]:
    """The rows of ``files`` in order; a row of a later file replaces the earlier one of the
    same variant, grasp, task and ``k`` (a query re-run after a change to its code path)."""
    merged: dict[tuple[str, str, str, int], dict[str, Any]] = {}
    for path in files:
        for r in read_rows(path):
            merged[(r["variant"], r["grasp"], r["task"], r["k"])] = r
    return list(merged.values())


def conflicts(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every exact value of one variant beyond another variant's proven bound on the same
    query (max disturbance: its ``lower`` above the other's ``upper``; optimal commands:
    its ``upper`` below the other's ``lower``, both by more than ``BOUND_RTOL`` relative).
    ``inside``: the point's ``reach`` is within the other's box (``force_bound``; unknown
    counts as inside): a wrong bound. Beyond the box, the bound does not speak for it
    (:mod:`stability.bench.hands`)."""
    by_q: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for r in rows:
        if r["task"] != "check":
            by_q.setdefault((r["grasp"], r["task"], int(r["k"])), []).append(r)
    out = []
    for (label, task, k), rs in by_q.items():
        for a in rs:
            for b in rs:
                md = task == "max_disturbance"
                val, bound = (a["lower"], b["upper"]) if md else (a["upper"], b["lower"])
                if a is b or val is None or bound is None:
                    continue
                beyond = val - bound if md else bound - val
                if beyond <= BOUND_RTOL * abs(bound) + 1e-12:
                    continue
                far, B = a.get("reach"), b.get("force_bound")
                out.append({"grasp": label, "task": task, "k": k, "variant": a["variant"],
                            "value": val, "other": b["variant"], "bound": bound,
                            "reach": far, "other_force_bound": B,
                            "inside": far is None or B is None or far <= B})  # fmt: skip
    return out


def print_conflicts(rows: list[dict[str, Any]]) -> None:
    found = conflicts(rows)
    inside = sum(c["inside"] for c in found)
    print(f"exact values beyond another variant's bound: {inside} inside its box (wrong "
          f"bounds), {len(found) - inside} beyond it")  # fmt: skip
    for c in found:
        print(f"  {c['grasp']}:{c['task']}:{c['k']} {c['variant']} {c['value']:.8g} vs "
              f"{c['other']} {c['bound']:.8g} (reach {c['reach']}, "
              f"its box {c['other_force_bound']})")  # fmt: skip


def parse_queries(text: str | None) -> set[tuple[str, str, int]] | None:
    """``--queries 'h:max_disturbance:9,b:check:0'`` as ``{(grasp, task, k)}``."""
    if not text:
        return None
    out = set()
    for item in text.split(","):
        parts = item.strip().split(":")
        if len(parts) != 3 or parts[1] not in TASKS or not parts[2].isdigit():
            raise SystemExit(f"--queries: want grasp:task:index, got {item!r}")
        out.add((parts[0], parts[1], int(parts[2])))
    return out


def by_contacts(rows: list[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    """Per variant, contact count and task: median and worst time (time-outs and errors
    at the limit), time-outs, answered share and closed-bracket share."""
    out = []
    for variant in dict.fromkeys(r["variant"] for r in rows):
        for m in sorted({r["contacts"] for r in rows}):
            for task in TASKS:
                rs = [r for r in rows if r["variant"] == variant and r["contacts"] == m
                      and r["task"] == task]  # fmt: skip
                if not rs:
                    continue
                ts = [r["time_s"] if r["status"] == "solved" else max(r["time_s"], time_limit)
                      for r in rs]  # fmt: skip
                # closed: a certified bracket; a check: any answer (a point or a proof)
                # (the landed code's checks carry no certificate: its "stable" needed none)
                closed = [str(r["certified"]) == "True" or (task == "check" and r["status"]
                          == "solved" and not r["variant"].startswith("landed"))
                          for r in rs]  # fmt: skip
                out.append({"variant": variant, "contacts": m, "task": task, "n": len(rs),
                            "median_s": float(np.median(ts)), "worst_s": float(np.max(ts)),
                            "timeouts": sum(r["status"] == "timeout" for r in rs),
                            "solved": sum(r["status"] == "solved" for r in rs),
                            "closed": sum(closed)})  # fmt: skip
    return out


def print_by_contacts(summ: list[dict[str, Any]]) -> None:
    thesis = {}
    for m, c, d, o in THESIS.values():
        for task, v in (("check", c), ("max_disturbance", d), ("optimal_commands", o)):
            thesis.setdefault((m, task), []).append(v)
    print(f"{'variant':>16} {'m':>2} {'task':>17} | {'median s':>9} {'worst s':>8} | "
          f"{'timeouts':>8} {'closed':>7} | thesis (Gurobi) s")  # fmt: skip
    for r in summ:
        th = thesis.get((r["contacts"], r["task"]), [])
        rng = f"{min(th):.3g}-{max(th):.3g}" if th else "-"
        print(f"{r['variant']:>16} {r['contacts']:>2} {r['task']:>17} | {r['median_s']:9.3f} "
              f"{r['worst_s']:8.2f} | {r['timeouts']:>3}/{r['n']:<4} {r['closed']:>3}/{r['n']:<3} "
              f"| {rng}")  # fmt: skip


def chart(summ: list[dict[str, Any]], path: Path) -> Path:
    """Median time per query against the contact count, one panel per task, log scale."""
    plt = pyplot()
    tasks = [("check", "stability check", 1), ("max_disturbance", "max disturbance", 2),
             ("optimal_commands", "optimal commands", 3)]  # fmt: skip
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), sharey=True)
    for ax, (task, name, k) in zip(axes, tasks, strict=True):
        for j, variant in enumerate(dict.fromkeys(r["variant"] for r in summ)):
            rs = [r for r in summ if r["variant"] == variant and r["task"] == task]
            ax.plot([r["contacts"] for r in rs], [r["median_s"] for r in rs], "o-",
                    color=f"C{j}", label=f"{variant} (median)")  # fmt: skip
            ax.plot([r["contacts"] for r in rs], [r["worst_s"] for r in rs], "v:",
                    color=f"C{j}", alpha=0.6, label=f"{variant} (worst)")  # fmt: skip
        th = [(m, v[k]) for v in THESIS.values() for m in [v[0]]]
        ax.scatter([m for m, _ in th], [v for _, v in th], marker="_", s=200, color="k",
                   zorder=3, label="thesis (Gurobi, desktop), per grasp")  # fmt: skip
        ax.set_yscale("log")
        ax.set_xlabel("contacts")
        ax.set_title(name)
        ax.set_xticks([3, 4, 5, 6])
        ax.grid(True, which="both", axis="y", alpha=0.3)
    axes[0].set_ylabel("time per query [s] (time-outs at the limit)")
    axes[2].legend(fontsize=7)
    return save(fig, path, dpi=120)


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench grasps``: options ``--directions``, ``--wrenches``,
    ``--time-limit`` (default 60 s), ``--only``, ``--out``, ``--baseline REV``,
    ``--backends`` (comma-separated, beside the default), ``--levels`` (refinement's ``q``
    for this run's variants, not the baseline's), ``--merge CSV ...`` (no run: the rows of
    earlier runs' ``grasps.csv`` files, summarised and charted together into ``--out``)."""
    limit = args.time_limit or 60.0
    if getattr(args, "merge", None):  # earlier runs' rows, summarised and charted together
        rows = merge_rows([Path(p) for p in args.merge])
        summ = by_contacts(rows, limit)
        print_by_contacts(summ)
        print_conflicts(rows)
        Path(args.out).mkdir(parents=True, exist_ok=True)
        csv_path = write_csv(Path(args.out) / "grasps.csv", rows)
        write_csv(Path(args.out) / "grasps_summary.csv", summ)
        png = chart(summ, Path(args.out) / "grasps.png")
        print(f"wrote {csv_path}, grasps_summary.csv and {png}")
        return
    base = None
    if getattr(args, "baseline", None):
        base = baseline(args.baseline, args)
    rows = []
    lv = getattr(args, "levels", None)
    qs = parse_queries(getattr(args, "queries", None))
    methods = [
        m for m in (getattr(args, "methods", None) or "modesearch,refinement").split(",") if m
    ]
    for method in methods:
        if method == "refinement" and getattr(args, "skip_default", False):
            continue
        rows += bench_grasps(args.directions, args.wrenches, limit, only=args.only,
                             levels=lv if method == "refinement" else None, queries=qs,
                             method=method)  # fmt: skip
    for b in [b for b in (getattr(args, "backends", None) or "").split(",") if b]:
        rows += bench_grasps(args.directions, args.wrenches, limit, only=args.only, backend=b,
                             levels=lv, queries=qs)  # fmt: skip
    if base is not None:
        proc, out, _ = base
        proc.wait()
        rows += read_baseline(out, args.baseline)
    mine = [r for r in rows if r["variant"] == methods[0]]
    if mine:
        print_grasps(summary(mine))
    summ = by_contacts(rows, limit)
    print_by_contacts(summ)
    print_conflicts(rows)
    if mine:
        write_grasps(mine, Path(args.out))
    Path(args.out).mkdir(parents=True, exist_ok=True)
    csv_path = write_csv(Path(args.out) / "grasps.csv", rows)
    write_csv(Path(args.out) / "grasps_summary.csv", summ)
    png = chart(summ, Path(args.out) / "grasps.png")
    print(f"wrote {csv_path}, grasps_summary.csv and {png}")
