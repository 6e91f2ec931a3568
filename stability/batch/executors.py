"""Where batch queries run: local worker processes (default) or a Ray cluster.

Both executors take a picklable function ``fn(payload) -> result`` and an iterable of
``(key, payload)`` tasks and yield ``(key, Outcome)`` as tasks finish (in completion order,
not input order). An :class:`Outcome` is

- ``"ok"`` with ``fn``'s return value,
- ``"error"``: ``fn`` raised (``message`` = ``"ExceptionType: text"``),
- ``"crashed"``: the process running it died on every one of ``1 + retries`` attempts
  (a segfault in a solver, the OOM killer, a lost node),
- ``"killed"``: it ran longer than ``hard_timeout`` seconds and was stopped (its worker
  process is killed and replaced; the task is not retried). Locally the time counts from
  the task's hand-over to a started worker (a fresh worker's imports are waited for first);
  on Ray from submission.

:class:`LocalExecutor` runs ``workers`` processes of its own (``forkserver`` start), one task
at a time each, so that it knows which task a dead worker held: that task is retried on a new
worker, the others go on. :class:`RayExecutor` submits each task as a Ray task
(``max_retries``: Ray re-runs a task whose worker died) and collects results with
``ray.wait``; a hard time-out is ``ray.cancel(force=True)``. Nothing of the distribution is
our own there: scheduling, retries and result transport are Ray's.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from ..errors import GraspError

__all__ = ["BatchError", "Executor", "LocalExecutor", "Outcome", "RayExecutor", "make_executor"]

READY_S = 120.0  # the longest a fresh local worker is waited for to start [s]


class BatchError(GraspError):
    """A batch cannot run: bad options, an unreachable Ray cluster, Ray not installed."""


@dataclass(frozen=True)
class Outcome:
    """How one task ended: ``status`` ``"ok"`` (``value`` is the result), ``"error"``,
    ``"crashed"`` or ``"killed"`` (``message`` says why)."""

    status: str
    value: Any = None
    message: str | None = None


def _call(fn: Callable[[Any], Any], payload: Any) -> Outcome:
    try:
        return Outcome("ok", fn(payload))
    except Exception as e:  # noqa: BLE001  (a query's failure is its result, not the batch's)
        return Outcome("error", message=f"{type(e).__name__}: {e}")


def _worker_main(conn: Connection, fn: Callable[[Any], Any]) -> None:
    """A local worker: send ``None`` once ready (``fn`` unpickled, its imports done), then
    receive ``(key, payload)``, send ``(key, Outcome)``; ``None`` ends it."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    conn.send(None)
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        key, payload = msg
        conn.send((key, _call(fn, payload)))


