"""``python -m stability.bench mip``: the 3D MIP methods per backend.

For each case, method (``no_mdp``, ``iterative``) and backend (``highs``, ``scip``) it
times ``Existence`` and ``MaxDisturbance`` queries and reports medians over repeats (all in
one run, on one machine), the answers, and whether the two backends agree:

* ``pinch``: the analytic pinch (:func:`stability.examples.pinch`), commands 0.1 N m per
  finger, a 1 N lift (stable) and the largest lift (2.22 N);
* ``wedge``: the rigid wedge, 1 N along the walls (``no_mdp`` wrongly says stable) and the
  largest such force (cap 20 N);
* ``random m``: ``m`` = 3..6 contacts on single-joint fingers
  (:func:`stability.examples.random_fingers`), random commands in [0.02, 0.1] N m, a random
  wrench (forces ~N(0, 1) N, torques ~N(0, 0.05) N m) and a random direction (cap 20); a
  fresh grasp per repeat, the same grasps for every method and backend.

The thesis reports no times for these formulations (its ch. 5 experiments give answers
only, and ch. 6's tables time the refinement), so there is no thesis column here.

Writes ``mip.csv`` (one row per case, query, method, backend) and ``mip.png`` (median
times, log scale).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import examples as ex
from ..api import solve
from ..io import write_csv
from ..queries import Existence, MaxDisturbance
from .plots import pyplot, save

METHODS = ("no_mdp", "iterative")
BACKENDS = ("highs", "scip")


def _cases(rng: np.random.Generator, repeats: int) -> list[tuple[str, list[tuple[Any, Any, Any]]]]:
    """``(case, [(grasp, existence_query, max_disturbance_query) per repeat])``."""
    cmd = [ex.PINCH_TORQUE] * 2
    pinch = (ex.pinch(), Existence((0, 0, 1, 0, 0, 0), commands=cmd),
             MaxDisturbance((0, 0, 1, 0, 0, 0), commands=cmd, cap=20.0))  # fmt: skip
    wedge = (ex.wedge(), Existence(ex.WEDGE_FORCE_DIR),
             MaxDisturbance(ex.WEDGE_FORCE_DIR, cap=20.0))  # fmt: skip
    out = [("pinch", [pinch] * repeats), ("wedge", [wedge] * repeats)]
    for m in (3, 4, 5, 6):
        reps = []
        for _ in range(repeats):
            g = ex.random_fingers(rng, m)
            c = rng.uniform(0.02, 0.1, m)
            w, d = ex.random_wrench(rng), ex.random_wrench(rng)
            reps.append((g, Existence(w, commands=c), MaxDisturbance(d, commands=c, cap=20.0)))
        out.append((f"random {m}", reps))
    return out


def bench_mip(repeats: int = 7, seed: int = 0) -> list[dict[str, Any]]:
    """One row per (case, query, method, backend); see the module docstring."""
    from tqdm import tqdm

    rng = np.random.default_rng(seed)
    cases = _cases(rng, repeats)
    rows = []
    total = len(cases) * 2 * len(METHODS) * len(BACKENDS)
    bar = tqdm(total=total, desc="mip bench", unit="config")
    for case, reps in cases:
        for qi, qname in ((1, "existence"), (2, "max_disturbance")):
            for method in METHODS:
                answers: dict[str, list] = {}
                for backend in BACKENDS:
                    times, ans, mips, statuses = [], [], [], []
                    for rep in reps:
                        g, q = rep[0], rep[qi]
                        t0 = time.perf_counter()
                        sol = solve(g, q, method=method, backend=backend)
                        times.append(time.perf_counter() - t0)
                        statuses.append(sol.status)
                        mips.append(sol.stats.get("mips", 0))
                        ans.append(sol.stable if qi == 1 else sol.value)
                    answers[backend] = ans
                    rows.append({
                        "case": case, "query": qname, "method": method, "backend": backend,
                        "median_s": float(np.median(times)), "min_s": float(np.min(times)),
                        "max_s": float(np.max(times)), "repeats": len(reps),
                        "median_mips": float(np.median(mips)),
                        "solved": sum(s == "solved" for s in statuses),
                        "answer": _summary(ans, qi),
                    })  # fmt: skip
                    bar.update()
                agree = _agree(answers["highs"], answers["scip"], qi)
                for r in rows[-len(BACKENDS) :]:
                    r["backends_agree"] = agree
    bar.close()
    return rows


def _summary(ans: list, qi: int) -> str:
    if qi == 1:
        return f"{sum(bool(a) for a in ans)}/{len(ans)} stable"
    vals = [a for a in ans if a is not None]
    return f"median {np.median(vals):.4g}" if vals else "none stable"


def _agree(a: list, b: list, qi: int) -> str:
    if qi == 1:
        return f"{sum(x == y for x, y in zip(a, b, strict=True))}/{len(a)}"
    ok = sum(
        (x is None and y is None)
        or (x is not None and y is not None and abs(x - y) <= 2e-3 * max(1.0, abs(x)))
        for x, y in zip(a, b, strict=True)
    )
    return f"{ok}/{len(a)}"


def print_mip_table(rows: list[dict[str, Any]]) -> None:
    hdr = (f"{'case':<9} {'query':<15} {'method':<9} {'highs ms':>9} {'scip ms':>9} "
           f"{'scip/highs':>10} {'MIPs':>5} {'agree':>6}  answer")  # fmt: skip
    print(hdr)
    print("-" * len(hdr))
    for i in range(0, len(rows), 2):
        h, s = rows[i], rows[i + 1]
        print(
            f"{h['case']:<9} {h['query']:<15} {h['method']:<9} {h['median_s'] * 1e3:>9.1f} "
            f"{s['median_s'] * 1e3:>9.1f} {s['median_s'] / h['median_s']:>10.2f} "
            f"{h['median_mips']:>5.0f} {h['backends_agree']:>6}  {h['answer']}"
        )


def write_mip(rows: list[dict[str, Any]], out: Path) -> tuple[Path, Path]:
    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    csv_path = write_csv(out / "mip.csv", rows)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    cases = list(dict.fromkeys(r["case"] for r in rows))
    x = np.arange(len(cases))
    width = 0.2
    for ax, qname in zip(axes, ("existence", "max_disturbance"), strict=True):
        k = 0
        for method in METHODS:
            for backend in BACKENDS:
                ys = [next(r["median_s"] for r in rows if r["case"] == c and r["query"] == qname
                           and r["method"] == method and r["backend"] == backend)
                      for c in cases]  # fmt: skip
                ax.bar(x + (k - 1.5) * width, ys, width, label=f"{method} / {backend}")
                k += 1
        ax.set_yscale("log")
        ax.set_xticks(x, cases, rotation=20)
        ax.set_title(f"{qname.replace('_', ' ').capitalize()}: median time per query")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].set_ylabel("median time [s]")
    axes[1].legend(fontsize=8)
    png = save(fig, out / "mip.png", dpi=120)
    return csv_path, png


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench mip``: options ``--repeats`` (default 7), ``--seed``,
    ``--out``."""
    rows = bench_mip(args.repeats or 7, args.seed)
    print_mip_table(rows)
    csv_path, png = write_mip(rows, Path(args.out))
    print(f"wrote {csv_path} and {png}")
