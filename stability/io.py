"""The one CSV writer of every benchmark (stability, envs, shields, train).

Rows are dicts; the columns are ``columns`` or, by default, the union of the rows' keys in
order of first appearance. Floats are written with ``repr`` unless ``float_format`` (e.g.
``".6g"``) is given. Sorting, if any, is the caller's.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["write_csv"]


def write_csv(
    path: str | Path,
    rows: Iterable[Mapping[str, Any]],
    columns: Sequence[str] | None = None,
    float_format: str | None = None,
) -> Path:
    """Write ``rows`` to ``path`` as CSV with a header line; returns ``path`` as a ``Path``.

    A row that lacks a column leaves its cell empty; a key outside ``columns`` is an error
    (``ValueError``), never silently dropped.
    """
    path = Path(path)
    rows = list(rows)
    if columns is None:
        columns = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(columns))
        w.writeheader()
        for r in rows:
            if float_format is not None:
                r = {
                    k: format(v, float_format) if isinstance(v, float) else v for k, v in r.items()
                }
            w.writerow(r)
    return path
