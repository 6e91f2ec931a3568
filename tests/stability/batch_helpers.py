"""Worker functions for tests/stability/test_batch.py: they must be importable by module name
in the batch's worker processes (tests/stability is on sys.path under pytest)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

from stability.batch import solve_row


def kill_once_then_solve(marker_dir: str, victims: tuple[str, ...], task: Any) -> dict:
    """Kill this worker process (SIGKILL) the first time it runs a query whose id is in
    ``victims``; answer it normally on the next attempt."""
    _, id, *_ = task
    marker = Path(marker_dir) / f"{id}.killed"
    if id in victims and not marker.exists():
        marker.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return solve_row(task)


def always_kill(victims: tuple[str, ...], task: Any) -> dict:
    """Kill the worker on every attempt at a query in ``victims``."""
    if task[1] in victims:
        os.kill(os.getpid(), signal.SIGKILL)
    return solve_row(task)


def sleep_on(victims: tuple[str, ...], seconds: float, task: Any) -> dict:
    """Sleep ``seconds`` before answering a query in ``victims`` (a hung solver)."""
    if task[1] in victims:
        time.sleep(seconds)
    return solve_row(task)


class SlowToStart:
    """A solver whose unpickling in a fresh worker takes ``seconds`` (as heavy imports do on
    a loaded machine); calling it solves the row."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def __setstate__(self, state: dict) -> None:
        time.sleep(state["seconds"])
        self.__dict__.update(state)

    def __call__(self, task: Any) -> dict:
        return solve_row(task)
