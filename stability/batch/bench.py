"""``python -m stability.batch --bench``: batch throughput on this machine.

For a ``planar`` batch (rigid planar grasps, 4 contacts, Existence) and a ``refinement``
batch (spatial single-joint-finger hands, 4 contacts, Existence): queries per second in this
process (a plain loop over :func:`stability.solve`, the reference), with 1 and 2 local
worker processes, and with Ray on a local cluster of 2 CPUs; median of ``--repeats`` runs,
each with a fresh result file. Ray's own cost: the start of a local cluster, and the
overhead of each executor: ``--noop`` and twice as many tasks that do nothing give the cost
per task (the difference over the extra tasks) and the fixed cost of a run (process
starts). Writes ``OUT/batch_bench.csv``, ``OUT/batch_overhead.csv`` and
``OUT/batch_bench.png``, and an estimate of the cores needed to label 1M grasps in a day from
the measured cost per query.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..io import write_csv
from .executors import LocalExecutor, RayExecutor
from .rows import decode_row
from .run import run_batch
from .writers import random_rows, write_rows

__all__ = ["main", "noop"]


def noop(task: Any) -> Any:
    """A task that does nothing: its wall time is the executor's overhead."""
    return task


def _batches(n_planar: int, n_ref: int) -> dict[str, list[dict[str, Any]]]:
    return {
        "planar": random_rows(n_planar, contacts=4, planar=True, seed=100),
        "refinement": random_rows(n_ref, contacts=4, seed=101, options={"time_limit": 60.0}),
    }


def _in_process(rows: list[dict[str, Any]]) -> tuple[float, list[float]]:
    from ..api import solve

    t0 = time.perf_counter()
    times = []
    for k, r in enumerate(rows):
        g, q, m, o = decode_row(k + 1, r)
        times.append(solve(g, q, method=m, **o).stats["time_s"])
    return time.perf_counter() - t0, times


def _timed(q: Path, tmp: Path, make: Any) -> float:
    out = tmp / f"r{time.perf_counter_ns()}.jsonl"
    with make() as ex:
        t0 = time.perf_counter()
        run_batch(q, out, executor=ex, progress=False)
        return time.perf_counter() - t0


def main(argv: Sequence[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m stability.batch --bench", description=__doc__)
    p.add_argument("--out", type=Path, default=Path("docs/bench/batch"))
    p.add_argument("--planar", type=int, default=400, help="queries in the planar batch")
    p.add_argument("--refinement", type=int, default=40, help="queries in the refinement batch")
    p.add_argument("--noop", type=int, default=400, help="no-op tasks for the overhead")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    import ray

    rows_out, over = [], []
    per_query: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        t0 = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        ray_start = time.perf_counter() - t0
        try:
            execs = {
                "local, 1 worker": lambda: LocalExecutor(1),
                "local, 2 workers": lambda: LocalExecutor(2),
                "ray, 2 CPUs": lambda: RayExecutor(),
            }
            for name, rows in _batches(a.planar, a.refinement).items():
                q = tmp / f"{name}.jsonl"
                write_rows(q, rows)
                ref = [_in_process(rows) for _ in range(a.repeats)]
                ref_wall = statistics.median(w for w, _ in ref)
                per_query[name] = statistics.median(ref[0][1])
                rows_out.append(
                    dict(
                        batch=name,
                        executor="in process (reference)",
                        queries=len(rows),
                        wall_s=ref_wall,
                        queries_per_s=len(rows) / ref_wall,
                        speedup=1.0,
                    )
                )
                for ex_name, make in execs.items():
                    walls = [_timed(q, tmp, make) for _ in range(a.repeats)]
                    w = statistics.median(walls)
                    rows_out.append(
                        dict(
                            batch=name,
                            executor=ex_name,
                            queries=len(rows),
                            wall_s=w,
                            queries_per_s=len(rows) / w,
                            speedup=ref_wall / w,
                        )
                    )
                    print(json.dumps(rows_out[-1]))
            for ex_name, make in execs.items():  # N and 2N no-op tasks: fixed + per task
                walls = {}
                for n in (a.noop, 2 * a.noop):
                    ws = []
                    for _ in range(a.repeats):
                        with make() as ex:
                            t = time.perf_counter()
                            got = sum(1 for _ in ex.run(noop, ((k, k) for k in range(n))))
                            ws.append(time.perf_counter() - t)
                        assert got == n
                    walls[n] = statistics.median(ws)
                per = (walls[2 * a.noop] - walls[a.noop]) / a.noop
                over.append(
                    dict(
                        executor=ex_name,
                        tasks=a.noop,
                        wall_s=walls[a.noop],
                        ms_per_task=1e3 * per,
                        fixed_s=walls[a.noop] - a.noop * per,
                    )
                )
                print(json.dumps(over[-1]))
        finally:
            ray.shutdown()
    over.append(
        dict(
            executor="ray, 2 CPUs: start of a local cluster",
            tasks=0,
            wall_s=ray_start,
            ms_per_task=float("nan"),
            fixed_s=ray_start,
        )
    )
    a.out.mkdir(parents=True, exist_ok=True)
    write_csv(a.out / "batch_bench.csv", rows_out)
    write_csv(a.out / "batch_overhead.csv", over)
    _chart(a.out / "batch_bench.png", rows_out)
    for name, t in per_query.items():
        cores = 1e6 * t / 86400.0
        print(
            f"{name}: median {t * 1e3:.1f} ms per query in one process -> 1M queries in a day "
            f"need about {cores:.2g} cores at full use (an estimate: no overhead, "
            "same query mix)"
        )
    print(f"wrote {a.out}/batch_bench.csv, batch_overhead.csv, batch_bench.png")


def _chart(path: Path, rows: list[dict[str, Any]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    batches = list(dict.fromkeys(r["batch"] for r in rows))
    fig, axes = plt.subplots(1, len(batches), figsize=(5 * len(batches), 3.6))
    for ax, b in zip(axes, batches, strict=True):
        rs = [r for r in rows if r["batch"] == b]
        ax.barh([r["executor"] for r in rs], [r["queries_per_s"] for r in rs], color="C0")
        for k, r in enumerate(rs):
            ax.text(r["queries_per_s"], k, f" {r['queries_per_s']:.1f}", va="center", fontsize=8)
        ax.set_xlabel("queries per second (median)")
        ax.set_title(f"{b} batch, {rs[0]['queries']} queries", fontsize=10)
        ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
