"""``python -m stability.bench hands``: random hand grasps as a new user would draw them,
``--n`` per contact count (``--contacts``, default 3-6), every method on the same queries.

Queries: :func:`stability.batch.random_rows` (``query="MaxDisturbance"``: the spatial
single-joint-finger hands of :func:`stability.examples.random_fingers` with compliant
fingers, 1 N per finger, a random direction, cap :data:`CAP`), seed ``--seed`` plus the
contact count. An "unstable" answer (no load along the direction holds) counts as 0.
Methods (``--methods``, default ``modesearch,refinement,exact``), each limited to
``--time-limit`` seconds per query; ``--exact-contacts`` (default 3,4) limits ``exact``,
the reference, to the counts where it can finish, and ``--refinement-contacts`` (default
all) limits ``refinement``.

Per query and method a row of ``hands.csv``: time, status, value, bracket, certified. The
accuracy of a value is its relative distance to the reference (``exact``'s checked value
where it is solved and certified, else the best exact value any method found); and any
exact value above another method's proven upper bound is flagged. A bound is proven for the
points inside its method's box (``stats["force_bound"]`` ``B``: forces and separations up to
``B``, motions up to a multiple of ``2 B``), so a point counts against it only when its
``reach`` (its largest contact force or contact displacement ``|G^T r - J q|``, in the unit
springs' newtons) is at most that ``B`` (``bound_violated``); a point beyond the other's
box is counted apart (``beyond_box``): on grasps whose best value is approached only as a
slide grows without limit, a larger box gives a larger value.
``hands_summary.csv``: per method and contact count the median and worst time, time-outs,
closed brackets, median and worst error. ``hands.png``: median time against contacts (log
scale) and every answer's error against its time.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..api import solve
from ..batch import decode_row, random_rows
from ..io import write_csv
from .plots import pyplot, save

CAP = 100.0  # [N] the thesis protocol's cap
ERROR_FLOOR = 1e-9  # errors below are drawn at this line
BOUND_RTOL = 1e-7  # an exact value above a proven bound by more than this (relative): flagged


def _ints(text: str | None, default: list[int]) -> list[int]:
    return default if not text else [int(t) for t in text.split(",") if t]


def queries(n: int, contacts: list[int], seed: int) -> list[tuple[str, int, Any, Any]]:
    """``(id, contacts, grasp, query)`` for ``n`` random hand grasps per contact count."""
    out = []
    for m in contacts:
        for k, row in enumerate(random_rows(n, contacts=m, query="MaxDisturbance",
                                            seed=seed + m, cap=CAP)):  # fmt: skip
            g, q, _, _ = decode_row(k, row)
            out.append((row["id"], m, g, q))
    return out


def run(qs: list[tuple[str, int, Any, Any]], methods: list[str], time_limit: float,
        only: dict[str, list[int]], progress: bool = True) -> list[dict[str, Any]]:  # fmt: skip
    """One row per (query, method) answered; ``only[method]``: the contact counts it runs."""
    from tqdm import tqdm

    jobs = [(i, m) for i, (_, c, _, _) in enumerate(qs) for m in methods
            if m not in only or c in only[m]]  # fmt: skip
    rows = []
    for i, method in tqdm(jobs, desc="hands", disable=not progress):
        qid, m, g, q = qs[i]
        t0 = time.perf_counter()
        sol = solve(g, q, method=method, time_limit=time_limit)
        value = 0.0 if sol.status == "solved" and not sol.stable else sol.value
        rows.append({"id": qid, "contacts": m, "method": method,
                     "time_s": round(time.perf_counter() - t0, 4), "status": sol.status,
                     "value": value, "lower": sol.lower, "upper": sol.upper,
                     "certified": sol.stats.get("certified"),
                     "nodes": sol.stats.get("nodes"), "force_bound": sol.stats.get("force_bound"),
                     "reach": reach(sol)})  # fmt: skip
    return score(rows)


def reach(sol: Any) -> float | None:
    """The exact point's largest contact force or contact displacement ``d = G^T r - J q``
    (module docstring); None without a point."""
    if sol.status != "solved" or sol.forces is None or sol.motion is None:
        return None
    g = sol.grasp
    d = g.G.T @ np.asarray(sol.motion, dtype=float)
    if sol.hand_motion is not None and g.J is not None:
        d = d - g.J @ np.asarray(sol.hand_motion, dtype=float)
    return float(max(np.abs(sol.forces).max(initial=0.0), np.abs(d).max(initial=0.0)))


def score(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each row's ``reference``, ``error``, ``bound_violated`` and ``beyond_box`` (module
    docstring)."""
    by_id: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        by_id.setdefault(r["id"], []).append(r)
    for rs in by_id.values():
        exact = [r for r in rs if r["method"] == "exact" and r["status"] == "solved"
                 and r["certified"] and r["value"] is not None]  # fmt: skip
        lowers = [r["lower"] for r in rs if r["lower"] is not None]
        lowers += [r["value"] for r in rs if r["status"] == "solved" and r["value"] is not None]
        ref = exact[0]["value"] if exact else (max(lowers) if lowers else None)
        bounds = [(r["upper"], r.get("force_bound")) for r in rs if r["upper"] is not None]
        for r in rs:
            r["reference"] = ref
            v = r["value"] if r["status"] == "solved" else None
            r["error"] = None if v is None or ref is None else abs(v - ref) / max(abs(ref), 1e-12)
            low, far = r["lower"], r.get("reach")
            above = [B for u, B in bounds if low is not None and low > u * (1 + BOUND_RTOL) + 1e-12]
            inside = [B is None or far is None or far <= float(B) for B in above]
            r["bound_violated"] = any(inside)
            r["beyond_box"] = bool(above) and not any(inside)
    return rows


