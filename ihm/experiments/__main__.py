"""``python -m ihm.experiments NAME [NAME ...]``: run the thesis' experiments (package doc)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from stability.cli import ArgumentParser

from . import EXPERIMENTS, ExperimentError, run_experiment


def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(
        prog="python -m ihm.experiments",
        description="The thesis' grasp experiments, predicted and simulated in MuJoCo.",
    )
    ap.add_argument("names", nargs="+", metavar="NAME", help=", ".join(sorted(EXPERIMENTS)))
    ap.add_argument("--out", type=Path, default=Path("docs/experiments"))
    ap.add_argument("--quick", action="store_true", help="coarse direction grids (smoke runs)")
    ap.add_argument("--workers", type=int, default=1, help="processes per map (default 1)")
    args = ap.parse_args(argv)
    try:
        for name in args.names:
            summary = run_experiment(name, args.out, quick=args.quick, workers=args.workers)
            print(f"{name}: {json.dumps(summary, default=float)}")
    except ExperimentError as exc:
        print(f"python -m ihm.experiments: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
