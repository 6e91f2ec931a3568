"""Command-line helpers shared by every package's CLIs (the lowest layer, so all can import it).

:class:`ArgumentParser` is :class:`argparse.ArgumentParser` with a short error: a bad option
prints one line naming the problem and one pointing to ``--help``, not the whole usage block::

    python -m train.ppo: error: argument --shield: invalid choice: 'magic' (choose from ...)
    try 'python -m train.ppo --help'

and exits with status 2, as argparse does. Subparsers made with ``add_subparsers`` are of the
same class (argparse's default), so subcommands behave alike.
"""

from __future__ import annotations

import argparse
from typing import NoReturn

__all__ = ["ArgumentParser"]


class ArgumentParser(argparse.ArgumentParser):
    """An ``argparse.ArgumentParser`` whose errors are one line plus a ``--help`` hint."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` and ``try 'prog --help'`` to stderr; exit 2."""
        self.exit(2, f"{self.prog}: error: {message}\ntry '{self.prog} --help'\n")
