"""``python -m stability.batch``: answer a file of stability queries (module doc of
:mod:`stability.batch`); ``python -m stability.batch random OUT``: write random queries;
``python -m stability.batch --bench``: the throughput benchmark."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence

from ..cli import ArgumentParser
from ..errors import GraspError
from .executors import make_executor
from .run import run_batch
from .writers import random_rows, write_rows

PROG = "python -m stability.batch"


def _run_parser() -> ArgumentParser:
    p = ArgumentParser(
        prog=PROG,
        description="Answer every query of a JSON-lines file (stability.batch.rows) and append "
        "one result row per query to OUT as it arrives; rerun with the same OUT to resume. "
        f"Other commands: '{PROG} random OUT' writes random queries, '{PROG} --bench' measures "
        "throughput.",
    )
    p.add_argument("queries", help="query file (JSON lines)")
    p.add_argument("out", help="result file (JSON lines; appended to, resumed from)")
    p.add_argument(
        "--method",
        help="method for rows that name none (default: solve()'s: "
        "planar for planar grasps, modesearch for spatial ones)",
    )
    p.add_argument(
        "--time-limit",
        type=float,
        help="per-query time limit [s] passed to the method (status 'timeout' when it runs out)",
    )
    p.add_argument(
        "--hard-timeout",
        type=float,
        help="wall-clock limit per query [s]; a query "
        "still running is stopped and recorded 'killed' (default: none)",
    )
    p.add_argument(
        "--workers",
        type=int,
        help="local worker processes (default: the number of "
        "cores); with --ray, the CPUs of a new local cluster",
    )
    p.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run on Ray: 'auto' (the running "
        "cluster, else a new local one), 'local' (a new one) or a cluster address",
    )
    p.add_argument(
        "--retries",
        type=int,
        default=2,
        help="re-runs of a query whose worker died before it is recorded 'crashed' (default 2)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _random_parser() -> ArgumentParser:
    p = ArgumentParser(
        prog=f"{PROG} random",
        description="Write N query rows about random grasps (stability.batch.random_rows).",
    )
    p.add_argument("out", help="query file to write (JSON lines)")
    p.add_argument("--n", type=int, default=100, help="number of queries (default 100)")
    p.add_argument("--contacts", type=int, default=4, help="contacts per grasp (default 4)")
    p.add_argument(
        "--planar",
        action="store_true",
        help="planar rigid grasps (else spatial single-joint-finger hands)",
    )
    p.add_argument("--query", default="Existence", choices=("Existence", "MaxDisturbance"))
    p.add_argument("--cap", type=float, default=10.0, help="MaxDisturbance cap (default 10)")
    p.add_argument("--seed", type=int, default=0)
    return p


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--bench"] or argv[:1] == ["bench"]:
        from .bench import main as bench_main

        bench_main(argv[1:])
        return
    if argv[:1] == ["random"]:
        p = _random_parser()
        a = p.parse_args(argv[1:])
        try:
            rows = random_rows(
                a.n, contacts=a.contacts, planar=a.planar, query=a.query, seed=a.seed, cap=a.cap
            )
        except GraspError as e:
            p.error(str(e))
        print(f"{write_rows(a.out, rows)} queries -> {a.out}")
        return
    p = _run_parser()
    a = p.parse_args(argv)
    options = {} if a.time_limit is None else {"time_limit": a.time_limit}
    t0 = time.perf_counter()
    try:
        with make_executor(a.workers, a.ray, retries=a.retries, hard_timeout=a.hard_timeout) as ex:
            counts = run_batch(
                a.queries,
                a.out,
                method=a.method,
                options=options,
                executor=ex,
                progress=not a.no_progress,
            )
    except GraspError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        sys.exit(2)
    dt = time.perf_counter() - t0
    rate = counts["done"] / dt if dt > 0 else 0.0
    print(json.dumps({**counts, "wall_s": round(dt, 2), "queries_per_s": round(rate, 2)}))


if __name__ == "__main__":
    main()
