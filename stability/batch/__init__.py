"""Label many grasps: a file of stability queries in, one result row per query out.

::

    python -m stability.batch random queries.jsonl --n 1000 --contacts 4    # a query file
    python -m stability.batch queries.jsonl results.jsonl --method refinement --time-limit 30
    python -m stability.batch queries.jsonl results.jsonl --ray auto        # on a Ray cluster
    python -m ihm batch barrett_box box.jsonl --directions 36                # a scene's map

The file format is JSON lines (:mod:`stability.batch.rows`); the queries run on local worker
processes by default or as Ray tasks (:mod:`stability.batch.executors`). Results are appended
as they arrive; rerunning with the same result file answers only what is missing (resume).
A query that fails, times out, or kills its worker is recorded with its status; a row that
cannot be read is reported with its row number. In Python::

    from stability.batch import run_batch, random_rows, write_rows, LocalExecutor
    write_rows("q.jsonl", random_rows(100, contacts=4))
    counts = run_batch("q.jsonl", "r.jsonl", method="refinement",
                       executor=LocalExecutor(workers=2))
"""

from .executors import BatchError, Executor, LocalExecutor, Outcome, RayExecutor, make_executor
from .rows import RESULT_FIELDS, RowError, decode_row, encode_query, read_rows, result_row
from .run import answered, run_batch, solve_row
from .writers import MapPlane, map_rows, random_planar, random_rows, write_rows

__all__ = [
    "RESULT_FIELDS",
    "BatchError",
    "Executor",
    "LocalExecutor",
    "MapPlane",
    "Outcome",
    "RayExecutor",
    "RowError",
    "answered",
    "decode_row",
    "encode_query",
    "make_executor",
    "map_rows",
    "random_planar",
    "random_rows",
    "read_rows",
    "result_row",
    "run_batch",
    "solve_row",
    "write_rows",
]
