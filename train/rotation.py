"""PPO on the four-finger in-hand rotation task: the main job, ``python -m train.ppo``.

The thesis' setup (ch. 7, sec. "In-hand manipulation with pure reinforcement
learning"): ``ihm/FourFingerRotate-v0`` with the 0.1 kg sphere and gravity on,
reward = the sphere's angular velocity about the vertical axis, 64-step
episodes from a cache of varied stable grasps, separate policy and value nets
of 4 x 512, one update per 96 episodes of 64 steps (6,144 env steps).

A run directory holds::

    config.json           the RotateConfig of the run
    model.zip             the latest PPO model (also every --checkpoint-every steps)
    vecnormalize.pkl      the observation/reward normalisation statistics
    monitor/N.monitor.csv one Monitor log per training env (return r, length l, time t)
    eval.csv              periodic evaluations: steps, rad/s, drop rate, wall time
    eval.json             the final evaluation
    curve.png             training return and evaluated rotation speed over env steps

Evaluation runs the deterministic policy for ``--eval-episodes`` episodes of
``--eval-seconds`` (20 s = 400 policy steps) on validation streams and reports
the mean rotation speed (turned angle about +z over the episode's duration,
rad/s; a drop ends an episode and counts its time so far) and the drop rate
(:func:`train.evaluation.evaluate_rotation`).
``--resume RUN_DIR`` continues a run for ``--total-steps`` more steps.
"""

from __future__ import annotations

import csv
import json
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

import envs  # noqa: F401  (registers ihm/FourFingerRotate-v0)
from envs.four_finger import (
    FRAME_SKIP,
    GRIPS,
    HEIGHT_FROM,
    N_OBS,
    N_PRIVILEGED,
    OBJECTS,
    TIMESTEP,
    FourFingerError,
    PhysicsSample,
    Randomization,
    check_start_sampling,
    corners,
    grasp_cache,
)
from shields import SHIELDS, make_shield
from shields.qp import BACKENDS
from stability.io import write_csv
from train.curves import monitor_returns, plot_curve, steps_label
from train.evaluation import evaluate_rotation
from train.pipeline import PipelinedPPO
from train.runfiles import (
    FINETUNE,
    checkpoint,
    export_policy,
    given,
    init_normalizer,
    init_weights,
    policy_dir,
    start_finetune,
    start_randomizing,
)
from train.sb3 import (
    RolloutThreads,
    build_parser,
    learning_rate,
    new_ppo,
    normalizer,
    open_run,
    opt,
    option_problems,
    progress_bar,
    saved_timesteps,
    seed_everything,
)
from train.seeding import EnvSeeds, RunSeeds
from train.vec import make_vec_env

__all__ = [
    "ENV_ID",
    "POLICY_DT",
    "TARGET_SPEED",
    "EvalCallback",
    "RotateConfig",
    "build_model",
    "checkpoint",
    "env_physics",
    "evaluate_rotation",
    "export_policy",
    "main",
    "make_env",
    "monitor_returns",
    "parse_config",
    "plot_curve",
    "policy_dir",
    "steps_label",
    "training_randomization",
    "validation_key",
]

ENV_ID = "ihm/FourFingerRotate-v0"
POLICY_DT = TIMESTEP * FRAME_SKIP  # [s] 0.05: the thesis' 20 Hz policy
TARGET_SPEED = 0.5  # [rad/s] the task's target, over 20 s episodes; drops <= 5 %
MAX_DROP_RATE = 0.05  # the task's drop target
SHIELD_KEYS = ("shield_episode_interventions", "shield_episode_seconds")  # monitor.csv columns


THESIS: dict[str, Any] = {
    "pi": [512, 512, 512, 512],
    "vf": [512, 512, 512, 512],
    "learning_rate": 1e-4,
    "episode_steps": 64,
    "rotation_cap": float("inf"),
    "height_weight": 0.0,
    "drop_weight": 0.0,
    "randomize": False,
    "lr_schedule": "constant",
}
"""What ``--thesis`` changes back to the thesis' setup (ch. 7): 64-step episodes, the uncapped
rotation reward without a drop penalty, nominal physics, a constant learning rate. Options
given beside ``--thesis`` still apply."""


