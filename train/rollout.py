"""Four-finger rotation rollouts as rerun recordings: ``python -m train.rollout``.

Runs a saved policy (default: the shipped ``policies/four_finger_sphere``;
``--policy DIR`` for another run or policy directory; ``--random`` for uniform
random actions) on ``ihm/FourFingerRotate-v0`` for ``--episodes`` episodes of at
most ``--steps`` policy steps (20 Hz: 400 = 20 s; a drop ends an episode),
without a shield, with the QP grasp shield (``shields.GraspShield``), or both
(``--shield none|qp|both``), and writes one ``.rrd`` per run (one episode under one
shield setting) to ``--out``, named
``FourFingerRotate-<object>__<agent>__<shield>__<seed>__<time>.rrd``.
Episode ``i`` starts from the cached grasp drawn with seed ``--seed + i`` under
every shield setting, so the runs of one episode start alike. Policy actions are
deterministic, on observations normalised with the run's frozen ``VecNormalize``
statistics (:func:`train.policy.load_policy`).

Each recording (:class:`ihm.rerun_log.SceneRecorder`; timelines ``step`` and
``sim_time`` [s]) holds, at step ``k`` (the state after ``k`` actions; step 0 is
the start grasp):

* ``world/geoms/...``, ``world/object``, ``world/contacts/points`` and
  ``world/contacts/forces``: the hand and object, and every contact of the object
  with the force on it (the hand's, or the palm's or floor's), as MuJoCo left them
  after the step's last physics substep;
* for ``k >= 1``, what led to that state: ``actions/agent/<actuator>`` (the
  policy's action, in ``[-1, 1]``, actuators ``ihm.hands.four_finger.ACTUATOR_NAMES``)
  and ``actions/executed/<actuator>`` (what the env applied: the shield's
  ``info["executed_action"]``, else the agent's), ``shield/intervened`` (0/1),
  ``shield/correction`` (``|executed - clip(agent)|``, 0 without a shield) and
  ``reward`` (the mean yaw rate over the step [rad/s]);
* ``rotation_angle``: the object's turned angle about +z since the start [rad].

The file carries a blueprint: the 3D view beside time series of reward, angle,
actions and shield. Open with ``rerun runs/rollouts/<file>.rrd`` (several files at
once open side by side). Prints one line per run: the mean rotation speed
(turned angle / episode time, rad/s), whether the object was dropped and how
often the shield intervened.
"""

from __future__ import annotations

import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import rerun.blueprint as rrb

from ihm.hands.four_finger import ACTUATOR_NAMES, NU
from ihm.rerun_log import SceneRecorder
from shields.qp import BACKENDS
from train.policy import SHIPPED, load_policy
from train.rotation import RotateConfig, make_env
from train.runfiles import PolicyError, check_policy_dir
from train.sb3 import build_parser, opt

__all__ = ["SHIELDS", "RolloutConfig", "blueprint", "main", "parse_config", "run_episode"]

SHIELDS = ("none", "qp", "both")
GROUPS = (0, 1, 2)  # geom groups logged: world, object, visual (not the collision capsules)
APP_ID = "ihm-rollout"  # rerun app ids: letters, digits, - and _ (a "." gets rewritten)


@dataclass
class RolloutConfig:
    """Everything a rollout depends on (every field is a command-line option)."""

    policy: str | None = opt(
        None,
        "policy or run directory (policy.pt or model.zip, vecnormalize.pkl, config.json); "
        "default: the shipped policies/four_finger_sphere",
    )
    random: bool = opt(
        False,
        "uniform random actions in [-1, 1]^12 instead of a policy (env: the sphere, gravity, "
        "torsional friction)",
    )
    episodes: int = opt(1, "episodes per shield setting")
    steps: int = opt(400, "policy steps per episode (20 Hz: 400 = 20 s); a drop ends it early")
    seed: int = opt(0, "episode i starts from the cached grasp drawn with seed + i")
    shield: str = opt(
        "both",
        "none: the bare env; qp: wrapped in shields.GraspShield; both: one run of each",
        choices=SHIELDS,
    )
    backend: str = opt(
        "daqp", "QP backend of the grasp shield (GraspShield(backend=...))", choices=BACKENDS
    )
    force_scale: float = opt(0.02, "force arrow length per newton [m/N]")
    out: str = opt("runs/rollouts", "directory that receives the .rrd files")
    threads: int = opt(1, "torch threads for the policy's forward pass")


def _policy_problems(path: Path) -> list[str]:
    try:
        check_policy_dir(path)
    except PolicyError as e:
        return [f"--policy {e}"]
    return []


def parse_config(argv: Sequence[str] | None = None) -> RolloutConfig:
    """Parse the command line into a :class:`RolloutConfig`; bad options exit with status 2
    and a message naming the option."""
    parser = build_parser(
        RolloutConfig, prog="python -m train.rollout", description=(__doc__ or "").split("\n\n")[0]
    )
    cfg = RolloutConfig(**vars(parser.parse_args(argv)))
    problems = [
        f"--{k} must be >= 1" for k in ("episodes", "steps", "threads") if getattr(cfg, k) < 1
    ]
    if cfg.seed < 0:
        problems.append("--seed must be >= 0")
    if not np.isfinite(cfg.force_scale) or cfg.force_scale < 0:
        problems.append("--force-scale must be a finite number >= 0 [m/N]")
    if cfg.random and cfg.policy is not None:
        problems.append("--random and --policy exclude each other")
    if not cfg.random:
        problems += _policy_problems(Path(cfg.policy) if cfg.policy else SHIPPED)
    if problems:
        parser.error("; ".join(problems))
    return cfg