def summary(rows: list[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        for m in sorted({r["contacts"] for r in rows if r["method"] == method}):
            rs = [r for r in rows if r["method"] == method and r["contacts"] == m]
            ts = [r["time_s"] if r["status"] == "solved" else max(r["time_s"], time_limit)
                  for r in rs]  # fmt: skip
            errs = [r["error"] for r in rs if r["error"] is not None]
            out.append({"method": method, "contacts": m, "n": len(rs),
                        "median_s": float(np.median(ts)), "worst_s": float(np.max(ts)),
                        "timeouts": sum(r["status"] == "timeout" for r in rs),
                        "solved": sum(r["status"] == "solved" for r in rs),
                        "closed": sum(_closed(r) for r in rs),
                        "median_error": float(np.median(errs)) if errs else None,
                        "worst_error": float(np.max(errs)) if errs else None,
                        "bound_violations": sum(bool(r["bound_violated"]) for r in rs),
                        "beyond_box": sum(bool(r["beyond_box"]) for r in rs)})  # fmt: skip
    return out


def _closed(r: dict[str, Any]) -> bool:
    """A certified bracket, or a proof of "unstable" (a solved answer of value 0 without a
    bracket)."""
    return bool(r["certified"]) or (r["status"] == "solved" and r["value"] == 0.0
                                     and r["lower"] is None)  # fmt: skip


def chart(rows: list[dict[str, Any]], summ: list[dict[str, Any]], path: Path) -> Path:
    """Median time against contacts, and every answer's error against its time."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for j, method in enumerate(dict.fromkeys(r["method"] for r in summ)):
        rs = [r for r in summ if r["method"] == method]
        a1.plot([r["contacts"] for r in rs], [r["median_s"] for r in rs], "o-", color=f"C{j}",
                label=f"{method} (median)")  # fmt: skip
        a1.plot([r["contacts"] for r in rs], [r["worst_s"] for r in rs], "v:", color=f"C{j}",
                alpha=0.6, label=f"{method} (worst)")  # fmt: skip
        pts = [r for r in rows if r["method"] == method and r["error"] is not None]
        a2.scatter([r["time_s"] for r in pts], [max(r["error"], ERROR_FLOOR) for r in pts],
                   s=14, color=f"C{j}", alpha=0.7, label=method)  # fmt: skip
    a1.set_yscale("log")
    a1.set_xlabel("contacts")
    a1.set_ylabel("time per max disturbance [s] (time-outs at the limit)")
    a1.set_xticks(sorted({r["contacts"] for r in summ}))
    a1.grid(True, which="both", axis="y", alpha=0.3)
    a1.legend(fontsize=7)
    a2.set_xscale("log")
    a2.set_yscale("log")
    a2.set_ylim(ERROR_FLOOR / 2, 1.0)
    a2.axhline(1e-4, color="k", lw=0.8, ls="--", label="1e-4 (the brackets' gap)")
    a2.set_xlabel("time [s]")
    a2.set_ylabel(f"|value - reference| / reference (floor {ERROR_FLOOR:g})")
    a2.set_title("accuracy against time (reference: exact, else the best exact value)")
    a2.grid(True, which="both", alpha=0.3)
    a2.legend(fontsize=7)
    return save(fig, path, dpi=120)


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench hands``: ``--n``, ``--contacts``, ``--methods``,
    ``--exact-contacts``, ``--refinement-contacts``, ``--time-limit`` (default 60 s),
    ``--seed``, ``--out``; ``--merge CSV ...``: no run, earlier runs' rows together."""
    limit = args.time_limit or 60.0
    out = Path(args.out)
    if getattr(args, "merge", None):  # earlier runs' rows, re-scored and charted together
        rows = merge_rows([Path(p) for p in args.merge])
        return report(score(rows), limit, out)
    contacts = _ints(args.contacts, [3, 4, 5, 6])
    methods = [m for m in (args.methods or "modesearch,refinement,exact").split(",") if m]
    only = {"exact": _ints(args.exact_contacts, [3, 4])}
    if args.refinement_contacts:
        only["refinement"] = _ints(args.refinement_contacts, contacts)
    qs = queries(args.n, contacts, args.seed)
    report(run(qs, methods, limit, only), limit, out)


def merge_rows(files: list[Path]) -> list[dict[str, Any]]:
    """The rows of earlier runs' ``hands.csv`` files (``--merge``), typed; a later file's row
    replaces an earlier one of the same query and method (a method re-run after a change)."""

    def num(v: str) -> float | None:
        return None if v in ("", "None") else float(v)

    merged: dict[tuple[str, str], dict[str, Any]] = {}
    for path in files:
        with open(path, newline="") as fh:
            for r in csv.DictReader(fh):
                row = {"id": r["id"], "contacts": int(r["contacts"]), "method": r["method"],
                       "time_s": float(r["time_s"]), "status": r["status"],
                       "value": num(r["value"]), "lower": num(r["lower"]),
                       "upper": num(r["upper"]), "certified": r["certified"] == "True",
                       "nodes": r["nodes"], "force_bound": num(r.get("force_bound", "")),
                       "reach": num(r.get("reach", ""))}  # fmt: skip
                merged[(row["id"], row["method"])] = row
    return list(merged.values())


def report(rows: list[dict[str, Any]], limit: float, out: Path) -> None:
    """Print the summary; write ``hands.csv``, ``hands_summary.csv`` and ``hands.png``."""
    summ = summary(rows, limit)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{'method':>11} {'m':>2} | {'median s':>9} {'worst s':>8} | {'t/o':>4} {'closed':>7} | "
          f"{'median err':>10} {'worst err':>10} | bound violations (beyond its box)")  # fmt: skip
    for r in summ:
        me = "-" if r["median_error"] is None else f"{r['median_error']:.2e}"
        we = "-" if r["worst_error"] is None else f"{r['worst_error']:.2e}"
        print(f"{r['method']:>11} {r['contacts']:>2} | {r['median_s']:9.3f} {r['worst_s']:8.2f} | "
              f"{r['timeouts']:>4} {r['closed']:>3}/{r['n']:<3} | {me:>10} {we:>10} | "
              f"{r['bound_violations']} ({r['beyond_box']})")  # fmt: skip
    csv_path = write_csv(out / "hands.csv", rows)
    write_csv(out / "hands_summary.csv", summ)
    png = chart(rows, summ, out / "hands.png")
    print(f"wrote {csv_path}, hands_summary.csv and {png}")
