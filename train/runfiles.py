"""What a rotation run directory holds, and how a run starts from another.

Checkpoints (``model.zip``, ``vecnormalize.pkl``), the kept policy (``best/``,
:func:`policy_dir`) and its export (:func:`export_policy`); ``--init-from`` (the weights and
observation statistics of another run or policy, widened to more observed frames:
:func:`init_weights`, :func:`init_normalizer`); and what ``--resume`` records when a fine-tune
changes the run (:func:`start_randomizing`, :data:`FINETUNE`, :func:`start_finetune`).
"""

from __future__ import annotations

import json
import pickle
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from train.options import from_saved, get_option, record_options, set_options
from train.sb3 import PrivilegedCriticPolicy

__all__ = [
    "FINETUNE",
    "PolicyError",
    "check_policy_dir",
    "checkpoint",
    "export_policy",
    "given",
    "init_normalizer",
    "init_weights",
    "load_actor_critic",
    "policy_dir",
    "start_finetune",
    "start_randomizing",
]


FIRST_LAYERS = ("mlp_extractor.policy_net.0.weight", "mlp_extractor.value_net.0.weight")


def init_weights(model: PPO, source: Path) -> None:
    """Copy the policy and value weights (and the policy's log std) of the run or policy
    directory ``source`` (:func:`policy_dir`: its ``best/`` when it kept one) into ``model``;
    ValueError naming the mismatch when the nets differ.

    A source that saw fewer frames (``--history``) than ``model`` does is widened: the first
    layers' weights on the older frames are zero, so the new net computes exactly what the
    source computed from the newest frame until training uses the older ones. So are the
    weights on the privileged state of a :class:`train.sb3.PrivilegedCriticPolicy` model
    (``--privileged-critic``) started from a source without it."""
    state = load_actor_critic(Path(source)).state_dict()
    target = model.policy.state_dict()
    priv = _privileged(model)
    for k in FIRST_LAYERS:
        w, t = state.get(k), target.get(k)
        if w is not None and t is not None and w.shape != t.shape and w.shape[0] == t.shape[0]:
            n_src, n_frames = w.shape[1], t.shape[1] - priv
            if n_frames % n_src == 0:  # older frames: zeros, the source's, privileged: zeros
                z = w.shape[0]
                parts = [torch.zeros(z, n_frames - n_src), w, torch.zeros(z, priv)]
                state[k] = torch.cat(parts, dim=1)
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as e:
        raise ValueError(
            f"--init-from {source}: its nets do not match --pi/--vf/--history ({e})"
        ) from e


class PolicyError(ValueError):
    """A directory that is not a run or policy directory (what it lacks is named)."""