@dataclass
class RotateConfig:
    """Everything a rotation training run depends on; saved as config.json."""

    object: str = opt("sphere", "object in the hand", choices=OBJECTS)
    thesis: bool = opt(
        False, "the thesis' setup as the defaults (train.rotation.THESIS); other options apply"
    )
    gravity: bool = opt(True, "gravity on (the thesis' hard case)")
    torsional: bool = opt(
        True, "torsional friction at the contacts (condim 4; off: point contacts, exploitable)"
    )
    timestep: float = opt(
        TIMESTEP,
        "physics timestep [s]; the policy period stays 0.05 s (0.05 / timestep substeps). "
        "0.0025: about 20 %% faster, coarser (docs/bench/four_finger_env.md)",
    )
    shield: str = opt(
        "none",
        "shield around every env, kept for evaluation (shields.make_shield): "
        + "; ".join(f"{k}: {v}" for k, v in SHIELDS.items()),
        choices=tuple(SHIELDS),
    )
    shield_backend: str = opt("daqp", "QP backend of --shield qp and qp-drift", choices=BACKENDS)
    total_steps: int = opt(1_200_000, "env steps to train (with --resume: steps to add)")
    seed: int = opt(1, "run seed (>= 0): root of the env, policy and evaluation streams")
    n_envs: int = opt(16, "parallel training envs")
    workers: int = opt(
        2, "processes that step the training envs, each its share (train.vec); 0: in this one"
    )
    pipeline: bool = opt(
        True,
        "with workers: overlap the policy's forward passes with the physics "
        "(train.pipeline; the same transitions)",
    )
    pi: list[int] = opt([256, 256, 256], "hidden layers of the policy net (thesis: 4 x 512)")
    vf: list[int] = opt(
        [256, 256, 256], "hidden layers of the separate value net (thesis: 4 x 512)"
    )
    learning_rate: float = opt(2e-4, "Adam learning rate (thesis: 1e-4)")
    n_steps: int = opt(384, "rollout length per env (16 x 384 = 96 episodes of 64 steps)")
    batch_size: int = opt(1024, "minibatch size")
    n_epochs: int = opt(5, "PPO epochs per rollout")
    gamma: float = opt(0.99, "discount factor")
    gae_lambda: float = opt(0.95, "GAE lambda")
    clip_range: float = opt(0.2, "PPO clipping range")
    ent_coef: float = opt(0.0, "entropy bonus coefficient")
    log_std_init: float = opt(-0.5, "initial log std of the Gaussian policy")
    drop_weight: float = opt(0.0, "env drop penalty weight (0: the thesis' reward)")
    height_weight: float = opt(
        1.0, "weight of the env's height term (penalises the object sagging below 0.07 m)"
    )
    height_from: str = opt(
        "hold",
        "the height term's reference: hold (0.07 m, about 7 mm below a held object) or start "
        "(the object's start height: every mm of sag counts)",
        choices=HEIGHT_FROM,
    )
    slip_weight: float = opt(
        0.0, "weight of the contact-slip penalty (mean sliding speed of the contacts [m/s])"
    )
    tilt_weight: float = opt(
        0.0, "weight of the tilt penalty (the object's tilt since the episode's start [rad])"
    )
    rotation_cap: float = opt(
        1.0, "cap of the rotation reward [rad/s] (inf: the thesis' uncapped reward)"
    )
    randomize: bool = opt(
        False,
        "randomised physics in the training envs (envs.four_finger.Randomization: friction, "
        "torsional friction, mass, servo gains, latency, sensor noise); evaluations stay nominal",
    )
    grip: str = opt(
        "nominal",
        "start grasps' squeeze: nominal (the thesis' inward grip) or firm (also lifting the "
        "object and 1 N harder, verified to hold still at the worst --randomize corner)",
        choices=GRIPS,
    )
    corner_prob: float = opt(
        0.0,
        "with --randomize: probability that a training episode's physics is one of the 16 "
        "corners of the ranges (envs.four_finger.corners) instead of a uniform draw",
    )
    hard_prob: float = opt(
        0.0,
        "with --randomize: probability that a training episode is drawn from the hard region "
        "(friction x0.5, mass x1-2; envs.four_finger.Randomization.hard_prob)",
    )
    hard_gain: float = opt(
        Randomization().gain[1],
        "with --hard-prob: upper bound of the servo gain scales in the hard region (1.2: the "
        "whole range x0.8-1.2; 1.0: the weak half)",
    )
    latency_prob: float = opt(
        Randomization().latency_prob,
        "with --randomize: probability that an episode has one step of action latency (the "
        "corners always have it)",
    )
    replay_prob: float = opt(
        0.0,
        "probability that a training episode restarts a start (grasp and physics) that "
        "dropped the object before in the same env (failure replay; envs.four_finger)",
    )
    turned_prob: float = opt(
        0.0,
        "cube: probability that a training episode starts from a grasp with the cube turned "
        ">= 22.5 degrees from the hand's square (envs.four_finger.cube_turn)",
    )
    range_scale: float = opt(
        1.0,
        "with --randomize: shrink the friction, torsional, mass and gain ranges towards nominal "
        "by this factor in (0, 1] (Randomization.scaled; 0.5: friction x0.75-1.25, mass "
        "x0.71-1.41); latency and noise stay. A first curriculum stage; the corners validated "
        "are the scaled range's",
    )
    validate_corners: int = opt(
        0,
        "with --randomize: also validate at each of the 16 corners, N episodes each; best/ is "
        "then chosen on the worse of the nominal and the pooled corner figures",
    )
    lr_schedule: str = opt(
        "linear",
        "learning rate: constant, or linear decay to 0 over --total-steps",
        choices=("constant", "linear"),
    )
    episode_steps: int = opt(64, "training episode length (thesis: 64)")
    checkpoint_every: int = opt(100_000, "env steps between checkpoints and evaluations")
    keep_best: bool = opt(
        True,
        "keep the best validated checkpoint in best/ (drops <= 5 %% first, then speed); the "
        "shipped and held-out evaluations use it",
    )
    eval_episodes: int = opt(20, "episodes per evaluation (deterministic policy)")
    eval_seconds: float = opt(20.0, "length of an evaluation episode [s]")
    threads: int = opt(2, "torch threads for the PPO update")
    out: str = opt("runs", "directory that receives the run directory")
    resume: str | None = opt(None, "run directory to continue")
    history: int = opt(
        1,
        "observed frames: the actor and critic see the last N sensed observations (joints, "
        "setpoints, contacts), oldest first; 1: the thesis' single frame",
    )
    privileged_critic: bool = opt(
        False,
        "asymmetric critic: the value net also reads the object's pose and velocity and the "
        "episode's physics (envs.four_finger N_PRIVILEGED); the actor reads what the hand senses",
    )
    init_from: str | None = opt(
        None,
        "run or policy directory whose policy and value weights and observation statistics "
        "start this new run (transfer: e.g. a sphere policy starts a cube run); its nets must "
        "match --pi and --vf",
    )
    progress: bool = opt(True, "show a tqdm progress bar")
    verbose: int = opt(0, "SB3 verbosity")


