"""``python -m train.bench training|fidelity|transfer|shield MEASURE``: parses the command line
and runs the benchmark (the modules of :mod:`train.bench`; ``MEASURE``: accuracy, latency,
effect or models)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from stability.cli import ArgumentParser
from train.bench import (
    fidelity,
    shield_accuracy,
    shield_common,
    shield_effect,
    shield_latency,
    shield_models,
    training,
    transfer,
)

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per benchmark, ``shield`` with its three."""
    p = ArgumentParser(
        prog="python -m train.bench",
        description=(sys.modules["train.bench"].__doc__ or "").split("\n\n")[0],
    )
    sub = p.add_subparsers(dest="bench", required=True, metavar="BENCHMARK")
    for module in (training, fidelity, transfer):
        module.add_parser(sub)
    shield = sub.add_parser(
        "shield",
        help="the grasp shields: accuracy, latency, effect, models",
        description="Measurements of the QP grasp shield (train.bench.shield_common): accuracy "
        "(its linearisation against MuJoCo), latency (its wall time per step), effect "
        "(episodes with and without it); models: its criteria judged by the QP and by the "
        "lookahead shield (train.bench.shield_models).",
    )
    measures = shield.add_subparsers(dest="measure", required=True, metavar="MEASURE")
    common = shield_common.common_options()
    for module in (shield_accuracy, shield_latency, shield_effect, shield_models):
        module.add_parser(measures, common)
    return p


def main(argv: Sequence[str] | None = None) -> Any:
    """Parse ``argv`` and run the chosen benchmark; returns its rows (or summary rows)."""
    args = build_parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    main()
