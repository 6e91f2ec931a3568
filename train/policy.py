"""Trained policies as functions: loading a run's or a shipped policy and evaluating it.

:func:`load_policy` turns a run directory (``policy.pt`` or ``model.zip``, with
``vecnormalize.pkl`` and ``config.json``) into a deterministic ``obs -> action`` function
and the env it was trained in (:func:`policy_env`: its groups of settings); :data:`SHIPPED`
is the shipped four-finger policy (``policies/four_finger_sphere``), :data:`STATED_RANGES`
the randomised physics each shipped robust policy is stated for. :func:`evaluate` runs such
a function on ``FourFingerRotate`` from start grasps drawn with given seeds (the evaluation loop of
:mod:`train.evaluation`). Used by ``python -m train.gait``, ``python -m train.rollout`` and
the policy-based benchmarks (:mod:`train.bench`).
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from envs.four_finger import FourFingerRotate, GraspCache, StartSettings
from train.evaluation import RotationEpisode, one_by_one, run_episodes
from train.options import from_saved
from train.rotation import RotateConfig, policy_dir
from train.runfiles import check_policy_dir, load_actor_critic

__all__ = [
    "ROOT",
    "SHIPPED",
    "STATED_RANGES",
    "evaluate",
    "load_policy",
    "policy_dir",
    "policy_env",
]

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "four_finger_sphere"

#: The randomised physics each shipped robust policy is stated for: the factor ``S`` of
#: ``Randomization().scaled(S)`` (friction, torsional friction and gain bounds
#: ``1 + S (b - 1)``, mass bounds ``b**S``; latency and noise at every corner). Over it the
#: policy keeps >= 0.5 rad/s and <= 1 drop in 20 at every corner (``python -m train.heldout
#: POLICY --corners --range-scale S``, the policy's ``robustness_xS.csv``). A shipped policy
#: not named here is stated for nominal physics only.
STATED_RANGES: dict[str, float] = {
    "four_finger_sphere_robust": 0.875,
    "four_finger_cylinder_robust": 0.25,
    "four_finger_cube_robust": 0.25,
}


def load_policy(run_dir: Path) -> tuple[Callable[[np.ndarray], np.ndarray], dict[str, Any]]:
    """A deterministic ``obs -> action`` function and the keyword arguments of
    ``FourFingerRotate`` that the policy runs in (:func:`policy_env`). Of a policy with a
    privileged critic the function reads only what the actor reads (the frames; the critic's
    entries, which the actor masks, may be missing or of another object set).

    ``run_dir`` holds ``policy.pt`` (SB3 ``ActorCriticPolicy.save``) or ``model.zip``, plus
    ``vecnormalize.pkl`` (observation statistics, frozen) and ``config.json`` (either layout:
    :func:`train.options.from_saved`); a training run that kept a best validated checkpoint
    is read from its ``best/`` (:func:`train.rotation.policy_dir`), the policy its
    evaluations and export name. :class:`~train.runfiles.PolicyError` names what a directory
    lacks.
    """
    run_dir = check_policy_dir(Path(run_dir))
    policy = load_actor_critic(run_dir)
    with (run_dir / "vecnormalize.pkl").open("rb") as f:
        norm = pickle.load(f)
    cfg = from_saved(RotateConfig, json.loads((run_dir / "config.json").read_text()))
    mean, var = norm.obs_rms.mean, norm.obs_rms.var
    clip, eps = norm.clip_obs, norm.epsilon
    seen = int(getattr(policy, "actor_obs", len(mean)))  # what the actor reads of an observation

    def act(obs: np.ndarray) -> np.ndarray:
        o = np.atleast_2d(obs)  # one observation or a batch
        x = np.zeros((len(o), len(mean)), dtype=np.float32)  # the critic's entries stay 0
        m, v = mean[:seen], var[:seen]
        x[:, :seen] = np.clip((o[:, :seen] - m) / np.sqrt(v + eps), -clip, clip)
        a, _ = policy.predict(x[0] if np.ndim(obs) == 1 else x, deterministic=True)
        return a

    return act, policy_env(cfg)


def policy_env(cfg: RotateConfig) -> dict[str, Any]:
    """The env a policy trained with ``cfg`` runs in, as ``FourFingerRotate`` keyword
    arguments: the run's ``object`` and its groups ``sim`` and ``observation`` as they are,
    the start grasps of its grip (uniform over the cache: no failure replay, no turned
    starts), nominal physics and the env's own reward (the thesis' rotation rate; what the
    evaluations measure does not depend on it)."""
    return {
        "object": cfg.object,
        "sim": cfg.sim,
        "starts": StartSettings(grip=cfg.starts.grip),
        "observation": cfg.observation,
    }


def evaluate(
    act: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict,
    episodes: int,
    seconds: float,
    seed: int = 0,
    start_grasps: GraspCache | None = None,
) -> dict[str, float]:
    """Deterministic policy over ``episodes`` episodes of ``seconds`` from start grasps drawn
    with ``seed`` (episode ``i``: ``env.reset(seed=seed + i)``): mean/median speed [rad/s]
    (turned angle / episode time; a drop ends an episode) and drop rate. ``start_grasps``: a
    :class:`envs.four_finger.GraspCache` to start from instead of the env's own (the same
    start states under other physics)."""
    env = FourFingerRotate(**env_kwargs)
    if start_grasps is not None:
        env.grasps = start_grasps
    n = int(round(seconds / env.dt))
    eps = run_episodes(
        [env],
        episodes,
        one_by_one(act),
        RotationEpisode,
        reset_seed=lambda i, ep: seed + ep,
        max_steps=n,
    )
    env.close()
    speeds = [e["speed_rad_s"] for e in eps]
    return {
        "episodes": episodes,
        "speed_rad_s": float(np.mean(speeds)),
        "speed_median_rad_s": float(np.median(speeds)),
        "speed_p10_rad_s": float(np.percentile(speeds, 10)),
        "drop_rate": float(np.mean([e["dropped"] for e in eps])),
    }