def check_policy_dir(run_dir: Path) -> Path:
    """:func:`policy_dir` of ``run_dir`` once it holds a policy (``policy.pt`` or
    ``model.zip``), ``vecnormalize.pkl`` and ``config.json``; else :class:`PolicyError`
    naming what is missing. Reads nothing else and creates nothing."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise PolicyError(f"{run_dir}: no such directory")
    src = policy_dir(run_dir)
    missing = [f for f in ("vecnormalize.pkl", "config.json") if not (src / f).is_file()]
    if not ((src / "policy.pt").is_file() or (src / "model.zip").is_file()):
        missing.insert(0, "policy.pt or model.zip")
    if missing:
        raise PolicyError(f"{run_dir}: not a policy directory (missing {', '.join(missing)})")
    return src


def load_actor_critic(run_dir: Path) -> ActorCriticPolicy:
    """The policy of a run or policy directory (:func:`policy_dir`: its ``best/`` when it kept
    one), on the CPU: ``policy.pt`` (``ActorCriticPolicy.save``, a shipped policy) when there
    is one, else the policy of ``model.zip``; :class:`PolicyError` when it holds neither."""
    src = policy_dir(Path(run_dir))
    if not (src / "policy.pt").is_file() and not (src / "model.zip").is_file():
        raise PolicyError(f"{run_dir}: not a policy directory (missing policy.pt or model.zip)")
    if (src / "policy.pt").is_file():
        saved = torch.load(src / "policy.pt", map_location="cpu", weights_only=False)
        cls = PrivilegedCriticPolicy if "actor_obs" in saved["data"] else ActorCriticPolicy
        return cls.load(str(src / "policy.pt"), device="cpu")
    return PPO.load(src / "model.zip", device="cpu").policy


def _privileged(model: PPO) -> int:
    """Observation entries after the actor's (the critic's privileged state), 0 if none."""
    pol = model.policy
    n = int(np.prod(pol.observation_space.shape))
    return n - pol.actor_obs if isinstance(pol, PrivilegedCriticPolicy) else 0


def init_normalizer(vec: VecEnv, source: Path, privileged: int = 0) -> VecNormalize:
    """``VecNormalize`` over ``vec`` that starts from the observation and return statistics of
    ``source`` (a run or policy directory), tiled over ``vec``'s frames when it observes
    more (``--history``); the last ``privileged`` entries, which the source did not observe,
    start at mean 0, variance 1; a source that observed what ``vec`` observes gives its
    statistics as they are. The statistics go on updating."""
    with (policy_dir(Path(source)) / "vecnormalize.pkl").open("rb") as f:
        old = pickle.load(f)
    norm = VecNormalize(vec, gamma=old.gamma)
    if old.obs_rms.mean.shape == norm.obs_rms.mean.shape:  # the same observation: as it is
        norm.obs_rms, norm.ret_rms = old.obs_rms, old.ret_rms
        return norm
    reps, rem = divmod(norm.obs_rms.mean.shape[0] - privileged, old.obs_rms.mean.shape[0])
    if rem or reps < 1:
        raise ValueError(f"--init-from {source}: observation sizes do not match")
    norm.obs_rms.mean = np.concatenate([np.tile(old.obs_rms.mean, reps), np.zeros(privileged)])
    norm.obs_rms.var = np.concatenate([np.tile(old.obs_rms.var, reps), np.ones(privileged)])
    norm.obs_rms.count = old.obs_rms.count
    norm.ret_rms = old.ret_rms
    return norm


def checkpoint(model: PPO, run_dir: Path) -> None:
    """Save model.zip and vecnormalize.pkl (written to a temporary name, then renamed)."""
    tmp = run_dir / "model.tmp.zip"
    model.save(tmp)
    tmp.replace(run_dir / "model.zip")
    env = model.get_env()
    if isinstance(env, VecNormalize):
        env.save(str(run_dir / "vecnormalize.tmp.pkl"))
        (run_dir / "vecnormalize.tmp.pkl").replace(run_dir / "vecnormalize.pkl")


def policy_dir(run_dir: Path) -> Path:
    """The directory of a run's policy: ``run_dir/best`` when the run kept its best validated
    checkpoint there (:class:`train.rotation.EvalCallback`), else ``run_dir``."""
    best = Path(run_dir) / "best"
    return best if (best / "model.zip").is_file() else Path(run_dir)


def export_policy(run_dir: Path, dest: Path) -> Path:
    """Copy a run's policy (weights only, ``ActorCriticPolicy.save``: no optimiser state) with
    its ``vecnormalize.pkl`` (:func:`policy_dir`: from ``best/`` when the run kept one, else the
    final model), and the run's ``config.json``, ``eval.json``, ``eval.csv`` and ``curve.png``
    to ``dest``: what ``python -m train.gait`` and replaying need, a quarter of ``model.zip``'s
    size. ``dest/best.json`` names the checkpoint exported."""
    src = policy_dir(run_dir)
    dest.mkdir(parents=True, exist_ok=True)
    PPO.load(src / "model.zip", device="cpu").policy.save(str(dest / "policy.pt"))
    shutil.copy(src / "vecnormalize.pkl", dest / "vecnormalize.pkl")
    for f in ("config.json", "eval.json", "eval.csv", "curve.png"):
        if (run_dir / f).is_file():
            shutil.copy(run_dir / f, dest / f)
    if src != run_dir:
        shutil.copy(src / "eval.json", dest / "best.json")
    return dest


def start_randomizing(cfg: Any, run_dir: Path, done: int) -> Any:
    """``--resume RUN --randomize`` on a run trained on nominal physics: go on with randomised
    physics (a fine-tune). config.json records it (``randomize``, ``randomized_from_step``);
    the nominal run's ``best/`` moves to ``best_nominal/`` so that ``best/`` is chosen among
    the randomised checkpoints."""
    cfg = set_options(cfg, {"randomize": True})
    record_options(run_dir / "config.json", cfg, ["randomize"], randomized_from_step=done)
    _best_aside(run_dir, "best_nominal")
    return cfg


FINETUNE = (
    "corner_prob",
    "hard_prob",
    "hard_gain",
    "latency_prob",
    "replay_prob",
    "turned_prob",
    "range_scale",
    "validate_corners",
    "rotation_cap",
    "drop_weight",
    "height_weight",
    "height_from",
    "slip_weight",
    "tilt_weight",
    "checkpoint_every",
    "eval_episodes",
    "grip",
)
"""Fields that ``--resume`` takes from the command line when given there (a fine-tune may
change them: the randomisation's sampling, the validation, the reward terms, the start
grasps' grip); every other
saved field decides."""


def given(argv: Sequence[str], field: str) -> bool:
    """Whether ``--field`` (or ``--field=...``) is on the command line ``argv``."""
    flag = "--" + field.replace("_", "-")
    return any(a == flag or a.startswith(flag + "=") for a in argv)


def start_finetune(cfg: Any, run_dir: Path, changed: Sequence[str], done: int) -> None:
    """Record the fine-tune options ``changed`` (given with ``--resume``) at their values in
    ``cfg`` in config.json (with ``finetune_from_step``); when corner validation starts, or
    the ranges whose corners are validated change (``range_scale``), the earlier ``best/``
    (chosen on other figures) moves to ``best_previous/``."""
    path = run_dir / "config.json"
    saved = from_saved(type(cfg), json.loads(path.read_text()))
    new = {f: get_option(cfg, f) for f in changed}
    starts_corners = new.get("validate_corners", 0) and not get_option(saved, "validate_corners")
    scale = get_option(saved, "range_scale")
    new_range = new.get("range_scale", scale) != scale
    record_options(path, cfg, changed, finetune_from_step=done)
    if starts_corners or new_range:
        _best_aside(run_dir, "best_previous")


def _best_aside(run_dir: Path, name: str) -> None:
    """Move an existing ``best/`` to ``name`` (replacing an earlier one) so that ``best/``
    is chosen afresh."""
    if (run_dir / "best").is_dir():
        shutil.rmtree(run_dir / name, ignore_errors=True)
        (run_dir / "best").rename(run_dir / name)
