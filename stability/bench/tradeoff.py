"""``python -m stability.bench tradeoff``: time against error, every 3D method and setting
on the same queries, the error measured against ``method="exact"`` (the exact problem
solved globally).

Queries (MaxDisturbance, cap 100 N): the pinch along +z (commands 0.1 N m), the tendon
finger along +y and +z (:data:`stability.examples.TENDON_FORCE`), and the thesis' planar
three-contact grasp embedded in z = 0 with preload 1 N along three in-plane directions
(where ``planar`` applies). Settings: ``planar`` (embedded queries), ``gws`` (rigid
fixtures only), ``no_mdp``, ``iterative``, ``refinement`` at q = 1..9 (4 initial edges,
``4 * 2^q`` equivalent edges), full resolution ``refine=False`` at k = 8..2048 edges,
``refinement`` (q = 7) stopping once its certified exact value is within ``certify_gap`` =
1e-2, 1e-3, 1e-4 of the relaxation's bound, and ``exact``. The error of one answer is
``|v - v_exact| / v_exact`` (an "unstable" answer counts as 0 N). Each solve is
limited to ``--time-limit`` seconds; a time-out is drawn at the limit and has no error.
Writes ``tradeoff.csv`` (one row per solve) and ``tradeoff.png`` (every solve, and each
setting's median time and error).
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import examples as ex
from ..api import solve
from ..errors import GraspError, MethodError
from ..io import write_csv
from ..queries import MaxDisturbance
from .plots import pyplot, save

CAP = 100.0
FLOOR = 1e-7  # errors below are drawn at this line


def queries() -> list[tuple[str, Any, MaxDisturbance, Any]]:
    """(name, spatial grasp, query, planar (grasp, query) or None)."""
    out: list[tuple[str, Any, MaxDisturbance, Any]] = [
        ("pinch +z", ex.pinch(), MaxDisturbance([0, 0, 1, 0, 0, 0], commands=0.1, cap=CAP),
         None),
        ("tendon +y", ex.tendon_finger(),
         MaxDisturbance([0, 1, 0, 0, 0, 0], commands=ex.TENDON_FORCE, cap=CAP), None),
        ("tendon +z", ex.tendon_finger(),
         MaxDisturbance([0, 0, 1, 0, 0, 0], commands=ex.TENDON_FORCE, cap=CAP), None),
    ]  # fmt: skip
    for d in [(0.0, 1.0, 0.0), (1.0, 1.0, 0.02), (-1.0, 0.5, 0.0)]:
        qe = MaxDisturbance(ex.embed_wrench(d), preload=1.0, cap=CAP)
        qp = MaxDisturbance(d, preload=1.0, cap=CAP)
        out.append((f"three {d}", ex.three_embedded(), qe, (ex.three_planar(), qp)))
    return out


def settings() -> list[tuple[str, str, str, dict[str, Any]]]:
    """(label, family, method, options)."""
    out: list[tuple[str, str, str, dict[str, Any]]] = [
        ("planar", "planar", "planar", {}),
        ("gws", "gws", "gws", {}),
        ("no_mdp", "no_mdp", "no_mdp", {}),
        ("iterative", "iterative", "iterative", {}),
    ]
    out += [(f"refinement q={q}", "refinement", "refinement", {"levels": q})
            for q in range(1, 10)]  # fmt: skip
    out += [(f"full k={4 * 2**q}", "full resolution", "refinement",
             {"levels": q, "refine": False}) for q in range(1, 10)]  # fmt: skip
    out += [(f"certified gap={gap:g}", "refinement, certify_gap", "refinement",
             {"certify_gap": gap}) for gap in (1e-2, 1e-3, 1e-4)]  # fmt: skip
    out.append(("exact", "exact", "exact", {}))
    return out


def bench_tradeoff(time_limit: float = 60.0, only: str | None = None,
                   progress: bool = True) -> list[dict[str, Any]]:  # fmt: skip
    """One row per (query, setting): time, value, status, error against exact."""
    from tqdm import tqdm

    qs = queries()
    if only:
        qs = [q for k, q in enumerate(qs) if str(k) in only]
    st = settings()
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(qs) * len(st), desc="tradeoff", disable=not progress)
    for name, g, q, planar in qs:
        ref = None
        for label, family, method, opts in reversed(st):  # exact first: the reference
            bar.update(1)
            gg, qq = g, q
            if method == "planar":
                if planar is None:
                    continue
                gg, qq = planar
            t0 = time.perf_counter()
            try:
                limit = {} if method in ("planar", "gws") else {"time_limit": time_limit}
                sol = solve(gg, qq, method=method, **limit, **opts)
            except (GraspError, MethodError):
                continue  # the method does not take this grasp (gws: hands)
            t = time.perf_counter() - t0
            value = None
            if sol.status == "solved":
                value = sol.value if sol.stable else 0.0
            if method == "exact":
                ref = value
            err = None
            if value is not None and ref is not None and ref > 0:
                err = abs(value - ref) / ref
            rows.append({"query": name, "setting": label, "family": family, "time_s": t,
                         "status": sol.status, "value": value, "reference": ref,
                         "error": err})  # fmt: skip
    bar.close()
    return rows


def medians(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for label, family, _, _ in settings():
        rs = [r for r in rows if r["setting"] == label]
        if not rs:
            continue
        errs = [r["error"] for r in rs if r["error"] is not None]
        out.append({"setting": label, "family": family, "n": len(rs),
                    "time_s": float(np.median([r["time_s"] for r in rs])),
                    "error": float(np.median(errs)) if errs else math.nan,
                    "max_error": float(max(errs)) if errs else math.nan,
                    "timeouts": sum(r["status"] == "timeout" for r in rs)})  # fmt: skip
    return out


def print_tradeoff(rows: list[dict[str, Any]]) -> None:
    print(f"{'setting':>20} {'n':>2} {'median s':>9} {'median err':>11} {'max err':>9} "
          f"{'time-outs':>9}")  # fmt: skip
    for r in medians(rows):
        print(f"{r['setting']:>20} {r['n']:>2} {r['time_s']:9.3f} {r['error']:11.2e} "
              f"{r['max_error']:9.2e} {r['timeouts']:>9}")  # fmt: skip


COLORS = {"planar": "C2", "gws": "C7", "no_mdp": "C3", "iterative": "C4",
          "refinement": "C0", "full resolution": "C1", "refinement, certify_gap": "C9",
          "exact": "k"}  # fmt: skip


def read_tradeoff(path: Path) -> list[dict[str, Any]]:
    """Rows of a ``tradeoff.csv`` (numbers parsed; empty fields None; the reference's label
    ``spatial``, the alias of ``exact``, read as ``exact``)."""
    rows = []
    with Path(path).open() as fh:
        for r in csv.DictReader(fh):
            for k in ("time_s", "value", "reference", "error"):
                r[k] = None if r[k] == "" else float(r[k])
            for k in ("setting", "family"):
                r[k] = "exact" if r[k] == "spatial" else r[k]
            rows.append(r)
    return rows


def write_tradeoff(rows: list[dict[str, Any]], out: Path) -> tuple[Path, Path]:
    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    path = write_csv(out / "tradeoff.csv", rows)
    fig, ax = plt.subplots(figsize=(10.5, 5.5))
    for r in rows:
        col = COLORS[r["family"]]
        if r["error"] is None:
            if r["status"] == "timeout":
                ax.scatter(r["time_s"], 3.0, marker="x", color=col, s=25, alpha=0.6)
            continue
        ax.scatter(r["time_s"], max(r["error"], FLOOR), color=col, s=12, alpha=0.35)
    med = medians(rows)
    for fam, col in COLORS.items():
        ms = [m for m in med if m["family"] == fam and not math.isnan(m["error"])]
        if not ms:
            continue
        xs = [m["time_s"] for m in ms]
        ys = [max(m["error"], FLOOR) for m in ms]
        ax.plot(xs, ys, "-o" if len(ms) > 1 else "o", color=col, ms=7, label=fam + " (median)")
        if fam in ("refinement", "full resolution"):
            for m, x, y in zip(ms, xs, ys, strict=True):
                ax.annotate(m["setting"].split()[-1], (x, y), fontsize=7, xytext=(3, 3),
                            textcoords="offset points", color=col)  # fmt: skip
    ax.set_xscale("log")
    tr = ax.get_yaxis_transform()
    ax.axhline(FLOOR, color="grey", lw=0.5, ls=":")
    ax.text(0.01, FLOOR * 1.3, f"error <= {FLOOR:g}", fontsize=7, color="grey", transform=tr)
    ax.axhline(3.0, color="grey", lw=0.5, ls=":")
    ax.text(0.01, 3.5, "time-outs (x)", fontsize=7, color="grey", transform=tr)
    ax.set_yscale("log")
    ax.set_xlabel("time per query [s] (log)")
    ax.set_ylabel("relative error of the max disturbance vs exact (log)")
    ax.set_title("speed vs accuracy: 6 queries, every method and setting (dots: single solves)")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    png = save(fig, out / "tradeoff.png", dpi=120)
    return path, png


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench tradeoff``: options ``--time-limit`` (default 60 s),
    ``--only``, ``--out``."""
    rows = bench_tradeoff(args.time_limit or 60.0, only=args.only)
    print_tradeoff(rows)
    csv_path, png = write_tradeoff(rows, Path(args.out))
    print(f"wrote {csv_path} and {png}")
