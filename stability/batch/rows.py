"""The batch file format: one JSON object per line (JSON lines), queries in, results out.

A **query row** (the input file; ``id`` optional, ``method`` and ``options`` optional)::

    {"id": "box-07",
     "grasp": {"points": [[x, y, z], ...], "normals": [[...], ...], "mu": 0.5,
               "tangents": null, "J": null, "R": null, "backdrivable": null},
     "query": {"type": "MaxDisturbance", "direction": [0, 0, -1, 0, 0, 0], "cap": 10,
               "base": null, "preload": null, "commands": [1.0, 1.0]},
     "method": "refinement", "options": {"time_limit": 30}}

``grasp`` holds :class:`stability.Grasp`'s arguments (the object frame, normals into the
object, SI units; planar grasps have 2 columns), ``query`` one of ``Existence`` (``wrench``),
``MaxDisturbance`` (``direction``, ``cap``, ``base``) or ``OptimalCommands`` (``wrench``,
``lower``, ``upper``, ``weights``, ``objective``, ``max_normal_force``) with the fields of
:mod:`stability.queries`. A missing or null field takes the dataclass' default.

A **result row** (the output file), one per query, written as it arrives::

    {"row": 3, "id": "box-07", "method": "refinement", "backend": "scip",
     "status": "solved", "stable": true, "value": 2.41, "lower": 2.41, "upper": 2.43,
     "certified": true, "capped": false, "commands": null, "time_s": 1.92,
     "message": null}

``row`` is the query's line number in the input (1-based); ``id`` its ``id``, or the row
number as a string when it has none (ids must be unique: resuming matches them). ``status``
is the :class:`stability.Solution`'s (``solved``, ``timeout``, ``not_converged``, ``error``)
or the batch's own: ``invalid`` (the row could not be read; ``message`` says why),
``crashed`` (its worker died on every attempt), ``killed`` (it ran past the hard time limit and
its worker was stopped). ``stable``, ``value``, ``lower``, ``upper``, ``commands`` are the
solution's; ``certified`` and ``capped`` its ``stats`` flags. Floats are written with
Python's shortest round-trip repr, so a value read back is the value computed, bit for bit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GraspError
from ..grasp import Grasp
from ..queries import Existence, MaxDisturbance, OptimalCommands, Query
from ..solution import Solution

__all__ = [
    "QUERY_TYPES",
    "RESULT_FIELDS",
    "RowError",
    "decode_row",
    "encode_query",
    "failed_row",
    "read_rows",
    "result_row",
    "row_id",
]

QUERY_TYPES: dict[str, type] = {
    "Existence": Existence,
    "MaxDisturbance": MaxDisturbance,
    "OptimalCommands": OptimalCommands,
}
_GRASP_FIELDS = ("points", "normals", "mu", "tangents", "J", "R", "backdrivable")
_QUERY_FIELDS = {
    "Existence": ("wrench", "preload", "commands"),
    "MaxDisturbance": ("direction", "preload", "commands", "cap", "base"),
    "OptimalCommands": (
        "wrench",
        "preload",
        "lower",
        "upper",
        "weights",
        "objective",
        "max_normal_force",
    ),
}
RESULT_FIELDS = (
    "row",
    "id",
    "method",
    "backend",
    "status",
    "stable",
    "value",
    "lower",
    "upper",
    "certified",
    "capped",
    "commands",
    "time_s",
    "message",
)


class RowError(GraspError):
    """A query row that cannot be read; ``row`` is its 1-based line number."""

    def __init__(self, row: int, message: str) -> None:
        super().__init__(f"row {row}: {message}")
        self.row, self.reason = row, message


def _plain(v: Any) -> Any:
    """numpy arrays and scalars as lists and Python numbers (for json)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    return v


