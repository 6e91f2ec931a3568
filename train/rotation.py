"""PPO on the four-finger in-hand rotation task: the main job, ``python -m train.ppo``.

The thesis' setup (ch. 7, sec. "In-hand manipulation with pure reinforcement
learning"): ``ihm/FourFingerRotate-v0`` with the 0.1 kg sphere and gravity on,
reward = the sphere's angular velocity about the vertical axis, 64-step
episodes from a cache of varied stable grasps, separate policy and value nets
of 4 x 512, one update per 96 episodes of 64 steps (6,144 env steps).

The run is :data:`TASK` plugged into the one trainer :func:`train.trainer.train`; its
config, command line and checks are :mod:`train.rotation_config` (:class:`RotateConfig`,
:func:`parse_config`). A run directory holds::

    config.json           the RotateConfig of the run (below)
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

config.json records ``"task": "rotation"`` and the config's fields, the env's settings as
their groups (:mod:`envs.four_finger.settings`), each passed to the env as it is::

    {"task": "rotation", "object": "sphere", "thesis": false,
     "sim": {"gravity": true, "torsional": true, "timestep": 0.002, "frame_skip": 25, ...},
     "shield": "none", ..., "log_std_init": -0.5,
     "reward": {"rotation_cap": 1.0, "drop_weight": 0.0, "height_weight": 1.0, ...},
     "randomization": {"randomize": false, "corner_prob": 0.0, ..., "range_scale": 1.0},
     "starts": {"grasps": "train", "n_grasps": 256, "grip": "nominal", ...},
     "validate_corners": 0, ..., "observation": {"history": 1, "privileged": false}, ...}

A config.json from before the groups names every option at the top level
(``"drop_weight": 0.0``); it is read as well (:func:`train.options.from_saved`).
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
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

import envs  # noqa: F401  (registers ihm/FourFingerRotate-v0)
from envs.four_finger import (
    GRASP_SETS,
    N_OBS,
    PhysicsSample,
    Randomization,
    corners,
    grasp_cache,
)
from shields import make_shield
from stability.io import write_csv
from train.adr import AdrCallback
from train.curves import monitor_returns, plot_curve, steps_label
from train.evaluation import evaluate_rotation
from train.pipeline import PipelinedPPO
from train.rotation_config import (
    POLICY_DT,
    THESIS,
    RotateConfig,
    TrainingRandomization,
    config_problems,
    env_physics,
    parse_config,
)
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
    learning_rate,
    new_ppo,
    normalizer,
)
from train.seeding import EnvSeeds, RunSeeds
from train.trainer import Run, Task, train
from train.vec import make_vec_env

__all__ = [
    "ENV_ID",
    "POLICY_DT",
    "TARGET_SPEED",
    "TASK",
    "THESIS",
    "EvalCallback",
    "RotateConfig",
    "RotationEvals",
    "RotationTask",
    "TrainingRandomization",
    "build_model",
    "checkpoint",
    "config_problems",
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
    "transfer_normalizer",
    "validation_key",
]

ENV_ID = "ihm/FourFingerRotate-v0"
MIXED_ENV_ID = "ihm/FourFingerRotateMixed-v0"  # --objects: the object drawn per episode
TARGET_SPEED = 0.5  # [rad/s] the task's target, over 20 s episodes; drops <= 5 %
MAX_DROP_RATE = 0.05  # the task's drop target
SHIELD_KEYS = ("shield_episode_interventions", "shield_episode_seconds")  # monitor.csv columns


def make_env(
    cfg: RotateConfig,
    seeds: EnvSeeds | None = None,
    monitor_file: str | None = None,
    append: bool = False,
    max_steps: int | None = None,
    train: bool = True,
    physics: PhysicsSample | None = None,
) -> Callable[[], gym.Env]:
    """A thunk: ``gym.make(ihm/FourFingerRotate-v0)`` (with ``--objects``
    ``ihm/FourFingerRotateMixed-v0``, the object drawn per episode) with the config's groups
    as they are
    (time limit ``max_steps``, default ``cfg.episode_steps``) -> the shield ``--shield``
    (:func:`shields.make_shield`) -> Monitor (the episode's drop and, under a shield,
    :data:`SHIELD_KEYS`) when ``monitor_file`` is given; seeded with ``seeds``. Training envs
    (``train``) start with the config's failure replay and turned starts and, in a
    ``--randomize`` run, draw their physics per episode; other envs start uniformly over the
    cache under nominal physics, or under ``physics`` when given."""

    def thunk() -> gym.Env:
        starts = cfg.starts if train else replace(cfg.starts, replay_prob=0.0, turned_prob=0.0)
        which = {"objects": tuple(cfg.objects)} if cfg.objects else {"object": cfg.object}
        env = gym.make(
            MIXED_ENV_ID if cfg.objects else ENV_ID,
            **which,
            reward=cfg.reward,
            sim=cfg.sim,
            starts=starts,
            observation=cfg.observation,
            randomize=training_randomization(cfg) if train and physics is None else None,
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
    """The training envs' randomised physics, ``cfg.randomization.ranges()``: the env's
    :class:`Randomization` with the config's sampling probabilities, its ranges scaled by
    ``range_scale`` (:meth:`Randomization.scaled`), or ``None`` without ``--randomize``."""
    return cfg.randomization.ranges()


def build_model(cfg: RotateConfig, vec_env: VecEnv) -> PPO:
    """PPO with separate policy and value nets (``cfg.pi``, ``cfg.vf``), the learning rate of
    ``cfg.lr_schedule`` (:func:`train.sb3.learning_rate`);
    :class:`train.pipeline.PipelinedPPO`, which pipelines its rollouts over a
    ``ChunkedVecEnv`` with parts and is plain SB3 PPO on any other env."""
    obs = cfg.observation
    actor_obs = N_OBS * obs.history if obs.privileged else None
    return new_ppo(cfg, vec_env, learning_rate(cfg), algo=PipelinedPPO, actor_obs=actor_obs)


def transfer_normalizer(cfg: RotateConfig, vec: VecEnv) -> VecNormalize:
    """``vec`` normalised from the statistics of ``cfg.init_from``
    (:func:`train.runfiles.init_normalizer`): the observation's entries after its
    ``history`` frames are the critic's privileged state, which the source may not have
    observed."""
    priv = vec.observation_space.shape[0] - N_OBS * cfg.observation.history
    return init_normalizer(vec, Path(str(cfg.init_from)), priv)


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


@dataclass(frozen=True)
class RotationEvals:
    """The rotation run's evaluation envs: ``validation`` (nominal physics, training start
    grasps on the validation streams) and ``corners`` (one per corner of the randomised
    ranges, with ``--validate-corners``; else none)."""

    validation: list[gym.Env]
    corners: list[gym.Env]


class RotationTask(Task):
    """The four-finger rotation main job as a :class:`train.trainer.Task` (module doc)."""

    name = "rotation"
    algo = PipelinedPPO

    def parse(self, argv: Sequence[str]) -> RotateConfig:
        return parse_config(argv)

    def run_name(self, cfg: RotateConfig) -> str:
        shield = "" if cfg.shield == "none" else f"__{cfg.shield}"
        stamp = time.strftime("%Y%m%d-%H%M%S")
        what = "-".join(cfg.objects) if cfg.objects else cfg.object
        return f"FourFingerRotate-{what}{shield}__{cfg.seed}__{stamp}"

    def resume_options(self, cfg: RotateConfig, argv: Sequence[str]) -> tuple[str, ...]:
        keep = ("total_steps", "progress", "verbose", "threads", "workers", "pipeline")
        return keep + _finetune(cfg, argv)

    def prepare(self, cfg: RotateConfig, run_dir: Path, argv: Sequence[str], done: int) -> Any:
        """Build the start-state cache once, before any worker; on resume, record a switch to
        randomised physics and the fine-tune options given (:mod:`train.runfiles`)."""
        s, starts = cfg.sim, cfg.starts
        seed = GRASP_SETS[starts.grasps]
        for obj in cfg.objects or [cfg.object]:
            grasp_cache(obj, s.gravity, starts.n_grasps, seed=seed, timestep=s.timestep,
                        frame_skip=s.frame_skip, grip=starts.grip)  # fmt: skip
        if cfg.resume is not None and given(argv, "randomize") and not cfg.randomization.randomize:
            cfg = start_randomizing(cfg, run_dir, done)
        finetune = _finetune(cfg, argv)
        if finetune:
            start_finetune(cfg, run_dir, finetune, done)
        return cfg

    def train_env(self, cfg: RotateConfig, seeds: RunSeeds, run_dir: Path) -> VecEnv:
        """``cfg.n_envs`` training envs (one Monitor file each) stepped by ``cfg.workers``
        processes, under VecNormalize: the run's statistics on resume, those of
        ``--init-from`` for a transfer, else fresh."""
        mon = run_dir / "monitor"
        mon.mkdir(exist_ok=True)
        thunks = [  # append to a resumed run's monitor files (a committed run has none)
            make_env(cfg, s, str(mon / str(i)), append=(mon / f"{i}.monitor.csv").is_file())
            for i, s in enumerate(seeds.envs("train", cfg.n_envs))
        ]
        vec: VecEnv = make_vec_env(thunks, cfg.workers, parts=2 if cfg.pipeline else 1)
        stats = run_dir / "vecnormalize.pkl"
        if cfg.resume is not None and stats.is_file():
            return VecNormalize.load(str(stats), vec)
        if cfg.init_from is None:
            return VecNormalize(vec, gamma=cfg.gamma)
        try:
            return transfer_normalizer(cfg, vec)
        except ValueError as e:
            vec.close()
            raise SystemExit(f"python -m train.ppo: error: {e}") from None

    def eval_envs(self, cfg: RotateConfig, seeds: RunSeeds) -> RotationEvals:
        max_eval = int(round(cfg.eval_seconds * 20))
        n_eval = max(1, min(cfg.eval_episodes, 10))
        validation = [
            make_env(cfg, s, max_steps=max_eval, train=False)()
            for s in seeds.envs("validation", n_eval)
        ]
        corner_envs = []
        rnd = cfg.randomization
        if rnd.randomize and cfg.validate_corners:
            cases = corners(rnd.full_ranges() if rnd.adr_step else training_randomization(cfg))
            streams = seeds.envs("validation", n_eval + len(cases))[n_eval:]
            corner_envs = [
                make_env(cfg, s, max_steps=max_eval, train=False, physics=c)()
                for s, c in zip(streams, cases, strict=True)
            ]
        return RotationEvals(validation, corner_envs)

    def new_model(self, cfg: RotateConfig, vec: VecEnv) -> PPO:
        model = build_model(cfg, vec)
        if cfg.init_from is not None:
            try:
                init_weights(model, Path(cfg.init_from))
            except ValueError as e:
                raise SystemExit(f"python -m train.ppo: error: {e}") from None
        return model

    def callbacks(
        self, cfg: RotateConfig, run_dir: Path, evals: RotationEvals
    ) -> list[BaseCallback]:
        ev = EvalCallback(cfg, run_dir, evals.validation, cfg.checkpoint_every, evals.corners)
        out: list[BaseCallback] = [ev]
        if cfg.randomization.randomize and cfg.randomization.adr_step:
            out.append(AdrCallback(cfg.randomization, cfg.objects, run_dir))
        return [*out, RolloutThreads(cfg.threads)] if cfg.workers else out

    def evaluate(self, run: Run, train_seconds: float) -> dict[str, Any]:
        """The last validation (also a row of eval.csv) with the run's size and speed, the
        evaluation episodes' length and the best validated checkpoint."""
        cfg, model = run.cfg, run.model
        (ev,) = [c for c in run.callbacks if isinstance(c, EvalCallback)]
        run.vec.training = False
        result = ev.evaluate() if cfg.eval_episodes else {}
        return {
            **result,
            "num_timesteps": int(model.num_timesteps),
            "train_seconds": round(train_seconds, 1),
            "steps_per_second": round((model.num_timesteps - run.done) / train_seconds, 1),
            "eval_episode_seconds": cfg.eval_seconds,
            "best": ev.best,
        }

    def summary(self, run: Run, result: dict[str, Any], train_seconds: float) -> str:
        return (
            f"{run.dir}: {result['num_timesteps']} steps in {train_seconds:.0f} s "
            f"({result['steps_per_second']:.0f} env steps/s); validation on training start "
            f"grasps, deterministic policy over {result.get('episodes', 0)} x "
            f"{run.cfg.eval_seconds:g} s: {result.get('speed_rad_s', float('nan')):.3f} rad/s, "
            f"drop rate {result.get('drop_rate', float('nan')):.3f} (held-out grasps: "
            f"python -m train.heldout {run.dir})"
        )

    def close(self, run: Run) -> None:
        """Redraw curve.png, close the envs."""
        plot_curve(run.dir, TARGET_SPEED)
        run.vec.close()
        for env in [*run.evals.validation, *run.evals.corners]:
            env.close()


def _finetune(cfg: RotateConfig, argv: Sequence[str]) -> tuple[str, ...]:
    """The fine-tune options (:data:`train.runfiles.FINETUNE`) given with ``--resume``."""
    return tuple(f for f in FINETUNE if given(argv, f)) if cfg.resume is not None else ()


TASK = RotationTask()


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Train (or resume), evaluate, save (:func:`train.trainer.train` with :data:`TASK`);
    returns the final evaluation."""
    return train(TASK, argv)


if __name__ == "__main__":
    main(sys.argv[1:])
