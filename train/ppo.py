"""PPO (stable-baselines3) on a shielded Gymnasium env: ``python -m train.ppo``.

CleanRL shape, SB3 algorithm: one :class:`Config` dataclass (every field is a
command-line option, ``--help`` lists them), one :func:`make_env` thunk with
the whole wrapper stack, the seeds set in one block, runs named
``{env}__{shield}__{seed}__{time}`` under ``--out``.

A run directory holds::

    model.zip           the PPO model (policy, value net, optimiser, num_timesteps)
    config.json         the Config of the run
    monitor/N.monitor.csv  one Monitor log per training env (r, l, t, is_success)
    eval.json           the final evaluation (see :func:`evaluate`)
    progress.csv        SB3's logger (losses/, charts/, shield/ keys)
    vecnormalize.pkl    VecNormalize statistics (--normalize, the default; reloaded by --resume)

The evaluation runs the deterministic policy with the shield kept in place
(as the thesis does) and reports the success rate over ``--eval-episodes``
episodes. ``--resume RUN_DIR`` loads ``model.zip`` and ``config.json``,
trains ``--total-steps`` more steps (appending to the monitor logs) and
rewrites ``eval.json``.

Examples::

    python -m train.ppo --shield smart --reward sparse --total-steps 200000
    python -m train.ppo --total-steps 50000 --resume runs/IslandsBridges-v0__smart__1__<time>
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import random
import sys
import time
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize
from tqdm import tqdm

import envs  # noqa: F401  (registers ihm/IslandsBridges-v0)

__all__ = [
    "SHIELDS",
    "Config",
    "TrainStats",
    "TqdmProgress",
    "build_envs",
    "build_model",
    "evaluate",
    "main",
    "make_env",
    "make_vec_env",
    "parse_config",
    "run_name",
    "seed_everything",
    "train_callbacks",
]

SHIELDS = ("none", "simple", "smart")
REWARDS = ("dense", "sparse")


def opt(default: Any, help: str, **kw: Any) -> Any:
    """A dataclass field with its ``--help`` text (and argparse extras such as choices)."""
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata={"help": help, **kw})
    return field(default=default, metadata={"help": help, **kw})


@dataclass
class Config:
    """Everything a training run depends on; saved as config.json."""

    env_id: str = opt("ihm/IslandsBridges-v0", "Gymnasium id of the environment")
    shield: str = opt("none", "shield around the env (kept for evaluation)", choices=SHIELDS)
    reward: str = opt("dense", "reward mode passed to the env as reward=...", choices=REWARDS)
    total_steps: int = opt(200_000, "env steps to train (with --resume: steps to add)")
    seed: int = opt(1, "seed of python, numpy, torch, env resets and action spaces")
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


def _type_of(f: dataclasses.Field) -> tuple[Callable[[str], Any], bool]:
    """The scalar argparse ``type`` of a field and whether it is a list."""
    t = str(f.type)
    if t.startswith("list["):
        return {"list[int]": int, "list[float]": float}.get(t, str), True
    for name, conv in (("bool", bool), ("int", int), ("float", float)):
        if t == name:
            return conv, False
    return str, False


def build_parser(
    cls: type = Config, prog: str = "python -m train.ppo", description: str | None = None
) -> argparse.ArgumentParser:
    """An argparse parser generated from the fields of a dataclass (``Config`` by default).

    Each field ``foo_bar`` becomes ``--foo-bar`` with the field's ``help`` and
    ``choices`` metadata; bools become ``--x/--no-x``, lists take several values.
    """
    p = argparse.ArgumentParser(
        prog=prog,
        description=description or (__doc__ or "").split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        conv, is_list = _type_of(f)
        default = f.default_factory() if f.default is dataclasses.MISSING else f.default
        kw: dict[str, Any] = {"help": f.metadata["help"], "default": default, "dest": f.name}
        if "choices" in f.metadata:
            kw["choices"] = f.metadata["choices"]
        if conv is bool:
            p.add_argument(flag, action=argparse.BooleanOptionalAction, **kw)
        elif is_list:
            p.add_argument(flag, type=conv, nargs="+", metavar="N" if conv is int else None, **kw)
        else:
            p.add_argument(flag, type=conv, **kw)
    return p


def parse_config(argv: Sequence[str] | None = None) -> Config:
    """Parse the command line into a :class:`Config` (argparse exits with 2 on bad options)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    cfg = Config(**vars(args))
    problems = [
        f"--{name.replace('_', '-')} must be >= 1"
        for name in ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs")
        if getattr(cfg, name) < 1
    ]
    problems += [f"--{k}: sizes must be >= 1" for k in ("pi", "vf") if min(getattr(cfg, k)) < 1]
    if cfg.eval_episodes < 0:
        problems.append("--eval-episodes must be >= 0")
    if cfg.resume is not None and not (Path(cfg.resume) / "model.zip").is_file():
        problems.append(f"--resume {cfg.resume}: no model.zip there")
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


