"""PPO on a shielded islands-and-bridges env: ``python -m train.ppo islands [options]``.

CleanRL shape, SB3 algorithm (:mod:`train.sb3`): one :class:`Config` dataclass (every field
is a command-line option, ``--help`` lists them), one :func:`make_env` thunk with the whole
wrapper stack, the seeds set in one block, runs named ``{env}__{shield}__{seed}__{time}``
under ``--out``. (``python -m train.ppo`` without ``islands`` trains the four-finger
rotation main job, :mod:`train.rotation`.)

The run is :data:`TASK` plugged into the one trainer :func:`train.trainer.train`. A run
directory holds::

    model.zip           the PPO model (policy, value net, optimiser, num_timesteps)
    config.json         the Config of the run, led by "task": "islands"
    monitor/N.monitor.csv  one Monitor log per training env (r, l, t, is_success)
    eval.json           the final evaluation (:func:`train.evaluation.evaluate_success`)
    progress.csv        SB3's logger (losses/, charts/, shield/ keys)
    vecnormalize.pkl    VecNormalize statistics (--normalize, the default; reloaded by --resume)

The evaluation runs the deterministic policy with the shield kept in place
and reports the success rate over ``--eval-episodes`` episodes, on the
*validation* environments of the run (:mod:`train.seeding`: every run seed
has its own independent streams for training, validation and held-out test
environments; the benchmark ``train.islands`` scores on the test streams,
which this script never draws from). ``--resume RUN_DIR`` loads ``model.zip``
and ``config.json``, trains ``--total-steps`` more steps (appending to the
monitor logs, with fresh streams for the new segment) and rewrites
``eval.json``.

Examples::

    python -m train.ppo islands --shield smart --reward sparse --total-steps 200000
    python -m train.ppo islands --total-steps 50000 \
        --resume runs/IslandsBridges-v0__smart__1__<time>
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

import envs  # noqa: F401  (registers ihm/IslandsBridges-v0 and ihm/IslandsBridgesRing-v0)
from train.evaluation import evaluate_success
from train.options import build_parser, opt
from train.sb3 import learning_rate, new_ppo, normalizer, option_problems, progress_bar
from train.seeding import EnvSeeds, RunSeeds
from train.trainer import Run, Task, train

__all__ = [
    "REWARDS",
    "SHIELDS",
    "TASK",
    "Config",
    "IslandsTask",
    "TrainStats",
    "build_envs",
    "build_model",
    "main",
    "make_env",
    "make_eval_envs",
    "make_vec_env",
    "parse_config",
    "run_name",
    "shield_wrapper",
    "train_callbacks",
]

PROG = "python -m train.ppo islands"

SHIELDS = ("none", "simple", "smart")
REWARDS = ("dense", "sparse")


@dataclass
class Config:
    """Everything a training run depends on; saved as config.json."""

    env_id: str = opt(
        "ihm/IslandsBridges-v0",
        "Gymnasium id of the environment (ihm/IslandsBridges-v0: five islands with a dead end; "
        "ihm/IslandsBridgesRing-v0: the four-island ring)",
    )
    shield: str = opt("none", "shield around the env (kept for evaluation)", choices=SHIELDS)
    reward: str = opt("dense", "reward mode passed to the env as reward=...", choices=REWARDS)
    total_steps: int = opt(200_000, "env steps to train (with --resume: steps to add)")
    seed: int = opt(
        1,
        "run seed (>= 0): root of independent streams for training, validation and test envs "
        "and for python/numpy/torch (train.seeding)",
    )
    n_envs: int = opt(8, "parallel training envs (one Monitor CSV each)")
    subproc: bool = opt(False, "run the training envs in subprocesses (SubprocVecEnv)")
    pi: list[int] = opt([64, 64], "hidden layer sizes of the policy net")
    vf: list[int] = opt([64, 64], "hidden layer sizes of the value net (a separate net)")
    learning_rate: float = opt(
        3e-4, "Adam learning rate (the initial one with --lr-schedule linear)"
    )
    lr_schedule: str = opt(
        "constant",
        "learning rate over training: constant, or linear decay to 0 at --total-steps",
        choices=("constant", "linear"),
    )
    n_steps: int = opt(128, "rollout length per env (rollout = n_steps * n_envs samples)")
    batch_size: int = opt(128, "minibatch size of the PPO update")
    n_epochs: int = opt(20, "PPO epochs per rollout")
    gamma: float = opt(0.98, "discount factor")
    gae_lambda: float = opt(0.95, "GAE lambda")
    clip_range: float = opt(0.2, "PPO clipping range")
    ent_coef: float = opt(0.01, "entropy bonus coefficient")
    log_std_init: float = opt(-0.5, "initial log std of the Gaussian policy")
    normalize: bool = opt(
        True,
        "VecNormalize the observations (running mean and std; saved as vecnormalize.pkl, "
        "frozen for evaluation)",
    )
    norm_reward: bool = opt(
        True, "with --normalize, also scale rewards by the std of the discounted return"
    )
    eval_episodes: int = opt(200, "episodes of the final evaluation (deterministic, shielded)")
    out: str = opt("runs", "directory that receives the run directory")
    resume: str | None = opt(None, "run directory to continue (loads model.zip and config.json)")
    progress: bool = opt(True, "show a tqdm progress bar")
    verbose: int = opt(0, "SB3 verbosity (1 prints the logger table every rollout)")


def parse_config(argv: Sequence[str] | None = None) -> Config:
    """Parse the command line into a :class:`Config` (argparse exits with 2 on bad options)."""
    parser = build_parser(Config, PROG, (__doc__ or "").split("\n\n")[0])
    args = parser.parse_args(argv)
    cfg = Config(**vars(args))
    problems = option_problems(cfg, ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs"))
    if cfg.eval_episodes < 0:
        problems.append("--eval-episodes must be >= 0")
    if problems:
        parser.error("; ".join(problems))
    return cfg


def shield_wrapper(name: str) -> Callable[[gym.Env], gym.Env] | None:
    """The wrapper class for ``--shield`` (None for ``none``)."""
    if name not in SHIELDS:
        raise ValueError(f"unknown shield {name!r}; choose one of {SHIELDS}")
    if name == "none":
        return None
    import shields

    return {"simple": shields.SimpleShield, "smart": shields.SmartShield}[name]


def make_env(
    cfg: Config,
    seeds: EnvSeeds | None = None,
    monitor_file: str | None = None,
    append: bool = False,
    shield: str | None = None,
    monitor: bool = True,
) -> Callable[[], gym.Env]:
    """A thunk that builds one env with the whole wrapper stack.

    ``gym.make`` (with its TimeLimit) -> shield (``shield``, default ``cfg.shield``) ->
    Monitor (episode return, length and ``is_success``, written to ``monitor_file`` when
    given, appended to it when ``append``; left out with ``monitor=False``). With ``seeds``
    the env is reset once with ``seeds.reset`` and its action space seeded with
    ``seeds.action_space``; every later reset continues that generator (the VecEnv passes
    no seeds).
    """
    shield_name = cfg.shield if shield is None else shield

    def thunk() -> gym.Env:
        env = gym.make(cfg.env_id, reward=cfg.reward)
        wrapper = shield_wrapper(shield_name)
        if wrapper is not None:
            env = wrapper(env)
        if monitor:
            env = Monitor(
                env,
                filename=monitor_file,
                info_keywords=("is_success",),
                override_existing=not append,
            )
        if seeds is not None:
            env.reset(seed=seeds.reset)
            env.action_space.seed(seeds.action_space)
        return env

    return thunk


def make_vec_env(
    cfg: Config,
    seeds: Sequence[EnvSeeds],
    monitor_dir: Path | None = None,
    append: bool = False,
) -> VecEnv:
    """One :func:`make_env` per entry of ``seeds`` in a Dummy (or Subproc) VecEnv."""
    thunks = [
        make_env(cfg, s, str(monitor_dir / str(i)) if monitor_dir else None, append)
        for i, s in enumerate(seeds)
    ]
    return SubprocVecEnv(thunks) if cfg.subproc and len(thunks) > 1 else DummyVecEnv(thunks)


def build_envs(
    cfg: Config, seeds: RunSeeds, monitor_dir: Path | None = None, stats: Path | None = None
) -> VecEnv:
    """The training VecEnv of a run: ``cfg.n_envs`` envs on the run's ``train`` streams.

    Monitor CSVs go to ``monitor_dir`` (appended to when ``stats`` is given, i.e. on resume).
    With ``cfg.normalize`` it is a ``VecNormalize`` (observations, and with ``cfg.norm_reward``
    rewards scaled by the std of the discounted return; loaded from ``stats`` when that file
    exists). Evaluation envs come from :func:`make_eval_envs` and see the same observation
    statistics through :func:`normalizer`.
    """
    resume = stats is not None
    train_env = make_vec_env(cfg, seeds.envs("train", cfg.n_envs), monitor_dir, append=resume)
    if cfg.normalize:
        if stats is not None and stats.is_file():
            train_env = VecNormalize.load(str(stats), train_env)
        else:
            train_env = VecNormalize(train_env, norm_reward=cfg.norm_reward, gamma=cfg.gamma)
    return train_env


def make_eval_envs(
    cfg: Config, seeds: RunSeeds, stream: str, n: int, shield: str | None = None
) -> list[gym.Env]:
    """``n`` plain envs (no Monitor) on the ``validation`` or ``test`` streams of a run.

    ``shield`` overrides ``cfg.shield`` (``"none"`` evaluates a shielded policy without its
    shield). Envs built from the same ``(seeds, stream, n)`` draw the same episodes in the same
    order, whatever the shield: evaluations on them are paired.
    """
    if stream not in ("validation", "test"):
        raise ValueError(f"evaluation stream must be 'validation' or 'test', got {stream!r}")
    return [make_env(cfg, s, shield=shield, monitor=False)() for s in seeds.envs(stream, n)]


def train_callbacks(cfg: Config, desc: str = "") -> list[BaseCallback]:
    """Training statistics (success and shield intervention rates) and the progress bar."""
    callbacks: list[BaseCallback] = [TrainStats()]
    if cfg.progress:
        callbacks.append(progress_bar(cfg, desc))
    return callbacks


def run_name(cfg: Config) -> str:
    """``{env}__{shield}__{seed}__{time}``, env without its namespace."""
    env = cfg.env_id.split(":")[-1].split("/")[-1]
    return f"{env}__{cfg.shield}__{cfg.seed}__{time.strftime('%Y%m%d-%H%M%S')}"


def build_model(cfg: Config, vec_env: VecEnv) -> PPO:
    """A fresh PPO with separate policy and value nets of the configured sizes
    (:func:`train.sb3.new_ppo`: ``seed=None``, call :func:`train.sb3.seed_everything` first)."""
    return new_ppo(cfg, vec_env, learning_rate(cfg))


class TrainStats(BaseCallback):
    """Training-episode statistics: the thesis' measure of a shielded stochastic policy.

    Logs ``charts/success_rate`` (training episodes that ended in the rollout) and
    ``shield/intervention_rate`` per rollout, and keeps every finished training episode in
    :attr:`episodes` as ``(step, success, failure, length)``, ``step`` being the run's
    ``num_timesteps`` when it ended.
    """

    def __init__(self) -> None:
        super().__init__()
        self.episodes: list[tuple[int, bool, bool, int]] = []

    def _on_rollout_start(self) -> None:
        self.successes: list[bool] = []
        self.steps = self.interventions = 0

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            self.steps += 1
            self.interventions += bool(info.get("shield_intervened", False))
            if done:
                success = bool(info.get("is_success", False))
                self.successes.append(success)
                length = int(info["episode"]["l"]) if "episode" in info else -1
                self.episodes.append(
                    (int(self.num_timesteps), success, bool(info.get("failure", False)), length)
                )
        return True

    def _on_rollout_end(self) -> None:
        if self.successes:
            self.logger.record("charts/success_rate", float(np.mean(self.successes)))
        self.logger.record("shield/intervention_rate", self.interventions / max(self.steps, 1))


class IslandsTask(Task):
    """PPO on the islands-and-bridges toy as a :class:`train.trainer.Task` (module doc)."""

    name = "islands"

    def parse(self, argv: Sequence[str]) -> Config:
        return parse_config(argv)

    def run_name(self, cfg: Config) -> str:
        return run_name(cfg)

    def resume_options(self, cfg: Config, argv: Sequence[str]) -> tuple[str, ...]:
        return ("total_steps", "eval_episodes", "progress", "verbose")

    def threads(self, cfg: Config) -> int:
        return 1  # small MLPs: threads cost more than they give on 2 cores

    def train_env(self, cfg: Config, seeds: RunSeeds, run_dir: Path) -> VecEnv:
        stats = run_dir / "vecnormalize.pkl" if cfg.resume is not None else None
        return build_envs(cfg, seeds, run_dir / "monitor", stats)  # "train" streams

    def eval_envs(self, cfg: Config, seeds: RunSeeds) -> list[gym.Env]:
        n_eval = min(cfg.n_envs, max(cfg.eval_episodes, 1))
        return make_eval_envs(cfg, seeds, "validation", n_eval)

    def new_model(self, cfg: Config, vec: VecEnv) -> PPO:
        return build_model(cfg, vec)

    def callbacks(self, cfg: Config, run_dir: Path, evals: Any) -> list[BaseCallback]:
        return [TrainStats()]

    def evaluate(self, run: Run, train_seconds: float) -> dict[str, Any]:
        """The success rate of the deterministic, shielded policy on the validation envs
        (:func:`train.evaluation.evaluate_success`) with the run's size and settings."""
        cfg = run.cfg
        t0 = time.perf_counter()
        norm = normalizer(run.vec)
        result = evaluate_success(run.model, run.evals, cfg.eval_episodes, normalize=norm)
        result.update(
            num_timesteps=int(run.model.num_timesteps),
            train_seconds=round(train_seconds, 2),
            eval_seconds=round(time.perf_counter() - t0, 2),
            deterministic=True,
            stream="validation",
            shield=cfg.shield,
            reward=cfg.reward,
        )
        return result

    def summary(self, run: Run, result: dict[str, Any], train_seconds: float) -> str:
        return (
            f"{run.dir}: {result['num_timesteps']} steps, success rate "
            f"{result['success_rate']:.3f} over {result['episodes']} episodes "
            f"(deterministic, shield {run.cfg.shield}), failure rate "
            f"{result['failure_rate']:.3f}, shield intervention rate "
            f"{result['intervention_rate']:.3f}; train {train_seconds:.1f} s"
        )


TASK = IslandsTask()


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """``python -m train.ppo islands``: train (or resume), evaluate, save
    (:func:`train.trainer.train` with :data:`TASK`); returns the evaluation dict."""
    return train(TASK, argv)