class Executor:
    """Runs tasks; subclasses implement :meth:`run`."""

    name = "executor"

    def run(
        self, fn: Callable[[Any], Any], tasks: Iterable[tuple[Any, Any]]
    ) -> Iterator[tuple[Any, Outcome]]:
        raise NotImplementedError

    def close(self) -> None:
        """Release what the executor holds (processes, a Ray connection it made)."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class LocalExecutor(Executor):
    """``workers`` local processes (default: the number of cores), each running one task at a
    time; a task whose worker dies is retried ``retries`` times on a fresh worker, then
    reported ``"crashed"``; one running past ``hard_timeout`` [s] is ``"killed"``."""

    name = "local"

    def __init__(
        self, workers: int | None = None, *, retries: int = 2, hard_timeout: float | None = None
    ) -> None:
        workers = (os.cpu_count() or 1) if workers is None else workers
        if not isinstance(workers, int) or workers < 1:
            raise BatchError(f"workers must be an integer >= 1, got {workers!r}")
        if not isinstance(retries, int) or retries < 0:
            raise BatchError(f"retries must be an integer >= 0, got {retries!r}")
        if hard_timeout is not None and not hard_timeout > 0:
            raise BatchError(f"hard_timeout must be > 0 seconds, got {hard_timeout!r}")
        self.workers, self.retries, self.hard_timeout = workers, retries, hard_timeout
        start = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        self._ctx = mp.get_context(start)

    def _spawn(self, fn: Callable[[Any], Any]) -> tuple[Any, Connection]:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_main, args=(child, fn), daemon=True)
        proc.start()
        child.close()
        return proc, parent

    @staticmethod
    def _ready(conn: Connection) -> None:
        """Wait (up to :data:`READY_S`) for a fresh worker's ready token, so that its start-up
        (imports: seconds on a loaded machine) does not count against its first task's
        ``hard_timeout``. A worker that died starting is found when it is given a task; the
        token of one slower than that is skipped when it arrives (:meth:`run`), and its
        start-up then counts against its first task."""
        try:
            if conn.poll(READY_S):
                conn.recv()
        except (EOFError, OSError):
            pass

    def _replace(
        self, pool: list[tuple[Any, Connection]], slot: int, fn: Callable[[Any], Any], kill: bool
    ) -> int | None:
        """A fresh worker in ``pool[slot]`` (the old one killed first when ``kill``, then
        reaped and its pipe closed); returns the old one's exit code."""
        proc, conn = pool[slot]
        if kill:
            proc.kill()
        proc.join(timeout=5.0 if kill else 1.0)
        conn.close()
        pool[slot] = self._spawn(fn)
        self._ready(pool[slot][1])
        return proc.exitcode

    def run(
        self, fn: Callable[[Any], Any], tasks: Iterable[tuple[Any, Any]]
    ) -> Iterator[tuple[Any, Outcome]]:
        todo = iter(tasks)
        retry: deque[tuple[Any, Any, int]] = deque()  # (key, payload, attempts so far)
        pool = [self._spawn(fn) for _ in range(self.workers)]
        for _, conn in pool:  # started together, then each waited for
            self._ready(conn)
        busy: dict[int, tuple[Any, Any, int, float]] = {}  # slot -> key, payload, tries, t0
        exhausted = False
        try:
            while True:
                for slot in range(len(pool)):  # hand out work to idle workers
                    if slot in busy:
                        continue
                    if retry:
                        key, payload, tries = retry.popleft()
                    elif not exhausted:
                        nxt = next(todo, None)
                        if nxt is None:
                            exhausted = True
                            continue
                        (key, payload), tries = nxt, 0
                    else:
                        continue
                    try:
                        pool[slot][1].send((key, payload))
                    except (BrokenPipeError, OSError):  # it died while idle: a fresh one
                        self._replace(pool, slot, fn, kill=False)
                        pool[slot][1].send((key, payload))
                    busy[slot] = (key, payload, tries, time.monotonic())
                if not busy:
                    return
                timeout = None
                if self.hard_timeout is not None:
                    first = min(t0 for *_, t0 in busy.values())
                    timeout = max(0.0, first + self.hard_timeout - time.monotonic())
                handles = {pool[s][1]: s for s in busy} | {pool[s][0].sentinel: s for s in busy}
                ready = wait(list(handles), timeout)
                done: set[int] = set()
                for h in ready:
                    slot = handles[h]
                    if slot in done:
                        continue
                    done.add(slot)
                    key, payload, tries, t0 = busy.pop(slot)
                    conn = pool[slot][1]
                    try:
                        if h is not conn or not conn.poll():
                            raise EOFError
                        msg = conn.recv()
                        if msg is None:  # a ready token later than READY_S: still running
                            busy[slot] = (key, payload, tries, t0)
                            continue
                        got_key, outcome = msg
                    except (EOFError, OSError):  # the worker died holding this task
                        code = self._replace(pool, slot, fn, kill=False)
                        if tries < self.retries:
                            retry.append((key, payload, tries + 1))
                        else:
                            msg = f"its worker died on all {tries + 1} attempts (exit code {code})"
                            yield key, Outcome("crashed", message=msg)
                        continue
                    yield got_key, outcome
                if self.hard_timeout is not None:
                    now = time.monotonic()
                    for slot, (key, _, _, t0) in list(busy.items()):
                        if now - t0 >= self.hard_timeout:
                            self._replace(pool, slot, fn, kill=True)
                            del busy[slot]
                            msg = f"ran past the hard time limit of {self.hard_timeout:g} s"
                            yield key, Outcome("killed", message=msg)
        finally:
            for _, conn in pool:
                try:
                    conn.send(None)
                except (OSError, ValueError):
                    pass
            for proc, conn in pool:
                proc.join(timeout=2.0)
                if proc.is_alive():
                    proc.kill()
                conn.close()


