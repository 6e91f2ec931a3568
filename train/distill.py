"""Distil the robust specialists into one student: ``python -m train.distill``.

A privileged teacher and a student that reads the hand's history (HORA's structure), by
DAgger (Ross et al. 2011). The teachers are the shipped robust policies, one per object
(:data:`TEACHERS`); their privilege is the object's identity, which selects the teacher of
each episode. The student is the generalist's actor (``python -m train.ppo generalist``'s
config, :data:`train.rotation_config.GENERALIST`): it reads the last three sensed frames
and never the object. Per iteration ``i``:

1. ``steps`` env steps in ``ihm/FourFingerRotateMixed-v0`` (the object drawn per episode,
   physics from the generalist's ranges at ``--range-scale``, latency and noise), each env
   acting with its teacher's action in the first iteration and the student's after (the
   student's own mistakes are what it must learn to recover from); every step's observation
   is stored with the action the episode's teacher takes there (deterministic, on the
   newest frame, the one frame it was trained on);
2. the student's mean action is fitted to the teachers' actions over everything stored so
   far (mean squared error, Adam, ``epochs`` passes).

The observation statistics start from the sphere teacher's (tiled over the frames) and
follow the collected observations. The output directory is a policy directory
(``policy.pt``, ``vecnormalize.pkl``, ``config.json``) that ``python -m train.heldout``
evaluates and ``python -m train.ppo generalist --init-from DIR`` starts from, with
``distill.csv``: per iteration the steps, who acted, each object's episodes and drop rate
under that actor, and the fit's loss.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from envs.four_finger import N_OBS, TRAIN_OBJECTS
from stability.io import write_csv
from train.options import build_parser, from_options, opt, to_json
from train.policy import ROOT, load_policy
from train.rotation import TASK, make_env, transfer_normalizer
from train.rotation_config import parse_config
from train.sb3 import seed_everything
from train.seeding import RunSeeds
from train.vec import make_vec_env

__all__ = ["TEACHERS", "DistillConfig", "distill", "main"]

TEACHERS = {o: ROOT / "policies" / f"four_finger_{o}_robust" for o in TRAIN_OBJECTS}
"""The teacher of each training object: the shipped robust policies."""


@dataclass(frozen=True)
class DistillConfig:
    """The distillation's settings (module doc), one option of ``python -m train.distill``
    each; the defaults made ``policies/four_finger_generalist/student``."""

    iterations: int = opt(8, "DAgger iterations (the first acted by the teachers)")
    steps: int = opt(40_960, "env steps per iteration")
    n_envs: int = opt(16, "envs")
    workers: int = opt(2, "processes that step the envs (train.vec); 0: in this one")
    epochs: int = opt(6, "passes over all labels so far per fit")
    batch: int = opt(1024, "minibatch size of the fit")
    lr: float = opt(3e-4, "Adam learning rate of the fit")
    range_scale: float = opt(0.25, "the physics ranges' share of the full ranges (in (0, 1])")
    seed: int = opt(1, "run seed")
    out: str = opt("runs/distill", "the policy directory written")


def _student_config(c: DistillConfig) -> Any:
    """The generalist's config for the student (its nets, observation, env settings),
    starting from the sphere teacher (its actor and critic widened to the student's
    observation)."""
    return parse_config(["--generalist", "--range-scale", str(c.range_scale), "--n-envs",
                         str(c.n_envs), "--seed", str(c.seed), "--adr-step", "0",
                         "--init-from", str(TEACHERS["sphere"]), "--no-progress"])  # fmt: skip


def distill(c: DistillConfig) -> Path:
    """Run the DAgger iterations of the module doc; returns the policy directory."""
    out = Path(c.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = _student_config(c)
    seeds = RunSeeds(cfg.seed)
    seed_everything(seeds.global_seed)
    vec = make_vec_env([make_env(cfg, s) for s in seeds.envs("train", c.n_envs)], c.workers)
    norm = transfer_normalizer(cfg, vec)
    norm.norm_reward = False
    model = TASK.new_model(cfg, norm)
    teachers = [load_policy(TEACHERS[o])[0] for o in cfg.objects]
    policy = model.policy
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    opt = torch.optim.Adam(actor, lr=c.lr)
    rng = np.random.default_rng(seeds.global_seed)
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    rows = []
    newest = slice(N_OBS * (cfg.observation.history - 1), N_OBS * cfg.observation.history)
    obs = norm.reset()
    for it in range(c.iterations):
        teacher_acts = it == 0
        eps = {o: [0, 0] for o in cfg.objects}
        for _ in range(c.steps // c.n_envs):
            raw = norm.get_original_obs()
            which = np.argmax(raw[:, -len(cfg.objects) :], axis=1)
            target = np.empty((c.n_envs, 12), dtype=np.float32)
            for k in range(len(cfg.objects)):
                sel = which == k
                if sel.any():
                    target[sel] = teachers[k](raw[sel][:, newest])
            xs.append(raw.copy())
            ys.append(target)
            act = target if teacher_acts else policy.predict(obs, deterministic=True)[0]
            obs, _, dones, infos = norm.step(act)
            for d, info in zip(dones, infos, strict=True):
                if d:
                    eps[info["object"]][0] += 1
                    eps[info["object"]][1] += bool(info.get("dropped"))
        loss = _fit(policy, opt, norm, np.concatenate(xs), np.concatenate(ys), c, rng)
        row: dict[str, Any] = {
            "iteration": it, "steps": (it + 1) * c.steps,
            "actor": "teacher" if teacher_acts else "student",
            "samples": sum(len(x) for x in xs), "loss": round(loss, 5),
        }  # fmt: skip
        for o, (n, d) in eps.items():
            row[f"{o}_episodes"], row[f"{o}_drop_rate"] = n, round(d / n, 4) if n else None
        rows.append(row)
        print(row, flush=True)
        write_csv(out / "distill.csv", rows, list(rows[0]))
    policy.save(str(out / "policy.pt"))
    norm.save(str(out / "vecnormalize.pkl"))
    teachers_used = {o: str(TEACHERS[o].relative_to(ROOT)) for o in cfg.objects}
    distilled = {"teachers": teachers_used, "iterations": c.iterations, "steps": c.steps}
    (out / "config.json").write_text(to_json(cfg, task="rotation", distilled=distilled))
    vec.close()
    return out


def _fit(policy: Any, opt: torch.optim.Optimizer, norm: Any, x: np.ndarray, y: np.ndarray,
         c: DistillConfig, rng: np.random.Generator) -> float:  # fmt: skip
    """``epochs`` passes of Adam on the mean squared error between the student's mean action
    on the normalised ``x`` and the teachers' actions ``y``; the last pass's mean loss."""
    xt = torch.as_tensor(norm.normalize_obs(x), dtype=torch.float32)
    yt = torch.as_tensor(y, dtype=torch.float32)
    policy.set_training_mode(True)
    loss_sum = 0.0
    for _ in range(c.epochs):
        order = torch.as_tensor(rng.permutation(len(xt)))
        loss_sum, n = 0.0, 0
        for i in range(0, len(order), c.batch):
            b = order[i : i + c.batch]
            mean = policy.get_distribution(xt[b]).distribution.mean
            loss = torch.mean((mean - yt[b]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum, n = loss_sum + loss.item() * len(b), n + len(b)
        loss_sum /= n
    policy.set_training_mode(False)
    return loss_sum


def main(argv: Sequence[str] | None = None) -> Path:
    """``python -m train.distill [--OPTION VALUE ...]`` (the fields of :class:`DistillConfig`);
    returns the policy directory."""
    p = build_parser(DistillConfig, prog="python -m train.distill",
                     description=(__doc__ or "").split("\n\n")[0])  # fmt: skip
    a = p.parse_args(sys.argv[1:] if argv is None else argv)
    torch.set_num_threads(1)
    return distill(from_options(DistillConfig, vars(a)))


if __name__ == "__main__":
    main()