def parse_config(argv: Sequence[str] | None = None) -> RotateConfig:
    """Parse the command line into a :class:`RotateConfig` (exit 2 on bad options)."""
    parser = build_parser(
        RotateConfig,
        description=(__doc__ or "").split("\n\n")[0],
        epilog="The islands-and-bridges toy: python -m train.ppo islands [options] "
        "(python -m train.ppo islands --help).",
    )
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--thesis" in argv:
        parser.set_defaults(**THESIS)
    cfg = RotateConfig(**vars(parser.parse_args(argv)))
    ints = (
        "total_steps",
        "n_envs",
        "n_steps",
        "batch_size",
        "n_epochs",
        "episode_steps",
        "history",
    )
    problems = option_problems(cfg, ints)
    if cfg.eval_episodes < 0 or cfg.checkpoint_every < 1 or cfg.threads < 1 or cfg.workers < 0:
        problems.append(
            "--eval-episodes and --workers must be >= 0, --checkpoint-every and --threads >= 1"
        )
    if cfg.privileged_critic and cfg.shield != "none":
        problems.append("--privileged-critic cannot be combined with a --shield")
    if cfg.shield.startswith("lookahead") and cfg.randomize and cfg.latency_prob > 0:
        problems.append("--shield lookahead cannot shield action latency: --latency-prob 0")
    try:  # --corner-prob, --hard-prob, --hard-gain, --latency-prob, --range-scale
        training_randomization(replace(cfg, randomize=True))  # Randomization's own checks
    except FourFingerError as e:
        problems.append(
            f"--corner-prob, --hard-prob, --hard-gain, --latency-prob, --range-scale: {e}"
        )
    if cfg.validate_corners < 0:
        problems.append("--validate-corners must be >= 0")
    try:  # the env's own check
        check_start_sampling(cfg.object, cfg.replay_prob, cfg.turned_prob)
    except FourFingerError as e:
        problems.append(f"--replay-prob, --turned-prob, --object: {e}")
    if not np.isfinite(cfg.eval_seconds) or cfg.eval_seconds <= 0:
        problems.append("--eval-seconds must be > 0")
    if cfg.init_from is not None:
        src = policy_dir(Path(cfg.init_from))
        if cfg.resume is not None:
            problems.append("--init-from starts a new run; it cannot be given with --resume")
        elif not (src / "vecnormalize.pkl").is_file() or not any(
            (src / f).is_file() for f in ("policy.pt", "model.zip")
        ):
            problems.append(
                f"--init-from {cfg.init_from}: no policy.pt or model.zip with vecnormalize.pkl"
            )
    try:
        env_physics(cfg.timestep)
    except ValueError as e:
        problems.append(str(e))
    if problems:
        parser.error("; ".join(problems))
    return cfg


