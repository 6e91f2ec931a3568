"""One PPO trainer for every task: the skeleton that ``python -m train.ppo`` runs.

A task (:class:`Task`; the four-finger rotation main job :data:`train.rotation.TASK`, the
islands-and-bridges toy :data:`train.islands_ppo.TASK`) says what differs between them: its
config (a dataclass of command-line options, :mod:`train.options`), its training and
evaluation envs, its model, its callbacks and its final evaluation. :func:`train` does the
rest, in the same order for every task:

1. the config: the command line, or with ``--resume`` the run's saved config.json except the
   options the task lets a resume change (:func:`train.sb3.open_run`);
2. the run directory, its config.json led by ``"task"`` (what ``--resume`` reads back:
   :func:`run_task`);
3. the task's preparations (:meth:`Task.prepare`: the rotation task builds its start-grasp
   cache and records a fine-tune);
4. the seeds: one :class:`train.seeding.RunSeeds` segment per (re)start, python, numpy and
   torch seeded from it (:func:`train.sb3.seed_everything`);
5. the training VecEnv, then the evaluation envs;
6. the model: ``model.zip`` loaded on resume, else the task's new one;
7. SB3's CSV logger in the run directory, the task's callbacks and the progress bar, and
   ``learn`` for ``total_steps`` more env steps;
8. ``model.zip`` and ``vecnormalize.pkl`` saved (:func:`train.runfiles.checkpoint`), the
   task's final evaluation written to ``eval.json``, the envs closed, one line printed.
"""

from __future__ import annotations

import json
import sys
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv

from train.runfiles import checkpoint
from train.sb3 import open_run, progress_bar, saved_timesteps, seed_everything
from train.seeding import RunSeeds

__all__ = ["Run", "Task", "run_task", "train"]


@dataclass(frozen=True)
class Run:
    """A training run once it is built, as the task's hooks see it: its config ``cfg``, its
    directory, ``done`` (the env steps it had before this (re)start), its ``seeds``, the
    training VecEnv ``vec``, the task's evaluation envs ``evals``, the ``model`` and the
    task's ``callbacks``."""

    cfg: Any
    dir: Path
    done: int
    seeds: RunSeeds
    vec: VecEnv
    evals: Any
    model: PPO
    callbacks: tuple[BaseCallback, ...]


class Task(ABC):
    """What a PPO task plugs into :func:`train`. ``name`` is recorded in the run's
    config.json; ``algo`` is the PPO class that loads the run's ``model.zip`` on resume."""

    name: ClassVar[str]
    algo: ClassVar[type[PPO]] = PPO

    @abstractmethod
    def parse(self, argv: Sequence[str]) -> Any:
        """The task's config from the command line ``argv`` (exit 2 on bad options)."""

    @abstractmethod
    def run_name(self, cfg: Any) -> str:
        """The new run directory's name."""

    @abstractmethod
    def resume_options(self, cfg: Any, argv: Sequence[str]) -> tuple[str, ...]:
        """The options that ``--resume`` takes from the command line ``argv``; every other
        option is the saved run's."""

    def threads(self, cfg: Any) -> int:
        """Torch threads for the run."""
        return int(cfg.threads)

    def prepare(self, cfg: Any, run_dir: Path, argv: Sequence[str], done: int) -> Any:
        """Work before the envs are built, ``done`` env steps into the run; returns the
        config the run goes on with (by default ``cfg``)."""
        return cfg

    @abstractmethod
    def train_env(self, cfg: Any, seeds: RunSeeds, run_dir: Path) -> VecEnv:
        """The training VecEnv on the ``train`` streams of ``seeds`` (with its Monitor files
        and normalisation; on resume appended to and loaded from ``run_dir``)."""

    @abstractmethod
    def eval_envs(self, cfg: Any, seeds: RunSeeds) -> Any:
        """The envs the evaluations run on (the ``validation`` streams of ``seeds``)."""

    @abstractmethod
    def new_model(self, cfg: Any, vec: VecEnv) -> PPO:
        """A new model on ``vec`` (a run that does not resume)."""

    def callbacks(self, cfg: Any, run_dir: Path, evals: Any) -> list[BaseCallback]:
        """The task's callbacks during ``learn`` (the skeleton adds the progress bar)."""
        return []

    @abstractmethod
    def evaluate(self, run: Run, train_seconds: float) -> dict[str, Any]:
        """The final evaluation and what ``eval.json`` records with it."""

    @abstractmethod
    def summary(self, run: Run, result: dict[str, Any], train_seconds: float) -> str:
        """The line printed at the end."""

    def close(self, run: Run) -> None:
        """Close the envs (and finish the run's files)."""
        run.vec.close()
        for env in run.evals:
            env.close()


