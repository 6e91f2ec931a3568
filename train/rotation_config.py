"""The rotation main job's config: :class:`RotateConfig`, its command line and its checks.

Every field of :class:`RotateConfig` is an option of ``python -m train.ppo`` or a group of
the env's settings (:mod:`envs.four_finger.settings`) with the options that set it
(:mod:`train.options`); :func:`parse_config` reads the command line (``--thesis``: the
thesis' setup, :data:`THESIS`, as the defaults), :func:`config_problems` names what is wrong
with a config beyond its groups' own checks. The trainer is :mod:`train.rotation`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from envs.four_finger import (
    FRAME_SKIP,
    GRIPS,
    HEIGHT_FROM,
    OBJECTS,
    TIMESTEP,
    TRAIN_OBJECTS,
    FourFingerError,
    ObservationSettings,
    Randomization,
    RewardSettings,
    SimSettings,
    StartSettings,
)
from shields import SHIELDS
from shields.qp import BACKENDS
from train.options import Flag, build_parser, from_options, group, opt
from train.runfiles import policy_dir
from train.sb3 import option_problems

__all__ = [
    "GENERALIST",
    "POLICY_DT",
    "THESIS",
    "RotateConfig",
    "TrainingRandomization",
    "config_problems",
    "env_physics",
    "parse_config",
]

POLICY_DT = TIMESTEP * FRAME_SKIP  # [s] 0.05: the thesis' 20 Hz policy
DESCRIPTION = "PPO on the four-finger in-hand rotation task: the main job, ``python -m train.ppo``."

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


GENERALIST: dict[str, Any] = {
    "objects": list(TRAIN_OBJECTS),
    "randomize": True,
    "range_scale": 0.25,
    "adr_step": 0.125,
    "object_share": 0.5,
    "corner_prob": 0.25,
    "grip": "firm",
    "history": 3,
    "privileged_critic": True,
    "episode_steps": 200,
    "slip_weight": 10.0,
    "tilt_weight": 0.25,
    "drop_weight": 20.0,
    "learning_rate": 5e-5,
    "lr_schedule": "constant",
    "total_steps": 20_000_000,
    "checkpoint_every": 245_760,
    "validate_corners": 1,
    "init_from": "policies/four_finger_generalist/student",
}
"""What ``--generalist`` (``python -m train.ppo generalist``) sets as the defaults: one policy
for the sphere, the cylinder and the cube (drawn per episode), physics over the full
ranges reached by automatic domain randomisation from a quarter of them (:mod:`train.adr`),
three observed frames and an asymmetric critic, 10 s training episodes, started from the
student distilled from the three robust specialists (``python -m train.distill``). Options
given beside it still apply."""


@dataclass(frozen=True)
class TrainingRandomization:
    """The randomised physics of the training envs: with ``randomize``, each training episode
    draws its physics from :class:`envs.four_finger.Randomization` with the sampling
    probabilities ``corner_prob``, ``hard_prob`` and ``latency_prob`` and the hard region's
    gain bound ``hard_gain``, its friction, torsional, mass and gain ranges shrunk towards
    nominal by ``range_scale`` in (0, 1] (:meth:`Randomization.scaled`). Evaluations stay
    nominal. ``adr_step > 0``: automatic domain randomisation (:mod:`train.adr`): the scale
    starts at ``range_scale`` and moves by ``adr_step`` every ``adr_every`` env steps, up
    when the training episodes' drop rate is at most ``adr_widen``, down when it is above
    ``adr_narrow``."""

    randomize: bool = False
    corner_prob: float = 0.0
    hard_prob: float = 0.0
    hard_gain: float = Randomization().gain[1]
    latency_prob: float = Randomization().latency_prob
    range_scale: float = 1.0
    adr_step: float = 0.0
    adr_every: int = 122_880
    adr_widen: float = 0.10
    adr_narrow: float = 0.25
    object_share: float = 0.0

    def full_ranges(self) -> Randomization:
        """The ranges at scale 1 with the config's sampling probabilities (what ADR widens
        towards)."""
        return Randomization(
            corner_prob=self.corner_prob,
            hard_prob=self.hard_prob,
            hard_gain=self.hard_gain,
            latency_prob=self.latency_prob,
        )

    def ranges(self) -> Randomization | None:
        """The :class:`Randomization` the training envs draw from, or ``None`` without
        ``randomize`` (:class:`FourFingerError` for a bad probability, bound or scale)."""
        if not self.randomize:
            return None
        return self.full_ranges().scaled(self.range_scale)


@dataclass
class RotateConfig:
    """Everything a rotation training run depends on; saved as config.json.

    The env's settings are its groups (:mod:`envs.four_finger.settings`): ``sim``,
    ``reward``, ``starts`` and ``observation`` go to every env as they are (the evaluation
    envs' starts without failure replay and turned starts); ``randomization`` gives the
    training envs' randomised physics. Each group field names the options that set it.
    ``sim.frame_skip`` follows ``sim.timestep``: the policy period stays ``POLICY_DT``."""

    object: str = opt("sphere", "object in the hand", choices=OBJECTS)
    objects: list[str] = opt(
        [],
        "objects drawn per training and validation episode, uniformly, their identity not "
        "observed (envs.four_finger.MixedObjectRotate); empty: --object alone",
    )
    generalist: bool = opt(
        False,
        "the generalist's setup as the defaults (train.rotation_config.GENERALIST: three "
        "objects, full ranges by ADR, history, asymmetric critic); other options apply",
    )
    thesis: bool = opt(
        False, "the thesis' setup as the defaults (train.rotation.THESIS); other options apply"
    )
    sim: SimSettings = group(
        SimSettings(),
        gravity=Flag("gravity on (the thesis' hard case)"),
        torsional=Flag(
            "torsional friction at the contacts (condim 4; off: point contacts, exploitable)"
        ),
        timestep=Flag(
            "physics timestep [s]; the policy period stays 0.05 s (0.05 / timestep substeps). "
            "0.0025: about 20 %% faster, coarser (docs/bench/four_finger_env.md)"
        ),
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
    reward: RewardSettings = group(
        RewardSettings(rotation_cap=1.0, height_weight=1.0),
        drop_weight=Flag("env drop penalty weight (0: the thesis' reward)"),
        height_weight=Flag(
            "weight of the env's height term (penalises the object sagging below 0.07 m)"
        ),
        height_from=Flag(
            "the height term's reference: hold (0.07 m, about 7 mm below a held object) or "
            "start (the object's start height: every mm of sag counts)",
            choices=HEIGHT_FROM,
        ),
        slip_weight=Flag(
            "weight of the contact-slip penalty (mean sliding speed of the contacts [m/s])"
        ),
        tilt_weight=Flag(
            "weight of the tilt penalty (the object's tilt since the episode's start [rad])"
        ),
        rotation_cap=Flag("cap of the rotation reward [rad/s] (inf: the thesis' uncapped reward)"),
    )
    randomization: TrainingRandomization = group(
        TrainingRandomization(),
        randomize=Flag(
            "randomised physics in the training envs (envs.four_finger.Randomization: "
            "friction, torsional friction, mass, servo gains, latency, sensor noise); "
            "evaluations stay nominal"
        ),
        corner_prob=Flag(
            "with --randomize: probability that a training episode's physics is one of the 16 "
            "corners of the ranges (envs.four_finger.corners) instead of a uniform draw"
        ),
        hard_prob=Flag(
            "with --randomize: probability that a training episode is drawn from the hard "
            "region (friction x0.5, mass x1-2; envs.four_finger.Randomization.hard_prob)"
        ),
        hard_gain=Flag(
            "with --hard-prob: upper bound of the servo gain scales in the hard region (1.2: "
            "the whole range x0.8-1.2; 1.0: the weak half)"
        ),
        latency_prob=Flag(
            "with --randomize: probability that an episode has one step of action latency "
            "(the corners always have it)"
        ),
        range_scale=Flag(
            "with --randomize: shrink the friction, torsional, mass and gain ranges towards "
            "nominal by this factor in (0, 1] (Randomization.scaled; 0.5: friction x0.75-1.25, "
            "mass x0.71-1.41); latency and noise stay. A first curriculum stage; the corners "
            "validated are the scaled range's (with --adr-step: the full range's)"
        ),
        adr_step=Flag(
            "with --randomize: automatic domain randomisation (train.adr): the range scale "
            "starts at --range-scale and moves by this step; 0: fixed ranges"
        ),
        adr_every=Flag("with --adr-step: env steps between the curriculum's decisions"),
        adr_widen=Flag(
            "with --adr-step: widen when the training episodes' drop rate is at most this"
        ),
        adr_narrow=Flag("with --adr-step: narrow when the drop rate is above this"),
        object_share=Flag(
            "with --adr-step and --objects: object curriculum, the share of the objects' draw "
            "given in proportion to their drop rates (train.adr); 0: uniform"
        ),
    )
    starts: StartSettings = group(
        StartSettings(),
        grip=Flag(
            "start grasps' squeeze: nominal (the thesis' inward grip) or firm (also lifting "
            "the object and 1 N harder, verified to hold still at the worst --randomize "
            "corner)",
            choices=GRIPS,
        ),
        replay_prob=Flag(
            "probability that a training episode restarts a start (grasp and physics) that "
            "dropped the object before in the same env (failure replay; envs.four_finger)"
        ),
        turned_prob=Flag(
            "cube: probability that a training episode starts from a grasp with the cube "
            "turned >= 22.5 degrees from the hand's square (envs.four_finger.cube_turn)"
        ),
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
    observation: ObservationSettings = group(
        ObservationSettings(),
        history=Flag(
            "observed frames: the actor and critic see the last N sensed observations (joints, "
            "setpoints, contacts), oldest first; 1: the thesis' single frame"
        ),
        privileged=Flag(
            "asymmetric critic: the value net also reads the object's pose and velocity and "
            "the episode's physics (envs.four_finger N_PRIVILEGED); the actor reads what the "
            "hand senses",
            name="privileged_critic",
        ),
    )
    init_from: str | None = opt(
        None,
        "run or policy directory whose policy and value weights and observation statistics "
        "start this new run (transfer: e.g. a sphere policy starts a cube run); its nets must "
        "match --pi and --vf",
    )
    progress: bool = opt(True, "show a tqdm progress bar")
    verbose: int = opt(0, "SB3 verbosity")

    def __post_init__(self) -> None:
        try:  # a timestep that does not divide the policy period is parse_config's to refuse
            frame_skip = env_physics(self.sim.timestep)["frame_skip"]
        except ValueError:
            return
        if frame_skip != self.sim.frame_skip:
            self.sim = replace(self.sim, frame_skip=frame_skip)


def parse_config(argv: Sequence[str] | None = None) -> RotateConfig:
    """Parse the command line into a :class:`RotateConfig` (exit 2 on bad options)."""
    parser = build_parser(
        RotateConfig,
        description=DESCRIPTION,
        epilog="The islands-and-bridges toy: python -m train.ppo islands [options] "
        "(python -m train.ppo islands --help).",
    )
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--thesis" in argv:
        parser.set_defaults(**THESIS)
    if "--generalist" in argv:
        parser.set_defaults(**GENERALIST)
    values = vars(parser.parse_args(argv))
    try:  # the groups check their own values (envs.four_finger.settings)
        env_physics(values["timestep"])
        cfg = from_options(RotateConfig, values)
    except ValueError as e:
        parser.error(str(e))
    problems = config_problems(cfg)
    if problems:
        parser.error("; ".join(problems))
    return cfg


def config_problems(cfg: RotateConfig) -> list[str]:
    """What is wrong with ``cfg`` beyond its groups' own checks, one message per problem
    naming the options (empty when nothing is)."""
    ints = ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs", "episode_steps")
    problems = option_problems(cfg, ints)
    if cfg.eval_episodes < 0 or cfg.checkpoint_every < 1 or cfg.threads < 1 or cfg.workers < 0:
        problems.append(
            "--eval-episodes and --workers must be >= 0, --checkpoint-every and --threads >= 1"
        )
    rnd = cfg.randomization
    if cfg.observation.privileged and cfg.shield != "none":
        problems.append("--privileged-critic cannot be combined with a --shield")
    if cfg.shield.startswith("lookahead") and rnd.randomize and rnd.latency_prob > 0:
        problems.append("--shield lookahead cannot shield action latency: --latency-prob 0")
    try:  # --corner-prob, --hard-prob, --hard-gain, --latency-prob, --range-scale
        replace(rnd, randomize=True).ranges()  # Randomization's own checks
    except FourFingerError as e:
        problems.append(
            f"--corner-prob, --hard-prob, --hard-gain, --latency-prob, --range-scale: {e}"
        )
    if any(o not in OBJECTS for o in cfg.objects) or len(set(cfg.objects)) != len(cfg.objects):
        problems.append(f"--objects must be distinct names of {', '.join(OBJECTS)}")
    if rnd.adr_step:
        if not (0 < rnd.adr_step <= 1 and rnd.adr_every >= 1 and rnd.randomize):
            problems.append("--adr-step must be in (0, 1] with --randomize, --adr-every >= 1")
        if not 0 <= rnd.object_share < 1:
            problems.append("--object-share must be in [0, 1)")
        if not 0 <= rnd.adr_widen <= rnd.adr_narrow <= 1:
            problems.append("--adr-widen and --adr-narrow must satisfy 0 <= widen <= narrow <= 1")
    if cfg.validate_corners < 0:
        problems.append("--validate-corners must be >= 0")
    try:  # the env's own check
        cfg.starts.for_object("cube" if "cube" in cfg.objects else cfg.object)
    except FourFingerError as e:
        problems.append(f"--replay-prob, --turned-prob, --object: {e}")
    if not np.isfinite(cfg.eval_seconds) or cfg.eval_seconds <= 0:
        problems.append("--eval-seconds must be > 0")
    if cfg.init_from is not None:
        problems += _init_from_problems(cfg)
    try:
        env_physics(cfg.sim.timestep)
    except ValueError as e:
        problems.append(str(e))
    return problems


def _init_from_problems(cfg: RotateConfig) -> list[str]:
    """``--init-from``: a new run (not ``--resume``) from a directory with a policy."""
    src = policy_dir(Path(str(cfg.init_from)))
    if cfg.resume is not None:
        return ["--init-from starts a new run; it cannot be given with --resume"]
    if not (src / "vecnormalize.pkl").is_file() or not any(
        (src / f).is_file() for f in ("policy.pt", "model.zip")
    ):
        return [f"--init-from {cfg.init_from}: no policy.pt or model.zip with vecnormalize.pkl"]
    return []


def env_physics(timestep: float) -> dict[str, float | int]:
    """``timestep`` [s] and ``frame_skip`` of the env for a physics timestep that divides
    the policy period ``POLICY_DT`` (0.05 s, the thesis' 20 Hz); ValueError otherwise."""
    n = POLICY_DT / timestep if np.isfinite(timestep) and timestep > 0 else 0.0
    if n < 1 or abs(n - round(n)) > 1e-9:
        raise ValueError(f"--timestep must divide the policy period {POLICY_DT} s, got {timestep}")
    return {"timestep": float(timestep), "frame_skip": int(round(n))}