def encode_query(
    grasp: Grasp,
    query: Query,
    *,
    id: str | None = None,
    method: str | None = None,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The query row of ``query`` about ``grasp`` (module doc); ``json.dumps`` it per line."""
    g: dict[str, Any] = {"points": grasp.points, "normals": grasp.normals, "mu": grasp.mu}
    if not grasp.planar:
        g["tangents"] = grasp.tangents
    if grasp.J is not None:
        g["J"] = grasp.J
    if grasp.R is not None:
        g["R"] = grasp.R
    if grasp.backdrivable is not None and grasp.backdrivable.any():
        g["backdrivable"] = grasp.backdrivable
    name = type(query).__name__
    q: dict[str, Any] = {"type": name}
    for f in _QUERY_FIELDS[name]:
        v = getattr(query, f)
        if v is not None:
            q[f] = v
    row: dict[str, Any] = {}
    if id is not None:
        row["id"] = str(id)
    row["grasp"] = {k: _plain(v) for k, v in g.items()}
    row["query"] = {k: _plain(v) for k, v in q.items()}
    if method is not None:
        row["method"] = method
    if options:
        row["options"] = dict(options)
    return row


def decode_row(row: int, data: Any) -> tuple[Grasp, Query, str | None, dict[str, Any]]:
    """``(grasp, query, method, options)`` of a parsed query row; :class:`RowError` naming the
    row and what is wrong (unknown query type or field, a bad grasp: NaN, shapes, ...)."""
    if not isinstance(data, dict):
        raise RowError(row, f"a query row is a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - {"id", "grasp", "query", "method", "options"})
    if unknown:
        raise RowError(row, f"unknown key(s) {unknown}")
    g, q = data.get("grasp"), data.get("query")
    if not isinstance(g, dict) or not isinstance(q, dict):
        raise RowError(row, "needs a 'grasp' object and a 'query' object")
    bad = sorted(set(g) - set(_GRASP_FIELDS))
    if bad:
        raise RowError(row, f"unknown grasp field(s) {bad}; known: {list(_GRASP_FIELDS)}")
    name = q.get("type")
    if name not in QUERY_TYPES:
        raise RowError(row, f"unknown query type {name!r}; known: {list(QUERY_TYPES)}")
    fields = {k: v for k, v in q.items() if k != "type" and v is not None}
    bad = sorted(set(fields) - set(_QUERY_FIELDS[name]))
    if bad:
        raise RowError(row, f"unknown {name} field(s) {bad}; known: {list(_QUERY_FIELDS[name])}")
    method, options = data.get("method"), data.get("options") or {}
    if method is not None and not isinstance(method, str):
        raise RowError(row, f"method must be a string, got {method!r}")
    if not isinstance(options, dict):
        raise RowError(row, f"options must be an object, got {options!r}")
    try:
        grasp = Grasp(**{k: v for k, v in g.items() if v is not None})
        query = QUERY_TYPES[name](**fields)
        _check_query(grasp, query)
    except (GraspError, TypeError, ValueError) as e:
        raise RowError(row, str(e)) from None
    return grasp, query, method, options


def _check_query(grasp: Grasp, query: Query) -> None:
    """The query's wrench-sized vectors have the grasp's wrench size and are finite."""
    for f in ("wrench", "direction", "base"):
        v = getattr(query, f, None)
        if v is not None:
            grasp.wrench(v, f)


def row_id(row: int, data: Any) -> str:
    """The id of a query row: its ``id`` field, else its row number."""
    if isinstance(data, dict) and data.get("id") is not None:
        return str(data["id"])
    return str(row)


def read_rows(path: str | Path) -> Iterator[tuple[int, str, Any]]:
    """``(row, id, parsed JSON or the RowError of a line that is not JSON)`` per non-blank line
    of a query file."""
    with open(path, encoding="utf-8") as f:
        for i, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                data = json.loads(line)
            except json.JSONDecodeError as e:
                yield i, str(i), RowError(i, f"not JSON: {e}")
                continue
            yield i, row_id(i, data), data


def _num(v: Any) -> float | None:
    return None if v is None else float(v)


def result_row(row: int, id: str, sol: Solution) -> dict[str, Any]:
    """The result row of a solution (module doc)."""
    st = sol.stats
    out = {
        "row": row,
        "id": id,
        "method": sol.method,
        "backend": st.get("backend"),
        "status": sol.status,
        "stable": sol.stable,
        "value": _num(sol.value),
        "lower": _num(sol.lower),
        "upper": _num(sol.upper),
        "certified": None if "certified" not in st else bool(st["certified"]),
        "capped": None if "capped" not in st else bool(st["capped"]),
        "commands": None if sol.commands is None else _plain(sol.commands),
        "time_s": float(st.get("time_s", math.nan)),
        "message": st.get("message"),
    }
    return out


def failed_row(
    row: int, id: str, status: str, message: str, method: str | None = None
) -> dict[str, Any]:
    """The result row of a query without a solution (``invalid``, ``error``, ``crashed``,
    ``killed``)."""
    out: dict[str, Any] = dict.fromkeys(RESULT_FIELDS)
    out.update(row=row, id=id, method=method, status=status, message=message)
    return out
