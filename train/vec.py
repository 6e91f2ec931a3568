"""A vectorised env that steps its envs in a few worker processes, each its share in turn.

SB3's ``SubprocVecEnv`` runs one process per env: with 16 envs on a 2-core machine
that is 16 pipe round trips and context switches per step, and it measured no
faster than stepping all envs in the training process (``DummyVecEnv``).
:class:`ChunkedVecEnv` runs ``n_workers`` processes (one per core), each holding a
``DummyVecEnv`` over a contiguous chunk of the envs: one round trip per worker
per step, and the physics of the chunks runs in parallel.

The result is the same as ``DummyVecEnv`` over the same thunks, step for step
(same auto-reset, ``terminal_observation`` and seeding semantics: each chunk *is*
a ``DummyVecEnv``); ``tests/test_four_finger_env.py`` checks it.
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
    parent.close()
    venv = DummyVecEnv(fns.var)
    try:
        while True:
            cmd, data = remote.recv()
            if cmd == "step":
                venv.step_async(data)
                remote.send(venv.step_wait())
            elif cmd == "reset":
                seeds, options = data
                for i, (s, o) in enumerate(zip(seeds, options, strict=True)):
                    venv._seeds[i], venv._options[i] = s, o
                remote.send((venv.reset(), venv.reset_infos))
            elif cmd == "get_attr":
                remote.send(venv.get_attr(*data))
            elif cmd == "set_attr":
                remote.send(venv.set_attr(*data))
            elif cmd == "env_method":
                name, args, kwargs, idx = data
                remote.send(venv.env_method(name, *args, indices=idx, **kwargs))
            elif cmd == "is_wrapped":
                remote.send(venv.env_is_wrapped(*data))
            elif cmd == "render":
                remote.send(venv.get_images())
            elif cmd == "close":
                venv.close()
                remote.close()
                break
            else:
                raise NotImplementedError(f"unknown command {cmd!r}")
    except (EOFError, KeyboardInterrupt):
        venv.close()


def _chunks(n: int, k: int) -> list[range]:
    """``n`` env indices split into ``k`` contiguous chunks of near-equal size."""
    bounds = np.linspace(0, n, k + 1).round().astype(int)
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


class ChunkedVecEnv(VecEnv):
    """``len(env_fns)`` envs stepped by ``n_workers`` processes (contiguous chunks).

    Parameters
    ----------
    env_fns : thunks that build the envs (pickled with cloudpickle to the workers).
    n_workers : worker processes (at most ``len(env_fns)``; one per core pays off).
    start_method : multiprocessing start method; default ``forkserver`` where
        available (safe with threads in the parent, e.g. torch's), else ``spawn``.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]],
        n_workers: int = 2,
        start_method: str | None = None,
    ) -> None:
        if n_workers < 1:
            raise ValueError(f"n_workers must be >= 1, got {n_workers}")
        self.chunks = _chunks(len(env_fns), min(n_workers, len(env_fns)))
        if start_method is None:
            methods = mp.get_all_start_methods()
            start_method = "forkserver" if "forkserver" in methods else "spawn"
        ctx = mp.get_context(start_method)
        self.remotes, self.processes = [], []
        for chunk in self.chunks:
            remote, work_remote = ctx.Pipe()
            fns = CloudpickleWrapper([env_fns[i] for i in chunk])
            proc = ctx.Process(target=_worker, args=(work_remote, remote, fns), daemon=True)
            proc.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(proc)
        self.closed = False
        self.waiting = False
        self.remotes[0].send(("get_attr", ("observation_space", [0])))
        obs_space = self.remotes[0].recv()[0]
        self.remotes[0].send(("get_attr", ("action_space", [0])))
        act_space = self.remotes[0].recv()[0]
        super().__init__(len(env_fns), obs_space, act_space)

    # -- stepping --------------------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        for remote, chunk in zip(self.remotes, self.chunks, strict=True):
            remote.send(("step", actions[chunk.start : chunk.stop]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        results = [remote.recv() for remote in self.remotes]
        self.waiting = False
        obs = np.concatenate([r[0] for r in results])
        rews = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        return obs, rews, dones, infos

    def reset(self) -> VecEnvObs:
        for remote, chunk in zip(self.remotes, self.chunks, strict=True):
            seeds = [self._seeds[i] for i in chunk]
            options = [self._options[i] for i in chunk]
            remote.send(("reset", (seeds, options)))
        results = [remote.recv() for remote in self.remotes]
        self.reset_infos = [info for r in results for info in r[1]]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate([r[0] for r in results])

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                remote.recv()
        for remote in self.remotes:
            remote.send(("close", None))
        for proc in self.processes:
            proc.join()
        self.closed = True

    def get_images(self) -> Sequence[np.ndarray | None]:
        for remote in self.remotes:
            remote.send(("render", None))
        return [img for remote in self.remotes for img in remote.recv()]

    # -- attributes and methods, routed to the worker that holds each env ---------------------
    def _route(self, indices: VecEnvIndices) -> list[tuple[int, list[int]]]:
        """(worker, local indices) for the global ``indices``, in worker order."""
        wanted = set(self._get_indices(indices))
        out = []
        for w, chunk in enumerate(self.chunks):
            local = [i - chunk.start for i in chunk if i in wanted]
            if local:
                out.append((w, local))
        return out

    def _gather(self, cmd: str, make: Callable[[list[int]], Any], indices: VecEnvIndices) -> list:
        routes = self._route(indices)
        for w, local in routes:
            self.remotes[w].send((cmd, make(local)))
        return [x for w, _ in routes for x in self.remotes[w].recv()]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._gather("get_attr", lambda loc: (attr_name, loc), indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for w, local in self._route(indices):
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
    thunks: Sequence[Callable[[], gym.Env]], workers: int
) -> DummyVecEnv | ChunkedVecEnv:
    """``DummyVecEnv`` for ``workers`` 0 (or a single env), else :class:`ChunkedVecEnv`."""
    if workers == 0 or len(thunks) == 1:
        return DummyVecEnv(list(thunks))
    return ChunkedVecEnv(thunks, n_workers=workers)


__all__ = ["ChunkedVecEnv", "make_vec_env"]
