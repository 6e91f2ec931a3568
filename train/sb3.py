"""Plumbing shared by the PPO trainers (stable-baselines3): configs, run directories, the model.

The trainers (:mod:`train.rotation`, the main job, and :mod:`train.islands_ppo`, run by the
one skeleton :func:`train.trainer.train`) follow the CleanRL shape: one dataclass config
whose every field is a command-line option or a group of them (:mod:`train.options`:
:func:`opt`, :func:`build_parser`), the seeds set in one block (:func:`seed_everything`
with :class:`train.seeding.RunSeeds`), a run directory with its config.json
(:func:`open_run`, resumable: :func:`saved_timesteps`), SB3 PPO built from the config
(:func:`new_ppo`) and a progress bar over env steps whose rate and time left cover the
whole run, PPO updates and evaluations included (:class:`TqdmProgress`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import random
import time
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecEnv, VecNormalize
from tqdm import tqdm

from train.options import build_parser, from_saved, get_option, opt, set_options, to_json

__all__ = [
    "ActorView",
    "PrivilegedCriticPolicy",
    "RolloutThreads",
    "TqdmProgress",
    "build_parser",
    "learning_rate",
    "new_ppo",
    "normalizer",
    "open_run",
    "opt",
    "option_problems",
    "progress_bar",
    "saved_timesteps",
    "seed_everything",
]


def option_problems(cfg: Any, positive: Sequence[str]) -> list[str]:
    """The checks every PPO config shares: the fields ``positive`` >= 1, net sizes >= 1,
    ``seed >= 0`` and a ``--resume`` directory that holds a model.zip."""
    problems = [f"--{k.replace('_', '-')} must be >= 1" for k in positive if getattr(cfg, k) < 1]
    problems += [f"--{k}: sizes must be >= 1" for k in ("pi", "vf") if min(getattr(cfg, k)) < 1]
    if cfg.seed < 0:
        problems.append("--seed must be >= 0")
    if cfg.resume is not None and not (Path(cfg.resume) / "model.zip").is_file():
        problems.append(f"--resume {cfg.resume}: no model.zip there")
    return problems


def open_run(cfg: Any, name: str, keep: Sequence[str], task: str | None = None) -> tuple[Any, Path]:
    """The config and directory of a run.

    With ``cfg.resume``: the saved config.json of that run (:func:`train.options.from_saved`:
    either layout), except the options ``keep`` (and ``resume``), which come from ``cfg``
    (the saved run decides everything except how long to go on and how to report).
    Otherwise a new directory ``cfg.out/name`` (``_`` appended while it exists) with ``cfg``
    written to config.json (:func:`train.options.to_json`), led by ``"task": task`` when
    given: the trainer that ``--resume`` picks.
    """
    if cfg.resume is not None:
        run_dir = Path(cfg.resume)
        saved = from_saved(type(cfg), json.loads((run_dir / "config.json").read_text()))
        kept = {k: get_option(cfg, k) for k in keep}
        return set_options(saved, kept, resume=cfg.resume), run_dir
    run_dir = Path(cfg.out) / name
    while run_dir.exists():  # two runs started in the same second
        run_dir = run_dir.with_name(run_dir.name + "_")
    run_dir.mkdir(parents=True)
    config = dataclasses.replace(cfg, resume=None)
    text = to_json(config, task=task) if task is not None else to_json(config)
    (run_dir / "config.json").write_text(text)
    return cfg, run_dir


def saved_timesteps(run_dir: Path) -> int:
    """``num_timesteps`` of the PPO model saved in ``run_dir/model.zip``."""
    with zipfile.ZipFile(run_dir / "model.zip") as z:
        return int(json.loads(z.read("data"))["num_timesteps"])


def seed_everything(seed: int) -> None:
    """Python, numpy's legacy global generator and torch (envs are seeded where they are built).

    Call with :attr:`train.seeding.RunSeeds.global_seed`.
    """
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002  (SB3 and Gymnasium wrappers may use the global RNG)
    torch.manual_seed(seed)
    torch.backends.cudnn.deterministic = True


def learning_rate(cfg: Any) -> float | Callable[[float], float]:
    """``cfg.learning_rate``, constant, or with ``cfg.lr_schedule == "linear"`` decaying linearly
    to 0 over the run (SB3's ``LinearSchedule``: ``lr * progress_remaining``)."""
    if cfg.lr_schedule == "constant":
        return cfg.learning_rate
    return LinearSchedule(cfg.learning_rate, 0.0, 1.0)


class ActorView(BaseFeaturesExtractor):
    """The actor's features: the flattened observation with every entry from ``actor_obs``
    on set to zero (the privileged state that only the critic may read). Same width as the
    observation, so the actor's first layer gets no signal, and no gradient, from them."""

    def __init__(self, observation_space: Any, actor_obs: int) -> None:
        super().__init__(observation_space, get_flattened_obs_dim(observation_space))
        mask = torch.zeros(self.features_dim)
        mask[:actor_obs] = 1.0
        self.register_buffer("mask", mask, persistent=False)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return torch.flatten(observations, 1) * self.mask


class PrivilegedCriticPolicy(ActorCriticPolicy):
    """An asymmetric actor-critic: the actor reads the first ``actor_obs`` observation
    entries (:class:`ActorView`), the critic all of them (separate feature extractors)."""

    def __init__(self, *args: Any, actor_obs: int, **kwargs: Any) -> None:
        kwargs["share_features_extractor"] = False
        super().__init__(*args, **kwargs)
        self.actor_obs = int(actor_obs)
        self.pi_features_extractor = ActorView(self.observation_space, self.actor_obs)
        self.features_extractor = self.pi_features_extractor

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "actor_obs": self.actor_obs}