def run_task(run_dir: Path) -> str:
    """The task of a run directory: the ``task`` its config.json records; a run from before
    that key is the rotation task when its config names an ``object``, else the islands
    task."""
    saved = json.loads((Path(run_dir) / "config.json").read_text())
    if "task" in saved:
        return str(saved["task"])
    return "rotation" if "object" in saved else "islands"


def _model(task: Task, cfg: Any, vec: VecEnv, run_dir: Path) -> PPO:
    """The run's model: ``model.zip`` loaded on resume (``seed=None``: SB3 would re-seed the
    envs with consecutive seeds), else the task's new model; the envs are closed when it
    fails."""
    try:
        if cfg.resume is not None:
            return task.algo.load(run_dir / "model.zip", env=vec, device="cpu", seed=None)
        return task.new_model(cfg, vec)
    except BaseException:
        vec.close()
        raise


def _check_task(task: Task, cfg: Any) -> None:
    """Exit with a message when ``--resume`` names a run of another task."""
    if cfg.resume is not None and (Path(cfg.resume) / "config.json").is_file():
        saved = run_task(Path(cfg.resume))
        if saved != task.name:
            raise SystemExit(
                f"python -m train.ppo: error: --resume {cfg.resume}: a {saved} run, "
                f"not a {task.name} run"
            )


def train(task: Task, argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Train (or resume) a run of ``task`` from the command line ``argv`` (module doc);
    returns the final evaluation with ``run_dir``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    cfg = task.parse(argv)
    _check_task(task, cfg)
    torch.set_num_threads(task.threads(cfg))
    keep = task.resume_options(cfg, argv)
    cfg, run_dir = open_run(cfg, task.run_name(cfg), keep=keep, task=task.name)
    done = saved_timesteps(run_dir) if cfg.resume is not None else 0
    cfg = task.prepare(cfg, run_dir, argv, done)
    seeds = RunSeeds(cfg.seed, segment=done)  # a resumed run is a new segment: fresh streams
    seed_everything(seeds.global_seed)  # python, numpy, torch (initial weights, sampling)
    vec = task.train_env(cfg, seeds, run_dir)
    evals = task.eval_envs(cfg, seeds)
    model = _model(task, cfg, vec, run_dir)
    model.set_logger(configure(str(run_dir), ["csv"] + (["stdout"] if cfg.verbose else [])))
    callbacks = task.callbacks(cfg, run_dir, evals)
    run = Run(cfg, run_dir, done, seeds, vec, evals, model, tuple(callbacks))
    if cfg.progress:
        callbacks.append(progress_bar(cfg, desc=run_dir.name))
    t0 = time.perf_counter()
    model.learn(cfg.total_steps, callback=callbacks, reset_num_timesteps=cfg.resume is None)
    train_s = time.perf_counter() - t0
    checkpoint(model, run_dir)
    result = task.evaluate(run, train_s)
    (run_dir / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
    task.close(run)
    print(task.summary(run, result, train_s))
    return {**result, "run_dir": str(run_dir)}
