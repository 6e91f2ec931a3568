"""A pointer: ``python -m shields.bench accuracy|latency|effect`` names the command that runs
the shield benchmarks, ``python -m train.bench shield accuracy|latency|effect``.

The shield benchmarks load the shipped policy, which lives in ``train``, and nothing below
``train`` imports it (the layers of docs/design.md). This stub only prints the ``train.bench``
command (with the same arguments) and exits with status 2; it imports nothing from ``train``.
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Sequence
from typing import NoReturn

__all__ = ["NEW_COMMAND", "main"]

NEW_COMMAND = "python -m train.bench shield"


def main(argv: Sequence[str] | None = None) -> NoReturn:
    """Print the ``train.bench`` command for ``argv`` to stderr and exit with status 2."""
    args = list(sys.argv[1:] if argv is None else argv)
    command = " ".join([NEW_COMMAND, *map(shlex.quote, args)])
    sys.stderr.write(
        f"python -m shields.bench: moved to {NEW_COMMAND} (the benchmarks load a trained "
        f"policy, which lives in train); run:\n  {command}\n"
    )
    raise SystemExit(2)


if __name__ == "__main__":
    main()