class RolloutThreads(BaseCallback):
    """Torch on one thread while collecting rollouts, ``threads`` for the update.

    With worker processes stepping the envs, two torch threads in the training process
    spin between the small forward passes and take the workers' cores (with them, 2 workers
    are slower than none)."""

    def __init__(self, threads: int) -> None:
        super().__init__()
        self.threads = threads

    def _on_rollout_start(self) -> None:
        torch.set_num_threads(1)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        torch.set_num_threads(self.threads)


def new_ppo(
    cfg: Any,
    vec_env: VecEnv,
    learning_rate: float | Callable[[float], float],
    algo: type[PPO] = PPO,
    actor_obs: int | None = None,
) -> PPO:
    """SB3 PPO (or the subclass ``algo``) from a config's settings: separate policy and value
    nets ``cfg.pi``/``cfg.vf``, CPU, and ``seed=None``: SB3's own seeding would reset the envs
    with ``seed + i`` (the VecEnv's consecutive seeds), undoing :mod:`train.seeding`; call
    :func:`seed_everything` first (the policy's initial weights come from torch's global
    generator). ``actor_obs``: a :class:`PrivilegedCriticPolicy` whose actor reads that many
    leading observation entries."""
    extra = {} if actor_obs is None else {"actor_obs": actor_obs}
    return algo(
        "MlpPolicy" if actor_obs is None else PrivilegedCriticPolicy,
        vec_env,
        learning_rate=learning_rate,
        n_steps=cfg.n_steps,
        batch_size=cfg.batch_size,
        n_epochs=cfg.n_epochs,
        gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        clip_range=cfg.clip_range,
        ent_coef=cfg.ent_coef,
        policy_kwargs={
            "net_arch": {"pi": list(cfg.pi), "vf": list(cfg.vf)},
            "log_std_init": cfg.log_std_init,
            **extra,
        },
        seed=None,
        device="cpu",
        verbose=cfg.verbose,
    )


def normalizer(train_env: VecEnv) -> Callable[[np.ndarray], np.ndarray] | None:
    """The training env's observation normalisation (frozen: it does not update the statistics),
    or ``None`` without ``VecNormalize``."""
    return train_env.normalize_obs if isinstance(train_env, VecNormalize) else None


class TqdmProgress(BaseCallback):
    """A plain tqdm progress bar over env steps (SB3's own bar needs ``rich``).

    The bar counts env steps; its rate and time left are those of the last ``window``
    seconds of whole rollout cycles (rollout, PPO update and any evaluation between two
    rollout starts), so that updates and evaluations count and a change of the machine's
    load shows within minutes. Until a second rollout starts, the rate is the average
    since the start. ``rate`` after training: the run's steps over its wall time."""

    def __init__(self, total: int, desc: str = "", window: float = 600.0) -> None:
        super().__init__()
        self.total, self.desc, self.window = total, desc, window
        self.rate = float("nan")
        self.samples: list[tuple[float, int]] = []  # (time [s], steps) at rollout starts
        self.recent = float("nan")  # [steps/s]

    def _on_training_start(self) -> None:
        self.bar = tqdm(
            total=self.total, desc=self.desc, unit="step", dynamic_ncols=True, smoothing=0,
            bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}{postfix}]",
        )  # fmt: skip

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        self._show(refresh=False)
        return True

    def _on_rollout_start(self) -> None:
        now = time.perf_counter()
        self.samples.append((now, self.bar.n))
        # the oldest sample kept is the last one at least `window` seconds old
        old = [k for k, (t, _) in enumerate(self.samples) if t <= now - self.window]
        if old:
            del self.samples[: old[-1]]
        (t0, n0), (t1, n1) = self.samples[0], self.samples[-1]
        if t1 > t0 and n1 > n0:
            self.recent = (n1 - n0) / (t1 - t0)
        self._show(refresh=True)  # after an update or evaluation: the time left counts it

    def _show(self, refresh: bool) -> None:
        """The recent rate and the time left at it (steps left / rate); tqdm's own average
        since the start until a second rollout has started."""
        rate = self.recent if math.isfinite(self.recent) else self._average()
        if math.isfinite(rate) and rate > 0:
            left = tqdm.format_interval((self.bar.total - self.bar.n) / rate)
            self.bar.set_postfix_str(f"{rate:.1f}step/s, {left} left", refresh=False)
        if refresh:
            self.bar.refresh()

    def _average(self) -> float:
        """Steps over the wall time since the start [steps/s] (NaN before any time passed)."""
        d = self.bar.format_dict
        return d["n"] / d["elapsed"] if d["elapsed"] > 0 else float("nan")

    def _on_training_end(self) -> None:
        self.rate = self._average()
        self.bar.close()


def progress_bar(cfg: Any, desc: str = "") -> TqdmProgress:
    """A :class:`TqdmProgress` over the steps ``learn(cfg.total_steps)`` will take: it stops at
    the first rollout end past the budget."""
    rollout = cfg.n_steps * cfg.n_envs
    return TqdmProgress(-(-cfg.total_steps // rollout) * rollout, desc=desc)