def make_env(cfg: Config, seed: int, monitor_file: str | None = None, append: bool = False):
    """A thunk that builds one env with the whole wrapper stack.

    ``gym.make`` (with its TimeLimit) -> shield (``--shield``) -> Monitor
    (episode return, length and ``is_success``, written to ``monitor_file``
    when given, appended to it when ``append``). The action space is seeded
    with ``seed``; the reset seeds come from the VecEnv (``vec_env.seed``).
    """

    def thunk() -> gym.Env:
        env = gym.make(cfg.env_id, reward=cfg.reward)
        shield = shield_wrapper(cfg.shield)
        if shield is not None:
            env = shield(env)
        env = Monitor(
            env, filename=monitor_file, info_keywords=("is_success",), override_existing=not append
        )
        env.action_space.seed(seed)
        return env

    return thunk


def make_vec_env(
    cfg: Config, seed: int, n_envs: int, monitor_dir: Path | None = None, append: bool = False
) -> VecEnv:
    """``n_envs`` copies of :func:`make_env` in a Dummy (or Subproc) VecEnv, reset seeds set."""
    thunks = [
        make_env(cfg, seed + i, str(monitor_dir / str(i)) if monitor_dir else None, append)
        for i in range(n_envs)
    ]
    vec: VecEnv = SubprocVecEnv(thunks) if cfg.subproc and n_envs > 1 else DummyVecEnv(thunks)
    vec.seed(seed)  # env i gets reset seed seed + i on its first reset
    return vec


def build_envs(
    cfg: Config, seed: int, monitor_dir: Path | None = None, stats: Path | None = None
) -> tuple[VecEnv, VecEnv]:
    """The training and evaluation VecEnvs of a run (both with the full :func:`make_env` stack).

    Training: ``cfg.n_envs`` envs, reset seeds ``seed + i``, Monitor CSVs in ``monitor_dir``
    (appended to when ``stats`` is given, i.e. on resume). Evaluation: ``min(n_envs,
    eval_episodes)`` envs seeded from ``seed + 1_000_000``. With ``cfg.normalize`` the training
    env is a ``VecNormalize`` (observations and discounted-return reward scaling; loaded from
    ``stats`` when that file exists) and the evaluation env a frozen ``VecNormalize`` that shares
    the training env's observation statistics and returns raw rewards.
    """
    resume = stats is not None
    train_env = make_vec_env(cfg, seed, cfg.n_envs, monitor_dir, append=resume)
    eval_env = make_vec_env(cfg, seed + 1_000_000, min(cfg.n_envs, max(cfg.eval_episodes, 1)))
    if cfg.normalize:
        if stats is not None and stats.is_file():
            train_env = VecNormalize.load(str(stats), train_env)
        else:
            train_env = VecNormalize(train_env, norm_reward=cfg.norm_reward, gamma=cfg.gamma)
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False)
        eval_env.obs_rms = train_env.obs_rms  # the same object: updated as training goes on
    return train_env, eval_env