def blueprint() -> rrb.Blueprint:
    """The viewer layout: the 3D scene (``world/**``) beside time series of the reward,
    the turned angle, the actions (agent and executed) and the shield."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="hand and object", origin="world", contents="world/**"),
            rrb.Vertical(
                rrb.TimeSeriesView(name="reward [rad/s]", origin="reward"),
                rrb.TimeSeriesView(name="rotation angle [rad]", origin="rotation_angle"),
                rrb.TimeSeriesView(name="actions: agent, executed", origin="actions"),
                rrb.TimeSeriesView(name="shield", origin="shield"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def run_episode(
    env: gym.Env,
    act: Callable[[np.ndarray], np.ndarray] | None,
    path: Path,
    *,
    seed: int,
    force_scale: float,
    name: str = "",
) -> dict[str, Any]:
    """One episode from the grasp drawn with ``seed``, recorded to ``path``.

    ``act`` maps an observation to an action (None: uniform random actions from a
    generator seeded with ``seed``); ``env`` is a (possibly shielded, time-limited)
    ``FourFingerRotate``. Returns the path, steps, mean rotation speed [rad/s],
    dropped flag, number of shield interventions and the shield statuses seen.
    """
    base = env.unwrapped
    model, data, dt = base.model, base.data, float(base.dt)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    interventions, statuses, steps = 0, Counter[str](), 0
    term = False
    with SceneRecorder(
        model, path, app_id=APP_ID, recording_name=name, groups=GROUPS, blueprint=blueprint()
    ) as rec:
        rec.set_time(0, 0.0)
        rec.log_poses(data)
        rec.log_object(data, force_scale=force_scale)
        rec.log_scalars({"rotation_angle": 0.0})
        while True:
            a = act(obs) if act is not None else rng.uniform(-1.0, 1.0, NU).astype(np.float32)
            a = np.asarray(a, dtype=np.float32)
            obs, reward, term, trunc, info = env.step(a)
            steps += 1
            executed = np.asarray(info.get("executed_action", a), dtype=float)
            intervened = bool(info.get("shield_intervened", False))
            interventions += intervened
            if "shield_status" in info:
                statuses[str(info["shield_status"])] += 1
            rec.set_time(steps, steps * dt)
            rec.log_poses(data)
            rec.log_object(data, force_scale=force_scale)
            scalars = {f"actions/agent/{n}": a[i] for i, n in enumerate(ACTUATOR_NAMES)}
            scalars |= {f"actions/executed/{n}": executed[i] for i, n in enumerate(ACTUATOR_NAMES)}
            scalars |= {
                "shield/intervened": float(intervened),
                "shield/correction": float(info.get("shield_correction", 0.0)),
                "reward": float(reward),
                "rotation_angle": float(info["rotation_angle"]),
            }
            rec.log_scalars(scalars)
            if term or trunc:
                break
    return {
        "path": str(path),
        "steps": steps,
        "seconds": steps * dt,
        "speed_rad_s": float(info["rotation_angle"]) / (steps * dt),
        "dropped": bool(term),
        "interventions": interventions,
        "statuses": dict(statuses),
        "wall_s": time.perf_counter() - t0,
    }


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Run and record every (episode, shield setting); print one line per run; return the
    runs' summaries (:func:`run_episode`, plus ``shield``, ``episode`` and ``seed``)."""
    cfg = parse_config(argv)
    act: Callable[[np.ndarray], np.ndarray] | None = None
    if cfg.random:
        agent, env_opts = "random", {}
    else:
        import torch

        torch.set_num_threads(cfg.threads)
        policy_dir = Path(cfg.policy) if cfg.policy else SHIPPED
        act, env_opts = load_policy(policy_dir)
        agent = policy_dir.resolve().name
    # the policy's env (its object and groups of settings) as a RotateConfig
    env_cfg = RotateConfig(**env_opts)
    settings = ["none", "qp"] if cfg.shield == "both" else [cfg.shield]
    # train.rotation.make_env wraps the env in shields.GraspShield for shield "qp"
    envs: dict[str, gym.Env] = {
        s: make_env(replace(env_cfg, shield=s, shield_backend=cfg.backend), max_steps=cfg.steps)()
        for s in settings
    }
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(cfg.out)
    results = []
    for ep in range(cfg.episodes):
        seed = cfg.seed + ep
        for s in settings:
            stem = f"FourFingerRotate-{env_cfg.object}__{agent}__{s}__{seed}__{stamp}"
            res = run_episode(
                envs[s],
                act,
                out / f"{stem}.rrd",
                seed=seed,
                force_scale=cfg.force_scale,
                name=f"{agent}, shield {s}, seed {seed}",
            )
            res |= {"shield": s, "episode": ep, "seed": seed}
            results.append(res)
            shield_note = f"{res['interventions']}/{res['steps']} steps"
            if res["statuses"]:
                shield_note += (
                    " (" + ", ".join(f"{k} {v}" for k, v in res["statuses"].items()) + ")"
                )
            print(
                f"{res['path']}: shield {s}, {res['steps']} steps ({res['seconds']:.1f} s), "
                f"{res['speed_rad_s']:.3f} rad/s, dropped: {'yes' if res['dropped'] else 'no'}, "
                f"shield interventions: {shield_note}; {res['wall_s']:.1f} s wall"
            )
    for env in envs.values():
        env.close()
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