class RayExecutor(Executor):
    """Ray tasks on a cluster: ``address`` ``"auto"`` (the running cluster that ``RAY_ADDRESS``
    or ``ray start`` names, else a new local one), ``"local"`` (always a new local one) or a
    cluster address (``"HOST:6379"``, ``"ray://HOST:10001"``). ``num_cpus`` sizes a new local
    cluster. Each task asks for one CPU; Ray re-runs a task whose worker died up to
    ``retries`` times; at most ``2 x cluster CPUs`` tasks are in flight (``1 x`` with a
    ``hard_timeout``, which counts from submission). Ray's workers import this package: on a
    cluster of several machines install it on every node (or pass Ray a ``runtime_env``)."""

    name = "ray"

    def __init__(
        self,
        address: str = "auto",
        *,
        num_cpus: int | None = None,
        retries: int = 2,
        hard_timeout: float | None = None,
    ) -> None:
        try:
            import ray
        except ImportError as e:
            raise BatchError(
                "--ray needs Ray: pip install -e '.[ray]' (or pip install 'ray>=2.40')"
            ) from e
        self.ray, self.retries, self.hard_timeout = ray, retries, hard_timeout
        self._own = not ray.is_initialized()
        if self._own:
            kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
            if address != "auto":
                kw["address"] = address
            if num_cpus is not None and address in ("auto", "local"):
                kw["num_cpus"] = num_cpus
            try:
                ray.init(**kw)
            except (ConnectionError, RuntimeError, ValueError) as e:
                raise BatchError(f"cannot reach a Ray cluster at {address!r}: {e}") from e
        self.cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))

    def run(
        self, fn: Callable[[Any], Any], tasks: Iterable[tuple[Any, Any]]
    ) -> Iterator[tuple[Any, Outcome]]:
        ray = self.ray
        remote = ray.remote(num_cpus=1, max_retries=self.retries, retry_exceptions=False)(_call)
        fn_ref = ray.put(fn)
        todo = iter(tasks)
        flying: dict[Any, tuple[Any, float]] = {}  # ObjectRef -> key, submit time
        # with a hard time-out a task must start when submitted: no queue beyond the CPUs
        limit = self.cpus if self.hard_timeout is not None else 2 * self.cpus
        exhausted = False
        while True:
            while not exhausted and len(flying) < limit:
                nxt = next(todo, None)
                if nxt is None:
                    exhausted = True
                    break
                key, payload = nxt
                flying[remote.remote(fn_ref, payload)] = (key, time.monotonic())
            if not flying:
                return
            timeout = None if self.hard_timeout is None else 1.0
            ready, _ = ray.wait(list(flying), num_returns=1, timeout=timeout)
            for ref in ready:
                key, _ = flying.pop(ref)
                try:
                    outcome = ray.get(ref)
                except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError) as e:
                    msg = f"its worker died on all {self.retries + 1} attempts ({type(e).__name__})"
                    outcome = Outcome("crashed", message=msg)
                except ray.exceptions.TaskCancelledError:
                    continue
                except ray.exceptions.RayError as e:
                    outcome = Outcome("error", message=f"{type(e).__name__}: {e}")
                yield key, outcome
            if self.hard_timeout is not None:
                now = time.monotonic()
                for ref, (key, t0) in list(flying.items()):
                    if now - t0 >= self.hard_timeout:  # submit time: queueing counts too
                        ray.cancel(ref, force=True)
                        del flying[ref]
                        msg = f"ran past the hard time limit of {self.hard_timeout:g} s"
                        yield key, Outcome("killed", message=msg)

    def close(self) -> None:
        if self._own and self.ray.is_initialized():
            self.ray.shutdown()


def make_executor(
    workers: int | None = None,
    ray: str | None = None,
    *,
    retries: int = 2,
    hard_timeout: float | None = None,
) -> Executor:
    """:class:`RayExecutor` at address ``ray`` when given (``workers`` then sizes a new local
    cluster), else :class:`LocalExecutor` with ``workers`` processes."""
    if ray is not None:
        return RayExecutor(ray, num_cpus=workers, retries=retries, hard_timeout=hard_timeout)
    return LocalExecutor(workers, retries=retries, hard_timeout=hard_timeout)