def train_callbacks(cfg: Config, desc: str = "") -> list[BaseCallback]:
    """Training statistics (success and shield intervention rates) and the progress bar."""
    callbacks: list[BaseCallback] = [TrainStats()]
    if cfg.progress:
        rollout = cfg.n_steps * cfg.n_envs  # learn() stops at the first rollout end past the budget
        total = -(-cfg.total_steps // rollout) * rollout
        callbacks.append(TqdmProgress(total, desc=desc))
    return callbacks


def seed_everything(seed: int) -> None:
    """Python, numpy and torch RNGs (env and action-space seeds are set where they are built)."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002  (SB3 and Gymnasium wrappers may use the global RNG)
    torch.manual_seed(seed)
    torch.backends.cudnn.deterministic = True


def run_name(cfg: Config) -> str:
    """``{env}__{shield}__{seed}__{time}``, env without its namespace."""
    env = cfg.env_id.split(":")[-1].split("/")[-1]
    return f"{env}__{cfg.shield}__{cfg.seed}__{time.strftime('%Y%m%d-%H%M%S')}"


def build_model(cfg: Config, vec_env: VecEnv) -> PPO:
    """A fresh PPO with separate policy and value nets of the configured sizes."""
    return PPO(
        "MlpPolicy",
        vec_env,
        learning_rate=(
            cfg.learning_rate
            if cfg.lr_schedule == "constant"
            else LinearSchedule(cfg.learning_rate, 0.0, 1.0)
        ),
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
        },
        seed=cfg.seed,
        device="cpu",
        verbose=cfg.verbose,
    )


def evaluate(model: PPO, vec_env: VecEnv, n_episodes: int) -> dict[str, float]:
    """Success rate of the deterministic policy over ``n_episodes`` episodes.

    ``vec_env`` should carry the same shield as training (the thesis keeps it
    in place). Env ``i`` of ``k`` runs ``(n_episodes + i) // k`` episodes, so
    short episodes are not over-counted. Returns ``success_rate``,
    ``failure_rate`` (``info["failure"]``), ``mean_return``, ``mean_length``,
    ``intervention_rate`` (fraction of steps where the shield changed the
    action; 0 without a shield) and ``episodes``.
    """
    k = vec_env.num_envs
    targets = np.array([(n_episodes + i) // k for i in range(k)])
    counts = np.zeros(k, dtype=int)
    ret = np.zeros(k)
    length = np.zeros(k, dtype=int)
    succ, fail, rets, lens = [], [], [], []
    steps = interventions = 0
    obs = vec_env.reset()
    while (counts < targets).any():
        action, _ = model.predict(obs, deterministic=True)
        obs, rew, done, infos = vec_env.step(action)
        for i in range(k):
            if counts[i] >= targets[i]:
                continue
            ret[i] += rew[i]
            length[i] += 1
            steps += 1
            interventions += bool(infos[i].get("shield_intervened", False))
            if done[i]:
                succ.append(bool(infos[i].get("is_success", False)))
                fail.append(bool(infos[i].get("failure", False)))
                rets.append(float(ret[i]))
                lens.append(int(length[i]))
                counts[i] += 1
                ret[i], length[i] = 0.0, 0
    mean = lambda xs: float(np.mean(xs)) if xs else float("nan")  # noqa: E731
    return {
        "episodes": len(succ),
        "success_rate": mean(succ),
        "failure_rate": mean(fail),
        "mean_return": mean(rets),
        "mean_length": mean(lens),
        "intervention_rate": interventions / steps if steps else 0.0,
    }


class TrainStats(BaseCallback):
    """Logs ``charts/success_rate`` (training episodes) and ``shield/intervention_rate``."""

    def _on_rollout_start(self) -> None:
        self.successes: list[bool] = []
        self.steps = self.interventions = 0

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            self.steps += 1
            self.interventions += bool(info.get("shield_intervened", False))
            if done:
                self.successes.append(bool(info.get("is_success", False)))
        return True

    def _on_rollout_end(self) -> None:
        if self.successes:
            self.logger.record("charts/success_rate", float(np.mean(self.successes)))
        self.logger.record("shield/intervention_rate", self.interventions / max(self.steps, 1))


class TqdmProgress(BaseCallback):
    """A plain tqdm progress bar over env steps (SB3's own bar needs ``rich``)."""

    def __init__(self, total: int, desc: str = "") -> None:
        super().__init__()
        self.total, self.desc = total, desc

    def _on_training_start(self) -> None:
        self.bar = tqdm(total=self.total, desc=self.desc, unit="step", dynamic_ncols=True)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Train (or resume), evaluate, save; returns the evaluation dict."""
    cfg = parse_config(argv)
    torch.set_num_threads(1)  # small MLPs: threads cost more than they give on 2 cores

    if cfg.resume is not None:
        run_dir = Path(cfg.resume)
        saved = json.loads((run_dir / "config.json").read_text())
        # the saved run decides everything except how long to go on and how to report
        cfg = dataclasses.replace(
            Config(**{k: v for k, v in saved.items() if k in Config.__dataclass_fields__}),
            total_steps=cfg.total_steps,
            eval_episodes=cfg.eval_episodes,
            progress=cfg.progress,
            verbose=cfg.verbose,
            resume=cfg.resume,
        )
    else:
        run_dir = Path(cfg.out) / run_name(cfg)
        while run_dir.exists():  # two runs started in the same second
            run_dir = run_dir.with_name(run_dir.name + "_")
        run_dir.mkdir(parents=True)
        config = {**dataclasses.asdict(cfg), "resume": None}
        (run_dir / "config.json").write_text(json.dumps(config, indent=2) + "\n")

    # ---- seeds, all in one place ------------------------------------------------------------
    done_steps = 0
    if cfg.resume is not None:
        with zipfile.ZipFile(run_dir / "model.zip") as z:
            done_steps = int(json.loads(z.read("data"))["num_timesteps"])
    # a resumed run draws fresh episodes: its seeds are offset by the steps already done
    seed = cfg.seed + done_steps
    seed_everything(seed)  # random, numpy, torch
    stats = run_dir / "vecnormalize.pkl" if cfg.resume is not None else None
    train_env, eval_env = build_envs(cfg, seed, run_dir / "monitor", stats)
    # PPO(seed=...) / set_random_seed re-seeds random, numpy, torch and the action space
    # -----------------------------------------------------------------------------------------

    if cfg.resume is not None:
        model = PPO.load(run_dir / "model.zip", env=train_env, device="cpu")
        model.set_random_seed(seed)
    else:
        model = build_model(cfg, train_env)
    model.set_logger(configure(str(run_dir), ["csv"] + (["stdout"] if cfg.verbose else [])))

    callbacks = train_callbacks(cfg, desc=run_dir.name)
    t0 = time.perf_counter()
    model.learn(cfg.total_steps, callback=callbacks, reset_num_timesteps=cfg.resume is None)
    train_s = time.perf_counter() - t0
    model.save(run_dir / "model.zip")
    if isinstance(train_env, VecNormalize):
        train_env.save(str(run_dir / "vecnormalize.pkl"))

    t0 = time.perf_counter()
    result = evaluate(model, eval_env, cfg.eval_episodes)
    result.update(
        num_timesteps=int(model.num_timesteps),
        train_seconds=round(train_s, 2),
        eval_seconds=round(time.perf_counter() - t0, 2),
        deterministic=True,
        shield=cfg.shield,
        reward=cfg.reward,
    )
    (run_dir / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
    train_env.close()
    eval_env.close()
    print(
        f"{run_dir}: {result['num_timesteps']} steps, success rate "
        f"{result['success_rate']:.3f} over {result['episodes']} episodes "
        f"(deterministic, shield {cfg.shield}), failure rate {result['failure_rate']:.3f}, "
        f"shield intervention rate {result['intervention_rate']:.3f}; "
        f"train {train_s:.1f} s"
    )
    return {**result, "run_dir": str(run_dir)}


if __name__ == "__main__":
    main(sys.argv[1:])
