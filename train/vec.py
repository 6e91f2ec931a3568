"""A vectorised env that steps its envs in a few worker processes, each its share in turn.

SB3's ``SubprocVecEnv`` runs one process per env: with 16 envs on a 2-core machine
that is 16 pipe round trips and context switches per step, and it is no
faster than stepping all envs in the training process (``DummyVecEnv``).
:class:`ChunkedVecEnv` runs ``n_workers`` processes (one per core), each holding a
``DummyVecEnv`` over a contiguous chunk of the envs: one round trip per worker
per step, and the physics of the chunks runs in parallel.

The result is the same as ``DummyVecEnv`` over the same thunks, step for step
(same auto-reset, ``terminal_observation`` and seeding semantics: each chunk *is*
a ``DummyVecEnv``); ``tests/train/test_vec.py`` checks it.
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv
from stable_baselines3.common.vec_env.base_vec_env import (
    CloudpickleWrapper,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)


def _worker(remote: Any, parent: Any, fns: CloudpickleWrapper) -> None:
    """Serve one worker's envs: one ``DummyVecEnv`` per part (``fns.var`` is a list of parts,
    each a list of thunks); local env ``j`` is the ``j``-th env of the parts in order."""
    parent.close()
    venvs = [DummyVecEnv(part) for part in fns.var]
    where = [(p, i) for p, v in enumerate(venvs) for i in range(v.num_envs)]

    def step(p: int, actions: np.ndarray) -> VecEnvStepReturn:
        venvs[p].step_async(actions)
        return venvs[p].step_wait()

    def each(local: list[int], method: str, *args: Any, **kwargs: Any) -> list[Any]:
        """``DummyVecEnv.<method>(*args, indices=[i], **kwargs)[0]`` per local env."""
        out = []
        for j in local:
            p, i = where[j]
            out.append(getattr(venvs[p], method)(*args, indices=[i], **kwargs)[0])
        return out

    try:
        while True:
            cmd, data = remote.recv()
            if cmd == "step":
                out, k = [], 0
                for p, v in enumerate(venvs):
                    out.append(step(p, data[k : k + v.num_envs]))
                    k += v.num_envs
                remote.send(
                    (
                        np.concatenate([o[0] for o in out]),
                        np.concatenate([o[1] for o in out]),
                        np.concatenate([o[2] for o in out]),
                        [i for o in out for i in o[3]],
                    )
                )
            elif cmd == "step_part":
                remote.send(step(*data))
            elif cmd == "reset":
                seeds, options = data
                for j, (s, o) in enumerate(zip(seeds, options, strict=True)):
                    p, i = where[j]
                    venvs[p]._seeds[i], venvs[p]._options[i] = s, o
                obs = np.concatenate([v.reset() for v in venvs])
                remote.send((obs, [i for v in venvs for i in v.reset_infos]))
            elif cmd == "get_attr":
                name, local = data
                remote.send(each(local, "get_attr", name))
            elif cmd == "set_attr":
                name, value, local = data
                for j in local:
                    p, i = where[j]
                    venvs[p].set_attr(name, value, [i])
                remote.send(None)
            elif cmd == "env_method":
                name, args, kwargs, local = data
                remote.send(each(local, "env_method", name, *args, **kwargs))
            elif cmd == "is_wrapped":
                cls, local = data
                remote.send(each(local, "env_is_wrapped", cls))
            elif cmd == "render":
                remote.send([img for v in venvs for img in v.get_images()])
            elif cmd == "close":
                for v in venvs:
                    v.close()
                remote.close()
                break
            else:
                raise NotImplementedError(f"unknown command {cmd!r}")
    except (EOFError, KeyboardInterrupt):
        for v in venvs:
            v.close()


def _chunks(n: int, k: int) -> list[range]:
    """``n`` env indices split into ``k`` contiguous chunks of near-equal size."""
    bounds = np.linspace(0, n, k + 1).round().astype(int)
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


class ChunkedVecEnv(VecEnv):
    """``len(env_fns)`` envs stepped by ``n_workers`` processes.

    The envs are split into ``parts`` contiguous parts, and each part into ``n_workers``
    contiguous chunks, worker ``w`` holding chunk ``w`` of every part: :meth:`step_async`
    steps them all, :meth:`step_part_async` one part on all workers at once. With two parts
    the training process can compute one part's actions while the workers step the other
    (:class:`train.pipeline.PipelinedPPO`).

    Parameters
    ----------
    env_fns : thunks that build the envs (pickled with cloudpickle to the workers).
    n_workers : worker processes (at most the smallest part's size; one per core pays off).
    parts : parts of the envs (1: plain stepping of all envs).
    start_method : multiprocessing start method; default ``forkserver`` where
        available (safe with threads in the parent, e.g. torch's), else ``spawn``.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]],
        n_workers: int = 2,
        start_method: str | None = None,
        parts: int = 1,
    ) -> None:
        if n_workers < 1:
            raise ValueError(f"n_workers must be >= 1, got {n_workers}")
        if not 1 <= parts <= len(env_fns):
            raise ValueError(f"parts must be in [1, {len(env_fns)}], got {parts}")
        self.parts = _chunks(len(env_fns), parts)
        k = min(n_workers, min(len(p) for p in self.parts))
        # sub[p][w]: the global indices of part p that worker w steps
        self.sub = [[range(p.start + c.start, p.start + c.stop) for c in _chunks(len(p), k)]
                    for p in self.parts]  # fmt: skip
        self.chunks = [[i for p in self.sub for i in p[w]] for w in range(k)]
        # env i sits at position _inverse[i] of the workers' concatenated results
        self._inverse = np.argsort([i for c in self.chunks for i in c])
        self._where = {i: (w, j) for w, c in enumerate(self.chunks) for j, i in enumerate(c)}
        if start_method is None:
            methods = mp.get_all_start_methods()
            start_method = "forkserver" if "forkserver" in methods else "spawn"
        ctx = mp.get_context(start_method)
        self.remotes, self.processes = [], []
        for w in range(k):
            remote, work_remote = ctx.Pipe()
            fns = CloudpickleWrapper([[env_fns[i] for i in p[w]] for p in self.sub])
            proc = ctx.Process(target=_worker, args=(work_remote, remote, fns), daemon=True)
            proc.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(proc)
        self.closed = False
        self.waiting = False
        self._pending = 0  # step commands sent and not yet received (part steps may queue)
        self.remotes[0].send(("get_attr", ("observation_space", [0])))
        obs_space = self.remotes[0].recv()[0]
        self.remotes[0].send(("get_attr", ("action_space", [0])))
        act_space = self.remotes[0].recv()[0]
        super().__init__(len(env_fns), obs_space, act_space)

    def _idle(self, what: str) -> None:
        """Raise unless no part step is queued: a reply would be read as a step result."""
        if self._pending:
            raise RuntimeError(f"{what} with part steps pending: collect them first")

    def _env_order(self, items: Any) -> Any:
        """Items concatenated in worker order (an array or a list), in env order."""
        if isinstance(items, np.ndarray):
            return items[self._inverse]
        return [items[k] for k in self._inverse]

    def _global(self, results: list[tuple]) -> tuple:
        """Workers' concatenated results in global env order."""
        return (
            self._env_order(np.concatenate([r[0] for r in results])),
            self._env_order(np.concatenate([r[1] for r in results])),
            self._env_order(np.concatenate([r[2] for r in results])),
            self._env_order([info for r in results for info in r[3]]),
        )

    # -- stepping --------------------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        self._idle("step_async")
        for remote, chunk in zip(self.remotes, self.chunks, strict=True):
            remote.send(("step", actions[chunk]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        results = [remote.recv() for remote in self.remotes]
        self.waiting = False
        return self._global(results)

    def step_part_async(self, part: int, actions: np.ndarray) -> None:
        """Step the envs of ``self.parts[part]`` with ``actions`` (one row per env of the
        part, in order); collect with :meth:`step_part_wait`. Part steps queue: a second
        one may be sent before the first is collected, and the workers start it as soon as
        they finish the first."""
        base = self.parts[part].start
        for remote, r in zip(self.remotes, self.sub[part], strict=True):
            remote.send(("step_part", (part, actions[r.start - base : r.stop - base])))
        self._pending += 1
        self.waiting = True

    def step_part_wait(self) -> VecEnvStepReturn:
        """Observations, rewards, dones and infos of the oldest part step not yet collected,
        in env order."""
        if self._pending == 0:
            raise RuntimeError("step_part_wait without a pending step_part_async")
        results = [remote.recv() for remote in self.remotes]
        self._pending -= 1
        self.waiting = self._pending > 0
        return (
            np.concatenate([r[0] for r in results]),
            np.concatenate([r[1] for r in results]),
            np.concatenate([r[2] for r in results]),
            [info for r in results for info in r[3]],
        )

    def reset(self) -> VecEnvObs:
        self._idle("reset")
        for remote, chunk in zip(self.remotes, self.chunks, strict=True):
            seeds = [self._seeds[i] for i in chunk]
            options = [self._options[i] for i in chunk]
            remote.send(("reset", (seeds, options)))
        results = [remote.recv() for remote in self.remotes]
        self.reset_infos = self._env_order([info for r in results for info in r[1]])
        self._reset_seeds()
        self._reset_options()
        return self._env_order(np.concatenate([r[0] for r in results]))

    def close(self) -> None:
        if self.closed:
            return
        for _ in range(max(self._pending, int(self.waiting))):
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for proc in self.processes:
            proc.join()
        self.closed = True

    def get_images(self) -> Sequence[np.ndarray | None]:
        self._idle("get_images")
        for remote in self.remotes:
            remote.send(("render", None))
        return self._env_order([img for remote in self.remotes for img in remote.recv()])

    # -- attributes and methods, routed to the worker that holds each env ---------------------
    def _route(self, indices: VecEnvIndices) -> list[tuple[int, list[int], list[int]]]:
        """(worker, local indices, global indices) for the global ``indices``."""
        per: dict[int, tuple[list[int], list[int]]] = {}
        for i in self._get_indices(indices):
            w, j = self._where[i]
            per.setdefault(w, ([], []))
            per[w][0].append(j)
            per[w][1].append(i)
        return [(w, *per[w]) for w in sorted(per)]

    def _gather(self, cmd: str, make: Callable[[list[int]], Any], indices: VecEnvIndices) -> list:
        """Results in the order of ``indices``."""
        self._idle(cmd)
        routes = self._route(indices)
        for w, local, _ in routes:
            self.remotes[w].send((cmd, make(local)))
        got = {}
        for w, _, glob in routes:
            got.update(zip(glob, self.remotes[w].recv(), strict=True))
        return [got[i] for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._gather("get_attr", lambda loc: (attr_name, loc), indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._idle("set_attr")
        for w, local, _ in self._route(indices):
            self.remotes[w].send(("set_attr", (attr_name, value, local)))
            self.remotes[w].recv()

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        return self._gather(
            "env_method", lambda loc: (method_name, method_args, method_kwargs, loc), indices
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return self._gather("is_wrapped", lambda loc: (wrapper_class, loc), indices)


def make_vec_env(
    thunks: Sequence[Callable[[], gym.Env]], workers: int, parts: int = 1
) -> DummyVecEnv | ChunkedVecEnv:
    """``DummyVecEnv`` for ``workers`` 0 (or a single env), else :class:`ChunkedVecEnv` with
    ``parts`` parts (at most one per env)."""
    if workers == 0 or len(thunks) == 1:
        return DummyVecEnv(list(thunks))
    return ChunkedVecEnv(thunks, n_workers=workers, parts=min(parts, len(thunks)))


__all__ = ["ChunkedVecEnv", "make_vec_env"]