def env_physics(timestep: float) -> dict[str, float | int]:
    """``timestep`` [s] and ``frame_skip`` of the env for a physics timestep that divides
    the policy period ``POLICY_DT`` (0.05 s, the thesis' 20 Hz); ValueError otherwise."""
    n = POLICY_DT / timestep if np.isfinite(timestep) and timestep > 0 else 0.0
    if n < 1 or abs(n - round(n)) > 1e-9:
        raise ValueError(f"--timestep must divide the policy period {POLICY_DT} s, got {timestep}")
    return {"timestep": float(timestep), "frame_skip": int(round(n))}


def make_env(
    cfg: RotateConfig,
    seeds: EnvSeeds | None = None,
    monitor_file: str | None = None,
    append: bool = False,
    max_steps: int | None = None,
    train: bool = True,
    physics: PhysicsSample | None = None,
) -> Callable[[], gym.Env]:
    """A thunk: ``gym.make(ihm/FourFingerRotate-v0)`` (time limit ``max_steps``, default
    ``cfg.episode_steps``) -> the shield ``--shield`` (:func:`shields.make_shield`) -> Monitor
    (the episode's drop and, under a shield, :data:`SHIELD_KEYS`) when ``monitor_file`` is
    given; seeded with ``seeds``. Training envs (``train``) of a ``--randomize`` run draw their
    physics per episode; ``physics`` fixes it instead."""

    def thunk() -> gym.Env:
        env = gym.make(
            ENV_ID,
            object=cfg.object,
            gravity=cfg.gravity,
            torsional=cfg.torsional,
            **env_physics(cfg.timestep),
            drop_weight=cfg.drop_weight,
            rotation_cap=cfg.rotation_cap,
            height_weight=cfg.height_weight,
            height_from=cfg.height_from,
            slip_weight=cfg.slip_weight,
            tilt_weight=cfg.tilt_weight,
            history=cfg.history,
            privileged=cfg.privileged_critic,
            grip=cfg.grip,
            randomize=training_randomization(cfg) if train and physics is None else None,
            replay_prob=cfg.replay_prob if train else 0.0,
            turned_prob=cfg.turned_prob if train else 0.0,
            physics=physics,
            max_episode_steps=max_steps or cfg.episode_steps,
        )
        env = make_shield(env, cfg.shield, backend=cfg.shield_backend)
        if monitor_file is not None:
            keys = ("dropped",) if cfg.shield == "none" else ("dropped", *SHIELD_KEYS)
            env = Monitor(
                env, filename=monitor_file, info_keywords=keys, override_existing=not append
            )
        if seeds is not None:
            env.reset(seed=seeds.reset)
            env.action_space.seed(seeds.action_space)
        return env

    return thunk


