"""Run a batch file: read query rows, answer those not answered yet, append result rows."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..api import RENAMED_METHODS, available_methods, solve
from .executors import BatchError, Executor, LocalExecutor
from .rows import RowError, decode_row, failed_row, read_rows, result_row

__all__ = ["UNTIMED", "answered", "run_batch", "solve_row"]

UNTIMED = ("planar", "gws")
"""Methods that take no ``time_limit`` (polynomial time, they always finish): the batch's
default limit (``--time-limit``) is not passed to them."""


def solve_row(task: tuple[int, str, Any, str | None, dict[str, Any]]) -> dict[str, Any]:
    """The result row of one query row: ``task = (row, id, parsed row, default method,
    default options)``; the row's own ``method``/``options`` take precedence. A query that the
    method refuses or that fails inside it becomes a row with status ``error``."""
    row, id, data, method, options = task
    grasp, query, own_method, own_options = decode_row(row, data)
    method = own_method or method
    opts = {**options, **own_options}
    if (method or ("planar" if grasp.planar else "")) in UNTIMED and "time_limit" in options:
        del opts["time_limit"]  # the batch's default limit; a row's own one is passed on
    try:
        sol = solve(grasp, query, method=method, **opts)
    except Exception as e:  # noqa: BLE001  (one query's failure is recorded, the batch goes on)
        return failed_row(row, id, "error", f"{type(e).__name__}: {e}", method)
    return result_row(row, id, sol)


def answered(out: str | Path) -> set[str]:
    """Ids of the result rows already in ``out`` (none when it does not exist). A last line
    cut short by a kill is removed from the file, so that its query runs again."""
    path = Path(out)
    if not path.exists():
        return set()
    ids: set[str] = set()
    good = 0  # byte offset after the last complete row
    with open(path, "rb") as f:
        for line in f:
            try:
                ids.add(str(json.loads(line)["id"]))
            except (ValueError, KeyError, TypeError):
                if line.endswith(b"\n"):
                    raise BatchError(f"{path}: a line at byte {good} is not a result row") from None
                break  # a row cut short at the end: written again below
            good += len(line)
    if good < path.stat().st_size:
        with open(path, "r+b") as f:
            f.truncate(good)
    return ids


def run_batch(
    queries: str | Path,
    out: str | Path,
    *,
    method: str | None = None,
    options: dict[str, Any] | None = None,
    executor: Executor | None = None,
    progress: bool = True,
    solver: Any = solve_row,
) -> dict[str, int]:
    """Answer every query row of ``queries`` (JSON lines, :mod:`stability.batch.rows`) that
    ``out`` does not hold yet and append its result row to ``out`` as it arrives.

    ``method``/``options``: for rows that name none (``options`` such as ``time_limit`` [s]
    go to :func:`stability.solve`). ``executor``: where the queries run (default
    :class:`LocalExecutor` on every core). Rows that cannot be read are written with status
    ``invalid`` and reported on stderr with their row numbers; a duplicate id is invalid.
    ``solver``: the function each worker applies to a task (tests swap it).

    Returns counts: ``total`` rows, ``skipped`` (already in ``out``), ``done`` (answered
    now), ``invalid``, and one count per status."""
    queries, out = Path(queries), Path(out)
    if method is not None and method not in available_methods() + list(RENAMED_METHODS):
        raise BatchError(f"unknown method {method!r}; registered: {available_methods()}")
    if not queries.is_file():
        raise BatchError(f"no query file {queries}")
    if out.resolve() == queries.resolve():
        raise BatchError("the result file must not be the query file")
    have = answered(out)
    seen: set[str] = set()
    todo: dict[int, str] = {}  # row -> id
    counts: dict[str, int] = {"total": 0, "skipped": 0, "done": 0}
    bad: list[dict[str, Any]] = []
    for row, id, data in read_rows(queries):  # first pass: ids, bad rows, work left
        counts["total"] += 1
        if id in have:
            counts["skipped"] += 1
            continue
        if id in seen:
            bad.append(failed_row(row, id, "invalid", f"row {row}: duplicate id {id!r}"))
            continue
        seen.add(id)
        try:
            if isinstance(data, RowError):
                raise data
            decode_row(row, data)
        except RowError as e:
            bad.append(failed_row(row, id, "invalid", str(e)))
            continue
        todo[row] = id

    def tasks() -> Iterator[tuple[int, Any]]:  # second pass: stream the rows to run
        for row, id, data in read_rows(queries):
            if row in todo:
                yield row, (row, id, data, method, dict(options or {}))

    ex = executor or LocalExecutor()
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=f"{queries.name} ({ex.name})", unit="query")
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "a", encoding="utf-8") as f:

        def write(r: dict[str, Any]) -> None:
            f.write(json.dumps(r) + "\n")
            f.flush()
            counts[r["status"]] = counts.get(r["status"], 0) + 1

        for r in bad:
            print(f"{queries}: {r['message']} (skipped)", file=sys.stderr)
            write(r)
        counts["invalid"] = len(bad)
        try:
            for row, outcome in ex.run(solver, tasks()):
                if outcome.status == "ok":
                    write(outcome.value)
                else:
                    msg = outcome.message or ""
                    write(failed_row(row, todo[row], outcome.status, msg, method))
                counts["done"] += 1
                if bar is not None:
                    bar.update()
        finally:
            if bar is not None:
                bar.close()
            if executor is None:
                ex.close()
    return counts
