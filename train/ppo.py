"""PPO (stable-baselines3): ``python -m train.ppo`` (the main job).

With no arguments it trains the four-finger in-hand rotation policy of thesis
ch. 7 (:mod:`train.rotate`, ``python -m train.ppo --help`` lists its options).
``python -m train.ppo islands [options]`` runs this module's trainer on a
shielded islands-and-bridges env, documented below.

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

import envs  # noqa: F401  (registers ihm/IslandsBridges-v0 and ihm/IslandsBridgesRing-v0)
from train.seeding import EnvSeeds, RunSeeds

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
    "make_eval_envs",
    "make_vec_env",
    "new_ppo",
    "normalizer",
    "open_run",
    "option_problems",
    "parse_config",
    "progress_bar",
    "run_name",
    "saved_timesteps",
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
    problems = option_problems(cfg, ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs"))
    if cfg.eval_episodes < 0:
        problems.append("--eval-episodes must be >= 0")
    if problems:
        parser.error("; ".join(problems))
    return cfg


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


def open_run(cfg: Any, name: str, keep: Sequence[str]) -> tuple[Any, Path]:
    """The config and directory of a run.

    With ``cfg.resume``: the saved config.json of that run, except the fields ``keep`` (and
    ``resume``), which come from ``cfg`` (the saved run decides everything except how long
    to go on and how to report). Otherwise a new directory ``cfg.out/name`` (``_`` appended
    while it exists) with ``cfg`` written to config.json.
    """
    cls = type(cfg)
    if cfg.resume is not None:
        run_dir = Path(cfg.resume)
        saved = json.loads((run_dir / "config.json").read_text())
        fields = cls.__dataclass_fields__
        restored = cls(**{k: v for k, v in saved.items() if k in fields})
        return dataclasses.replace(
            restored, resume=cfg.resume, **{k: getattr(cfg, k) for k in keep}
        ), run_dir
    run_dir = Path(cfg.out) / name
    while run_dir.exists():  # two runs started in the same second
        run_dir = run_dir.with_name(run_dir.name + "_")
    run_dir.mkdir(parents=True)
    config = {**dataclasses.asdict(cfg), "resume": None}
    (run_dir / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    return cfg, run_dir


def saved_timesteps(run_dir: Path) -> int:
    """``num_timesteps`` of the PPO model saved in ``run_dir/model.zip``."""
    with zipfile.ZipFile(run_dir / "model.zip") as z:
        return int(json.loads(z.read("data"))["num_timesteps"])


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


def normalizer(train_env: VecEnv) -> Callable[[np.ndarray], np.ndarray] | None:
    """The training env's observation normalisation (frozen: it does not update the statistics),
    or ``None`` without ``VecNormalize``."""
    return train_env.normalize_obs if isinstance(train_env, VecNormalize) else None


def train_callbacks(cfg: Config, desc: str = "") -> list[BaseCallback]:
    """Training statistics (success and shield intervention rates) and the progress bar."""
    callbacks: list[BaseCallback] = [TrainStats()]
    if cfg.progress:
        callbacks.append(progress_bar(cfg, desc))
    return callbacks


def progress_bar(cfg: Any, desc: str = "") -> TqdmProgress:
    """A :class:`TqdmProgress` over the steps ``learn(cfg.total_steps)`` will take: it stops at
    the first rollout end past the budget."""
    rollout = cfg.n_steps * cfg.n_envs
    return TqdmProgress(-(-cfg.total_steps // rollout) * rollout, desc=desc)


def seed_everything(seed: int) -> None:
    """Python, numpy's legacy global generator and torch (envs are seeded where they are built).

    Call with :attr:`train.seeding.RunSeeds.global_seed`.
    """
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002  (SB3 and Gymnasium wrappers may use the global RNG)
    torch.manual_seed(seed)
    torch.backends.cudnn.deterministic = True


def run_name(cfg: Config) -> str:
    """``{env}__{shield}__{seed}__{time}``, env without its namespace."""
    env = cfg.env_id.split(":")[-1].split("/")[-1]
    return f"{env}__{cfg.shield}__{cfg.seed}__{time.strftime('%Y%m%d-%H%M%S')}"


def build_model(cfg: Config, vec_env: VecEnv) -> PPO:
    """A fresh PPO with separate policy and value nets of the configured sizes.

    ``PPO(seed=None)``: SB3's own seeding would reset the envs with ``seed + i`` (the VecEnv's
    consecutive seeds), undoing :mod:`train.seeding`; call :func:`seed_everything` first (the
    policy's initial weights come from torch's global generator).
    """
    learning_rate = (
        cfg.learning_rate
        if cfg.lr_schedule == "constant"
        else LinearSchedule(cfg.learning_rate, 0.0, 1.0)
    )
    return new_ppo(cfg, vec_env, learning_rate)


def new_ppo(
    cfg: Any,
    vec_env: VecEnv,
    learning_rate: float | Callable[[float], float],
    algo: type[PPO] = PPO,
) -> PPO:
    """SB3 PPO (or the subclass ``algo``) from a config's settings: separate policy and value
    nets ``cfg.pi``/``cfg.vf``, ``seed=None`` (see :func:`build_model`), CPU."""
    return algo(
        "MlpPolicy",
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
        },
        seed=None,
        device="cpu",
        verbose=cfg.verbose,
    )


def evaluate(
    model: PPO,
    eval_envs: Sequence[gym.Env],
    n_episodes: int,
    *,
    deterministic: bool = True,
    normalize: Callable[[np.ndarray], np.ndarray] | None = None,
    stop_cycles: bool = True,
) -> dict[str, float]:
    """Success rate of the policy over ``n_episodes`` episodes on the plain envs ``eval_envs``.

    Env ``i`` of ``k`` runs ``(n_episodes + i) // k`` episodes (so short episodes are not
    over-counted); the policy is queried for all running envs at once, on observations passed
    through ``normalize`` (:func:`normalizer`). Build ``eval_envs`` with :func:`make_eval_envs`
    (shielded or not); the shield is part of each env.

    ``stop_cycles`` (deterministic policy only, envs that expose ``unwrapped.state`` and have
    a time limit): an episode whose state repeats has entered a cycle, which it can only
    leave by truncation, so it is completed without stepping on: not a success, not a
    failure, length = the time limit, return and shield interventions those of the cycle
    repeated up to the limit. This is exact for an env and shield that are deterministic
    functions of ``state`` (and the episode's goal) and a policy that maps equal observations
    to equal actions (the islands world; the simple shield's zero step is such a fixed
    point), and saves running frozen episodes to the limit. One caveat: the policy is queried
    on batches whose size changes as envs finish, and a CPU matrix product may round one row
    differently in a batch of another size; a cycle that a last-bit difference would break
    is then stopped. Tests compare both ways on trained and scripted policies.

    Returns ``episodes``, ``successes``, ``failures``, ``success_rate``, ``failure_rate``
    (``info["failure"]``), ``mean_return``, ``mean_length``, ``intervention_rate`` (fraction
    of steps where the shield changed the action; 0 without a shield) and ``cycles_stopped``.
    """
    k = len(eval_envs)
    if k == 0 and n_episodes > 0:
        raise ValueError("evaluate needs at least one env")
    targets = [(n_episodes + i) // k for i in range(k)] if k else []
    counts = [0] * k
    succ: list[bool] = []
    fail: list[bool] = []
    rets: list[float] = []
    lens: list[int] = []
    steps = interventions = cycles = 0
    can_stop = [
        stop_cycles
        and deterministic
        and hasattr(env.unwrapped, "state")
        and env.spec is not None
        and env.spec.max_episode_steps is not None
        for env in eval_envs
    ]
    obs: list[Any] = [None] * k
    rewards: list[list[float]] = [[] for _ in range(k)]  # per step of the current episode
    shielded: list[list[bool]] = [[] for _ in range(k)]
    seen: list[dict[bytes, int]] = [{} for _ in range(k)]  # state -> steps taken when there

    def start(i: int) -> None:
        obs[i], _ = eval_envs[i].reset()
        rewards[i], shielded[i] = [], []
        seen[i] = {np.asarray(eval_envs[i].unwrapped.state).tobytes(): 0} if can_stop[i] else {}

    def finish(i: int, success: bool, failure: bool, ret: float, length: int, n_int: int) -> None:
        nonlocal steps, interventions
        succ.append(success)
        fail.append(failure)
        rets.append(ret)
        lens.append(length)
        steps += length
        interventions += n_int
        counts[i] += 1
        if counts[i] < targets[i]:
            start(i)

    for i in range(k):
        if targets[i] > 0:
            start(i)
    while True:
        active = [i for i in range(k) if counts[i] < targets[i]]
        if not active:
            break
        batch = np.stack([obs[i] for i in active])
        if normalize is not None:
            batch = normalize(batch)
        actions, _ = model.predict(batch, deterministic=deterministic)
        for j, i in enumerate(active):
            obs[i], reward, terminated, truncated, info = eval_envs[i].step(actions[j])
            rewards[i].append(float(reward))
            shielded[i].append(bool(info.get("shield_intervened", False)))
            t = len(rewards[i])
            if terminated or truncated:
                finish(
                    i,
                    bool(info.get("is_success", False)),
                    bool(info.get("failure", False)),
                    float(np.sum(rewards[i])),
                    t,
                    sum(shielded[i]),
                )
                continue
            if not can_stop[i]:
                continue
            key = np.asarray(eval_envs[i].unwrapped.state).tobytes()
            first = seen[i].setdefault(key, t)
            if first == t:
                continue
            # steps first+1 .. t form a cycle; repeat it up to the time limit
            limit = int(eval_envs[i].spec.max_episode_steps)
            period = t - first
            cyc_r, cyc_s = rewards[i][first:], shielded[i][first:]
            rest = range(limit - t)
            cycles += 1
            finish(
                i,
                False,
                False,
                float(np.sum(rewards[i] + [cyc_r[m % period] for m in rest])),
                limit,
                sum(shielded[i]) + sum(cyc_s[m % period] for m in rest),
            )
    mean = lambda xs: float(np.mean(xs)) if xs else float("nan")  # noqa: E731
    return {
        "episodes": len(succ),
        "successes": int(np.sum(succ)),
        "failures": int(np.sum(fail)),
        "success_rate": mean(succ),
        "failure_rate": mean(fail),
        "mean_return": mean(rets),
        "mean_length": mean(lens),
        "intervention_rate": interventions / steps if steps else 0.0,
        "cycles_stopped": cycles,
    }


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

    cfg, run_dir = open_run(
        cfg, run_name(cfg), keep=("total_steps", "eval_episodes", "progress", "verbose")
    )

    # ---- seeds, all in one place (train.seeding) ---------------------------------------------
    done_steps = saved_timesteps(run_dir) if cfg.resume is not None else 0
    # a resumed run is a new segment of the seed tree: fresh episodes, no repeated streams
    seeds = RunSeeds(cfg.seed, segment=done_steps)
    seed_everything(seeds.global_seed)  # random, numpy, torch (initial weights, sampling)
    stats = run_dir / "vecnormalize.pkl" if cfg.resume is not None else None
    train_env = build_envs(cfg, seeds, run_dir / "monitor", stats)  # "train" streams
    n_eval = min(cfg.n_envs, max(cfg.eval_episodes, 1))
    eval_envs = make_eval_envs(cfg, seeds, "validation", n_eval)
    # -----------------------------------------------------------------------------------------

    if cfg.resume is not None:
        # seed=None: SB3 would otherwise re-seed the envs with consecutive seeds
        model = PPO.load(run_dir / "model.zip", env=train_env, device="cpu", seed=None)
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
    result = evaluate(model, eval_envs, cfg.eval_episodes, normalize=normalizer(train_env))
    result.update(
        num_timesteps=int(model.num_timesteps),
        train_seconds=round(train_s, 2),
        eval_seconds=round(time.perf_counter() - t0, 2),
        deterministic=True,
        stream="validation",
        shield=cfg.shield,
        reward=cfg.reward,
    )
    (run_dir / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
    train_env.close()
    for env in eval_envs:
        env.close()
    print(
        f"{run_dir}: {result['num_timesteps']} steps, success rate "
        f"{result['success_rate']:.3f} over {result['episodes']} episodes "
        f"(deterministic, shield {cfg.shield}), failure rate {result['failure_rate']:.3f}, "
        f"shield intervention rate {result['intervention_rate']:.3f}; "
        f"train {train_s:.1f} s"
    )
    return {**result, "run_dir": str(run_dir)}


def cli(argv: Sequence[str]) -> dict[str, Any]:
    """``python -m train.ppo``: the four-finger rotation main job (:mod:`train.rotate`) by
    default; ``python -m train.ppo islands [options]`` trains on the islands-and-bridges toy
    (:func:`main`). ``--resume RUN_DIR`` picks the trainer from the run's config.json."""
    argv = list(argv)
    if argv and argv[0] == "islands":
        return main(argv[1:])
    if "--resume" in argv:
        i = argv.index("--resume")
        cfg_file = Path(argv[i + 1]) / "config.json" if i + 1 < len(argv) else None
        if cfg_file is not None and cfg_file.is_file():
            if "object" not in json.loads(cfg_file.read_text()):  # rotation runs name one
                return main(argv)
    from train import rotate

    return rotate.main(argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