def training_randomization(cfg: RotateConfig) -> Randomization | None:
    """The training envs' randomised physics: the env's :class:`Randomization` with
    ``cfg.corner_prob``, ``cfg.hard_prob`` and ``cfg.latency_prob``, its ranges scaled by
    ``cfg.range_scale`` (:meth:`Randomization.scaled`), or ``None`` without ``--randomize``."""
    if not cfg.randomize:
        return None
    return Randomization(
        corner_prob=cfg.corner_prob,
        hard_prob=cfg.hard_prob,
        hard_gain=cfg.hard_gain,
        latency_prob=cfg.latency_prob,
    ).scaled(cfg.range_scale)


def build_model(cfg: RotateConfig, vec_env: VecEnv) -> PPO:
    """PPO with separate policy and value nets (``cfg.pi``, ``cfg.vf``), the learning rate of
    ``cfg.lr_schedule`` (:func:`train.sb3.learning_rate`);
    :class:`train.pipeline.PipelinedPPO`, which pipelines its rollouts over a
    ``ChunkedVecEnv`` with parts and is plain SB3 PPO on any other env."""
    actor_obs = N_OBS * cfg.history if cfg.privileged_critic else None
    return new_ppo(cfg, vec_env, learning_rate(cfg), algo=PipelinedPPO, actor_obs=actor_obs)


def validation_key(res: dict[str, Any]) -> tuple[bool, float]:
    """How :class:`EvalCallback` ranks validation evaluations for ``best/``: first whether the
    drop rate meets the target (<= :data:`MAX_DROP_RATE`), then the speed among those that do,
    and the drop rate among those that do not (fewer is better)."""
    ok = res["drop_rate"] <= MAX_DROP_RATE
    return ok, res["speed_rad_s"] if ok else -res["drop_rate"]


