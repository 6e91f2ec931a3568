"""PPO training throughput on the four-finger env: ``python -m train.bench training``.

Env steps per second including the PPO updates, with ``python -m train.ppo``'s default
settings (4 x 512 nets, 16 envs, 6,144-step rollouts), the envs stepped in the training
process, in 2 worker processes (``train.vec.ChunkedVecEnv``), and in 2 worker processes with
pipelined rollouts (``train.pipeline.PipelinedPPO``, the default), beside the thesis' 474
env steps/s (15.36M steps in about 9 h). The three setups take turns rollout by rollout in
one process (``--rollouts`` each); the ratio column is the median of the per-turn ratios to
the in-process setup (:func:`train_steps_per_second`).

Writes ``--out``/four_finger_training.csv. (The env-only rows are ``python -m envs.bench``'s
four_finger_env.csv: training lives in ``train``.)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecNormalize

from envs.bench import THESIS_STEPS_PER_S
from stability.io import write_csv
from train import rotation
from train.seeding import RunSeeds
from train.vec import make_vec_env

__all__ = ["TRAIN_SETUPS", "add_parser", "run", "train_steps_per_second"]

TRAIN_SETUPS = {  # name: (worker processes, pipelined rollouts)
    "PPO training (4x512, 16 envs in-process)": (0, False),
    "PPO training (4x512, 16 envs 2 worker processes)": (2, False),
    "PPO training (4x512, 16 envs 2 workers, pipelined: default)": (2, True),
}


def train_steps_per_second(rollouts: int = 6) -> dict[str, list[float]]:
    """PPO training throughput with train.ppo's defaults (env steps/s including updates),
    per setup of :data:`TRAIN_SETUPS`: all setups are built (and warmed up by one rollout
    and update) in this process, then take turns, one rollout + update each, ``rollouts``
    times, so that a drift of the machine's speed hits them alike."""
    cfg = rotation.RotateConfig()
    torch.set_num_threads(cfg.threads)
    n = cfg.n_steps * cfg.n_envs
    built = {}
    for name, (workers, pipeline) in TRAIN_SETUPS.items():
        thunks = [rotation.make_env(cfg, s) for s in RunSeeds(0).envs("train", cfg.n_envs)]
        vec = VecNormalize(make_vec_env(thunks, workers, parts=2 if pipeline else 1))
        model = rotation.build_model(cfg, vec)  # PipelinedPPO: plain PPO unless parts >= 2
        cb = rotation.RolloutThreads(cfg.threads) if workers else None
        model.learn(n, callback=cb)  # warm-up: worker start, first update
        built[name] = (model, cb, vec)
    rates: dict[str, list[float]] = {name: [] for name in built}
    for r in range(rollouts):
        order = list(built) if r % 2 == 0 else list(built)[::-1]
        for name in order:
            model, cb, _ = built[name]
            t = time.perf_counter()
            model.learn(n, callback=cb, reset_num_timesteps=False)
            rates[name].append(n / (time.perf_counter() - t))
    for _, _, vec in built.values():
        vec.close()
    return rates


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """The ``training`` subcommand."""
    p = sub.add_parser(
        "training",
        help="PPO training throughput (env steps/s including updates)",
        description=(__doc__ or "").split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--rollouts", type=int, default=6,
                   help="rollouts (6,144 steps + update) per training setup")  # fmt: skip
    p.add_argument("--out", default="bench_out", help="directory for the CSV")
    p.set_defaults(run=run, parser=p)
    return p


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    """Measure, print, write four_finger_training.csv; returns the rows."""
    if args.rollouts < 1:
        args.parser.error("--rollouts must be >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rates = train_steps_per_second(args.rollouts)
    rows: list[dict[str, object]] = []
    first = None
    for name, sps in rates.items():
        med = float(np.median(sps))
        first = first or sps
        ratio = float(np.median(np.array(sps) / np.array(first)))
        rows.append(
            {
                "config": name,
                "env_steps_per_s": round(med, 1),
                "min": round(min(sps), 1),
                "max": round(max(sps), 1),
                "ratio_to_in_process": round(ratio, 2),
            }
        )
        print(f"{name}: {med:.0f} env steps/s including updates (x{ratio:.2f} in-process)")
    thesis = {"config": "thesis training (server)", "env_steps_per_s": round(THESIS_STEPS_PER_S)}
    rows.append(thesis)
    write_csv(out / "four_finger_training.csv", rows)
    print(f"wrote {out / 'four_finger_training.csv'}")
    return rows
