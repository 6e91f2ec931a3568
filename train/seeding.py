"""Independent random streams for a training run, from one integer seed.

A run seed ``S`` (``--seed``) names a root :class:`numpy.random.SeedSequence`; every
consumer of randomness gets its own child of that root, addressed by a fixed path of
spawn keys, so that

- two run seeds share no stream: ``SeedSequence`` hashes the whole path, so run 1's
  training env 3 and run 2's training env 2 are unrelated (with consecutive seeds
  ``seed + i`` instead, seeds 1, 2 and 3 would share 7 of their 8 reset streams);
- the streams of one run do not overlap each other either: training, validation and
  test environments, and the global generators, each have their own subtree;
- the same seed gives the same streams on every machine.

The tree (``segment`` is 0 for a fresh run and the number of steps already trained
for a resumed one, so that a resumed run draws fresh episodes)::

    SeedSequence(S, spawn_key=(segment,))
    ├── 0 "train"       child i: reset seed and action-space seed of training env i
    ├── 1 "validation"  child i: evaluation env i of the trainers' own evaluations
    │                   (eval.json; what tuning looks at)
    ├── 2 "test"        child i: evaluation env i of held-out evaluations (the
    │                   benchmark's final scores); the trainers never draw from it
    └── 3 "global"      one 32-bit seed for Python's ``random``, numpy's legacy global
                        generator and torch (policy initialisation, action sampling)

An environment gets its stream through ``env.reset(seed=reset_seed)`` once, when it is
built; every later reset continues that generator. Reset seeds are 64-bit integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["STREAMS", "EnvSeeds", "RunSeeds"]

STREAMS = {"train": 0, "validation": 1, "test": 2, "global": 3}
"""Named subtrees of a run's root seed sequence (their spawn-key index)."""


@dataclass(frozen=True)
class EnvSeeds:
    """The seeds of one environment: its first ``reset(seed=...)`` and its action space."""

    reset: int
    action_space: int


def _child(parent: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child ``index`` of ``parent``, addressed directly (``spawn`` would count calls)."""
    return np.random.SeedSequence(parent.entropy, spawn_key=(*parent.spawn_key, index))


@dataclass(frozen=True)
class RunSeeds:
    """All random streams of one run (see the module docstring for the tree).

    Args:
        seed: the run seed, an integer >= 0.
        segment: 0 for a fresh run; for a resumed run, the steps already trained.
    """

    seed: int
    segment: int = 0

    def __post_init__(self) -> None:
        for name in ("seed", "segment"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")

    @property
    def root(self) -> np.random.SeedSequence:
        """``SeedSequence(seed, spawn_key=(segment,))``."""
        return np.random.SeedSequence(int(self.seed), spawn_key=(int(self.segment),))

    def stream(self, name: str) -> np.random.SeedSequence:
        """The subtree ``name`` (one of :data:`STREAMS`)."""
        if name not in STREAMS:
            raise ValueError(f"unknown stream {name!r}; choose one of {list(STREAMS)}")
        return _child(self.root, STREAMS[name])

    def env(self, stream: str, index: int) -> EnvSeeds:
        """Seeds of env ``index`` (>= 0) of the ``train``, ``validation`` or ``test`` stream."""
        if stream == "global":
            raise ValueError("the 'global' stream has no environments")
        if index < 0:
            raise ValueError(f"env index must be >= 0, got {index}")
        reset, action = _child(self.stream(stream), index).generate_state(2, np.uint64)
        return EnvSeeds(reset=int(reset), action_space=int(action))

    def envs(self, stream: str, n: int) -> list[EnvSeeds]:
        """Seeds of envs ``0 .. n-1`` of ``stream``."""
        return [self.env(stream, i) for i in range(n)]

    def policy_seed(self, stream: str) -> int:
        """A 32-bit torch seed for sampling a stochastic policy's actions while evaluating on
        ``stream`` (the stream node's own state: unrelated to its env children)."""
        if stream not in ("validation", "test"):
            raise ValueError(f"policy_seed is for 'validation' or 'test', got {stream!r}")
        return int(self.stream(stream).generate_state(1, np.uint32)[0])

    @property
    def global_seed(self) -> int:
        """A 32-bit seed for ``random``, ``numpy.random.seed`` and ``torch.manual_seed``."""
        return int(self.stream("global").generate_state(1, np.uint32)[0])