class EvalCallback(BaseCallback):
    """Every ``every`` env steps: save model.zip and vecnormalize.pkl, evaluate, append a row
    to eval.csv, redraw curve.png; with ``cfg.keep_best``, a checkpoint that ranks above every
    earlier one (:func:`validation_key`) is also saved to ``best/`` (model.zip,
    vecnormalize.pkl, config.json, eval.json with its validation result)."""

    def __init__(
        self,
        cfg: RotateConfig,
        run_dir: Path,
        eval_envs: Sequence[gym.Env],
        every: int,
        corner_envs: Sequence[gym.Env] = (),
    ) -> None:
        super().__init__()
        self.cfg, self.run_dir, self.eval_envs, self.every = cfg, run_dir, eval_envs, every
        self.corner_envs = corner_envs
        self.t0 = time.perf_counter()
        self.next = 0
        best = run_dir / "best" / "eval.json"
        self.best: dict[str, Any] | None = json.loads(best.read_text()) if best.is_file() else None

    def _on_training_start(self) -> None:
        self.next = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        if self.num_timesteps >= self.next:
            self.next = (self.num_timesteps // self.every + 1) * self.every
            checkpoint(self.model, self.run_dir)
            if self.cfg.eval_episodes:
                self.evaluate()

    def evaluate(self) -> dict[str, float]:
        norm = normalizer(self.model.get_env())
        res = evaluate_rotation(self.model, self.eval_envs, self.cfg.eval_episodes, norm)
        row: dict[str, Any] = {
            "steps": int(self.num_timesteps),
            "speed_rad_s": round(res["speed_rad_s"], 4),
            "drop_rate": round(res["drop_rate"], 4),
            "episodes": res["episodes"],
            "wall_s": round(time.perf_counter() - self.t0, 1),
        }
        rank = res
        if self.corner_envs:  # the corners, pooled; best/ on the worse of the two
            n = len(self.corner_envs) * self.cfg.validate_corners
            cor = evaluate_rotation(self.model, self.corner_envs, n, norm)
            row.update(
                corner_speed_rad_s=round(cor["speed_rad_s"], 4),
                corner_drop_rate=round(cor["drop_rate"], 4),
                corner_episodes=cor["episodes"],
            )
            rank = {
                "speed_rad_s": min(res["speed_rad_s"], cor["speed_rad_s"]),
                "drop_rate": max(res["drop_rate"], cor["drop_rate"]),
            }
            res = {**res, "corners": cor}
        path = self.run_dir / "eval.csv"
        rows = []
        if path.is_file():  # a resumed run goes on with its rows
            with path.open(newline="") as f:
                rows = list(csv.DictReader(f))
        write_csv(
            path, [*rows, row], columns=list(dict.fromkeys([*row, *rows[0]] if rows else row))
        )
        self.logger.record("eval/speed_rad_s", res["speed_rad_s"])
        self.logger.record("eval/drop_rate", res["drop_rate"])
        plot_curve(self.run_dir, TARGET_SPEED)
        if self.cfg.keep_best and (
            self.best is None
            or validation_key(rank) > validation_key(self.best.get("ranked_on", self.best))
        ):
            self.best = {
                **row,
                "validation_episodes": res["episodes"],
                "ranked_on": {k: round(rank[k], 4) for k in ("speed_rad_s", "drop_rate")},
            }
            best = self.run_dir / "best"
            best.mkdir(exist_ok=True)
            checkpoint(self.model, best)
            shutil.copy(self.run_dir / "config.json", best / "config.json")
            (best / "eval.json").write_text(json.dumps(self.best, indent=2) + "\n")
        return res


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Train (or resume), evaluate, save; returns the final evaluation."""
    argv = list(sys.argv[1:] if argv is None else argv)
    cfg = parse_config(argv)
    torch.set_num_threads(cfg.threads)
    shield = "" if cfg.shield == "none" else f"__{cfg.shield}"
    name = f"FourFingerRotate-{cfg.object}{shield}__{cfg.seed}__{time.strftime('%Y%m%d-%H%M%S')}"
    keep = ("total_steps", "progress", "verbose", "threads", "workers", "pipeline")
    finetune = tuple(f for f in FINETUNE if given(argv, f)) if cfg.resume is not None else ()
    cfg, run_dir = open_run(cfg, name, keep=keep + finetune)
    grasp_cache(
        cfg.object, cfg.gravity, **env_physics(cfg.timestep), grip=cfg.grip
    )  # build the start-state cache once, before any worker
    done = saved_timesteps(run_dir) if cfg.resume is not None else 0
    if cfg.resume is not None and given(argv, "randomize") and not cfg.randomize:
        cfg = start_randomizing(cfg, run_dir, done)
    if finetune:
        start_finetune(run_dir, {f: getattr(cfg, f) for f in finetune}, done)
    seeds = RunSeeds(cfg.seed, segment=done)
    seed_everything(seeds.global_seed)
    mon = run_dir / "monitor"
    mon.mkdir(exist_ok=True)
    thunks = [
        make_env(cfg, s, str(mon / str(i)), append=cfg.resume is not None)
        for i, s in enumerate(seeds.envs("train", cfg.n_envs))
    ]
    vec: VecEnv = make_vec_env(thunks, cfg.workers, parts=2 if cfg.pipeline else 1)
    stats = run_dir / "vecnormalize.pkl"
    if cfg.resume is not None and stats.is_file():
        vec = VecNormalize.load(str(stats), vec)
    elif cfg.init_from is not None:
        try:
            priv = N_PRIVILEGED if cfg.privileged_critic else 0
            vec = init_normalizer(vec, Path(cfg.init_from), priv)
        except ValueError as e:
            vec.close()
            raise SystemExit(f"python -m train.ppo: error: {e}") from None
    else:
        vec = VecNormalize(vec, gamma=cfg.gamma)
    max_eval = int(round(cfg.eval_seconds * 20))
    n_eval = max(1, min(cfg.eval_episodes, 10))
    eval_envs = [
        make_env(cfg, s, max_steps=max_eval, train=False)()
        for s in seeds.envs("validation", n_eval)
    ]
    corner_envs = []
    if cfg.randomize and cfg.validate_corners:
        cases = corners(training_randomization(cfg))
        corner_envs = [
            make_env(cfg, s, max_steps=max_eval, train=False, physics=c)()
            for s, c in zip(
                seeds.envs("validation", n_eval + len(cases))[n_eval:], cases, strict=True
            )
        ]
    if cfg.resume is not None:
        model = PipelinedPPO.load(run_dir / "model.zip", env=vec, device="cpu", seed=None)
    else:
        model = build_model(cfg, vec)
        if cfg.init_from is not None:
            try:
                init_weights(model, Path(cfg.init_from))
            except ValueError as e:
                vec.close()
                raise SystemExit(f"python -m train.ppo: error: {e}") from None
    model.set_logger(configure(str(run_dir), ["csv"] + (["stdout"] if cfg.verbose else [])))
    ev = EvalCallback(cfg, run_dir, eval_envs, cfg.checkpoint_every, corner_envs)
    callbacks: list[BaseCallback] = [ev]
    if cfg.workers:
        callbacks.append(RolloutThreads(cfg.threads))
    if cfg.progress:
        callbacks.append(progress_bar(cfg, desc=run_dir.name))
    t0 = time.perf_counter()
    model.learn(cfg.total_steps, callback=callbacks, reset_num_timesteps=cfg.resume is None)
    train_s = time.perf_counter() - t0
    checkpoint(model, run_dir)
    vec.training = False
    result = ev.evaluate() if cfg.eval_episodes else {}
    result = {
        **result,
        "num_timesteps": int(model.num_timesteps),
        "train_seconds": round(train_s, 1),
        "steps_per_second": round((model.num_timesteps - done) / train_s, 1),
        "eval_episode_seconds": cfg.eval_seconds,
        "best": ev.best,
    }
    (run_dir / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
    plot_curve(run_dir, TARGET_SPEED)
    vec.close()
    for env in [*eval_envs, *corner_envs]:
        env.close()
    print(
        f"{run_dir}: {result['num_timesteps']} steps in {train_s:.0f} s "
        f"({result['steps_per_second']:.0f} env steps/s); validation on training start "
        f"grasps, deterministic policy over {result.get('episodes', 0)} x "
        f"{cfg.eval_seconds:g} s: {result.get('speed_rad_s', float('nan')):.3f} rad/s, "
        f"drop rate {result.get('drop_rate', float('nan')):.3f} (held-out grasps: "
        f"python -m train.heldout {run_dir})"
    )
    return {**result, "run_dir": str(run_dir)}


if __name__ == "__main__":
    main(sys.argv[1:])
