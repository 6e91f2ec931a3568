"""``python -m stability.bench planar|mip|refinement|grasps|tradeoff [options]``: parses the
command line and runs one benchmark (``cli(args)`` of the module of that name)."""

from __future__ import annotations

import argparse
import importlib

from stability.cli import ArgumentParser

BENCHMARKS = ("planar", "mip", "refinement", "grasps", "tradeoff", "hands", "nodelp")


def parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(
        prog="python -m stability.bench",
        description=importlib.import_module("stability.bench").__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("which", choices=BENCHMARKS, help="benchmark to run")
    ap.add_argument("--max-levels", type=int, default=9,
                    help="refinement: largest q (4 * 2^q equivalent edges)")  # fmt: skip
    ap.add_argument("--time-limit", type=float, default=None,
                    help="seconds per query (default: refinement 120, grasps, hands and "
                    "tradeoff 60)")  # fmt: skip
    ap.add_argument("--directions", type=int, default=10,
                    help="grasps: max-disturbance directions per grasp")  # fmt: skip
    ap.add_argument("--wrenches", type=int, default=10,
                    help="grasps: optimal-commands wrenches per grasp")  # fmt: skip
    ap.add_argument("--only", default=None,
                    help="grasps: labels to run (e.g. 'abe'); tradeoff: query indices")  # fmt: skip
    ap.add_argument("--out", default="bench_out", help="folder for the CSV and PNG")
    ap.add_argument("--repeats", type=int, default=None,
                    help="repeats per point (default: planar 15, mip 7)")  # fmt: skip
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", default=None,
                    help="grasps: also run this git revision's code (a worktree), side by "
                    "side")  # fmt: skip
    ap.add_argument("--backends", default=None,
                    help="grasps: more MIP backends for refinement, comma-separated "
                    "(e.g. gurobi)")  # fmt: skip
    ap.add_argument("--levels", type=int, default=None,
                    help="grasps: refinement's levels q for this run's variants (default 9: "
                    "2048 equivalent edges)")  # fmt: skip
    ap.add_argument("--merge", nargs="+", default=None, metavar="CSV",
                    help="grasps, hands: no run; summarise and chart the rows of these "
                    "earlier runs' CSV files together (time-outs at --time-limit)")  # fmt: skip
    ap.add_argument("--queries", default=None, metavar="LIST",
                    help="grasps: run only these queries, comma-separated "
                    "grasp:task:index (e.g. 'h:max_disturbance:9'; index from 0 within "
                    "the task); with --merge, a later file's row replaces an earlier "
                    "one's")  # fmt: skip
    ap.add_argument("--methods", default=None,
                    help="grasps, hands: methods to run, comma-separated, one variant each "
                    "(default grasps modesearch,refinement; hands modesearch,refinement,exact; "
                    "refinement with SCIP)")  # fmt: skip
    ap.add_argument("--n", type=int, default=25, help="hands: random grasps per contact count")
    ap.add_argument("--contacts", default=None, help="hands: contact counts (default 3,4,5,6)")
    ap.add_argument("--exact-contacts", default=None,
                    help="hands: contact counts exact runs on (default 3,4)")  # fmt: skip
    ap.add_argument("--refinement-contacts", default=None,
                    help="hands: contact counts refinement runs on (default all)")  # fmt: skip
    ap.add_argument(
        "--skip-default",
        action="store_true",
        help="grasps: run only --backends (and --baseline), not refinement on its default backend",
    )
    return ap


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)
    importlib.import_module(f"stability.bench.{args.which}").cli(args)


if __name__ == "__main__":
    main()
