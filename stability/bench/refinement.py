"""``python -m stability.bench refinement``: the thesis' table "Performance of the analysis"
(tab:data) on one 4-contact grasp.

For equivalent edge counts ``4 * 2^q`` (``q = 0 .. --max-levels``) the largest force along
``-y`` the grasp resists (commands 0.1 N m per finger), solved at full resolution (one MIP
with ``4 * 2^q`` uniform edges per contact, ``refine=False``) and by hierarchical
refinement (``refine=True``), without and with robustness to 2.5 deg of contact-normal
error. Each solve gets ``--time-limit`` seconds; a full-resolution column stops after its
first time-out (the thesis' "-"). The grasp: :func:`stability.examples.random_fingers`
with 4 contacts and seed 2 (four single-joint fingers, contacts not coplanar; the thesis'
flask is a GraspIt! grasp we do not have). The thesis' numbers (Gurobi, a desktop) are
printed beside ours for the shape, not for the values: different grasp.

Writes ``refinement.csv`` and ``refinement.png`` (time vs equivalent edges, log-log).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import examples as ex
from ..api import solve
from ..io import write_csv
from ..queries import MaxDisturbance
from .plots import pyplot, save

# thesis tab:data: edges -> (max wrench, t_full, t_hier, robust max wrench, t_full, t_hier)
THESIS = {
    4: (">100", 0.088, 0.088, ">100", 0.11, 0.11),
    8: (7.07435, 0.22, 0.43, 7.07435, 0.24, 0.46),
    16: (6.34905, 0.43, 0.65, 3.73377, 0.45, 1.02),
    32: (3.71036, 0.72, 1.92, 3.70539, 0.97, 1.33),
    64: (3.70095, 1.58, 2.33, 2.31479, 1.83, 3.09),
    128: (3.69775, 5.80, 3.50, 1.21805, 5.12, 10.9),
    256: (3.69751, ">600", 4.87, 1.21756, 20.3, 13.0),
    512: (3.69681, "-", 4.34, 1.21743, 102, 17.8),
    1024: (3.07268, "-", 13.3, 1.21740, 394, 22.9),
    2048: (3.07267, "-", 15.0, 1.21739, "-", 32.2),
}
ETA = math.radians(2.5)
SEED = 2
CAP = 100.0


def grasp_and_query() -> tuple[Any, MaxDisturbance]:
    g = ex.random_fingers(np.random.default_rng(SEED), 4)
    return g, MaxDisturbance([0, -1, 0, 0, 0, 0], commands=[0.1] * 4, cap=CAP)


def _one(g, q, levels: int, refine: bool, eta: float, time_limit: float) -> dict[str, Any]:
    t0 = time.perf_counter()
    sol = solve(g, q, method="refinement", levels=levels, refine=refine,
                normal_uncertainty=eta, time_limit=time_limit)  # fmt: skip
    t = time.perf_counter() - t0
    if sol.status == "not_converged" and "relaxed_value" in sol.stats:
        # no exact point with this level's modes (a coarse level, typically): the table is
        # the relaxation's value per level, as the thesis' is
        return {"value": sol.stats["relaxed_value"], "time_s": round(t, 3),
                "rounds": sol.stats.get("mip_rounds")}  # fmt: skip
    if sol.status != "solved":
        return {"value": sol.status, "time_s": round(t, 3)}
    v = sol.value if sol.stable else 0.0
    if sol.stats.get("capped"):
        v = f">={CAP:g}"
    return {"value": v, "time_s": round(t, 3), "rounds": sol.stats.get("mip_rounds")}


def bench_refinement(max_levels: int = 9, time_limit: float = 120.0) -> list[dict[str, Any]]:
    g, query = grasp_and_query()
    rows: list[dict[str, Any]] = []
    full_dead = {0.0: False, ETA: False}
    for levels in range(max_levels + 1):
        edges = 4 * 2**levels
        row: dict[str, Any] = {"equivalent_edges": edges}
        for eta, tag in ((0.0, ""), (ETA, "robust_")):
            h = _one(g, query, levels, True, eta, time_limit)
            row[f"{tag}value"] = h["value"]
            row[f"{tag}hier_s"] = h["time_s"]
            row[f"{tag}hier_rounds"] = h.get("rounds")
            if full_dead[eta]:
                row[f"{tag}full_s"], row[f"{tag}full_value"] = "-", "-"
            else:
                f = _one(g, query, levels, False, eta, time_limit)
                row[f"{tag}full_s"] = f["time_s"]
                row[f"{tag}full_value"] = f["value"]
                full_dead[eta] = f["value"] == "timeout"
        th = THESIS.get(edges, ("",) * 6)
        row.update(thesis_value=th[0], thesis_full_s=th[1], thesis_hier_s=th[2],
                   thesis_robust_value=th[3], thesis_robust_full_s=th[4],
                   thesis_robust_hier_s=th[5])  # fmt: skip
        rows.append(row)
        _print_row(row)
    return rows


def _fmt(v: Any) -> str:
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def _print_row(r: dict[str, Any]) -> None:
    print(
        f"{r['equivalent_edges']:>5} | ours: {_fmt(r['value']):>9} full {_fmt(r['full_s']):>8} s "
        f"hier {_fmt(r['hier_s']):>7} s | robust {_fmt(r['robust_value']):>9} full "
        f"{_fmt(r['robust_full_s']):>8} s hier {_fmt(r['robust_hier_s']):>7} s || thesis: "
        f"{_fmt(r['thesis_value'])} {_fmt(r['thesis_full_s'])} {_fmt(r['thesis_hier_s'])} | "
        f"{_fmt(r['thesis_robust_value'])} {_fmt(r['thesis_robust_full_s'])} "
        f"{_fmt(r['thesis_robust_hier_s'])}",
        flush=True,
    )


def write_refinement(rows: list[dict[str, Any]], out: Path) -> tuple[Path, Path]:
    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    csv_path = write_csv(out / "refinement.csv", rows)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    e = [r["equivalent_edges"] for r in rows]
    for key, label, style in (("full_s", "full resolution", "C0--o"),
                              ("hier_s", "hierarchical", "C0-o"),
                              ("robust_full_s", "full, 2.5 deg robust", "C3--s"),
                              ("robust_hier_s", "hierarchical, robust", "C3-s")):  # fmt: skip
        pts = [(x, r[key]) for x, r in zip(e, rows, strict=True) if isinstance(r[key], float)]
        if pts:
            ax.plot(*zip(*pts, strict=True), style, label=label)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("equivalent friction edges per contact")
    ax.set_ylabel("time per MaxDisturbance query [s]")
    ax.set_title("Refinement vs full resolution (4 contacts, this 2-core machine)")
    ax.legend()
    ax.grid(alpha=0.3)
    png = save(fig, out / "refinement.png", dpi=110)
    return csv_path, png


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench refinement``: options ``--max-levels``, ``--time-limit``
    (default 120 s), ``--out``."""
    rows = bench_refinement(args.max_levels, args.time_limit or 120.0)
    csv_path, png = write_refinement(rows, Path(args.out))
    print(f"wrote {csv_path} and {png}")
