"""The main job over several seeds: ``python -m train.ppo seeds --seeds 3 [options]``.

Trains the rotation configuration (:mod:`train.rotation`; every option after the seeds
options is passed on, so ``python -m train.ppo seeds --seeds 3`` trains the default main job)
once per seed ``--first-seed .. --first-seed + --seeds - 1``, one after the other, then
evaluates each run's policy (its best validated checkpoint, ``best/``, when it kept one:
:func:`train.policy.policy_dir`) on the held-out start grasps
(:func:`train.heldout.evaluate_heldout`: ``--episodes`` episodes of 20 s from test grasps no
training run uses) and writes to ``--out``:

    seeds.csv   one row per seed: env steps, training wall time, net speed [rad/s] with its
                95 % interval, summed per-step speed, drops with the 95 % Wilson interval
    seeds.png   speed and drop rate per seed with their intervals, and the learning curves
                (the trainers' own validation evaluations over env steps)
    <run dirs>  the runs themselves (train.rotation's layout)

``--runs DIR [DIR ...]`` skips training and evaluates existing run directories instead.
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stability.cli import ArgumentParser
from stability.io import write_csv
from train import rotation
from train.heldout import TEST_GRASPS, evaluate_heldout
from train.policy import load_policy

__all__ = ["evaluate_runs", "main", "plot_seeds"]

COLUMNS = [
    "seed", "run", "steps", "train_minutes", "episodes", "speed_rad_s", "speed_lo", "speed_hi",
    "summed_rad_s", "drops", "drop_rate", "drop_lo", "drop_hi",
]  # fmt: skip


def evaluate_runs(runs: Sequence[Path], episodes: int = TEST_GRASPS) -> list[dict[str, Any]]:
    """One :data:`COLUMNS` row per run directory: its held-out evaluation and training size."""
    rows = []
    for run in runs:
        act, kw = load_policy(run)
        r = evaluate_heldout(act, kw, episodes)
        cfg = json.loads((run / "config.json").read_text())
        ev = json.loads((run / "eval.json").read_text()) if (run / "eval.json").is_file() else {}
        rows.append(
            {
                "seed": cfg["seed"],
                "run": run.name,
                "steps": ev.get("num_timesteps", ""),
                "train_minutes": round(ev["train_seconds"] / 60, 1) if ev else "",
                "episodes": r["episodes"],
                "speed_rad_s": round(r["speed_rad_s"], 3),
                "speed_lo": round(r["speed_ci95"][0], 3),
                "speed_hi": round(r["speed_ci95"][1], 3),
                "summed_rad_s": round(r["summed_rad_s"], 3),
                "drops": r["drops"],
                "drop_rate": round(r["drop_rate"], 3),
                "drop_lo": round(r["drop_ci95"][0], 3),
                "drop_hi": round(r["drop_ci95"][1], 3),
            }
        )
        print(
            f"seed {cfg['seed']} ({run.name}): net {r['speed_rad_s']:.3f} rad/s "
            f"[{r['speed_ci95'][0]:.3f}, {r['speed_ci95'][1]:.3f}], drops {r['drops']}/"
            f"{r['episodes']} [{r['drop_ci95'][0]:.3f}, {r['drop_ci95'][1]:.3f}]"
        )
    return rows


def plot_seeds(rows: Sequence[dict[str, Any]], runs: Sequence[Path], out: Path) -> Path:
    """seeds.png: per-seed speed and drop rate with 95 % intervals; learning curves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    x = np.arange(len(rows))
    labels = [str(r["seed"]) for r in rows]
    panels = (
        ("speed_rad_s", "speed", "o", "C0", rotation.TARGET_SPEED, "target >= 0.5 rad/s",
         "net turn speed [rad/s]"),
        ("drop_rate", "drop", "s", "C3", rotation.MAX_DROP_RATE, "target <= 5 %", "drop rate"),
    )  # fmt: skip
    for a, (key, pre, fmt, color, target, label, ylabel) in zip(ax[:2], panels, strict=False):
        v = np.array([float(r[key]) for r in rows])
        lo = np.array([float(r[f"{pre}_lo"]) for r in rows])
        hi = np.array([float(r[f"{pre}_hi"]) for r in rows])
        a.errorbar(x, v, yerr=[v - lo, hi - v], fmt=fmt, color=color, capsize=4)
        a.axhline(target, color="gray", ls=":", label=label)
        a.set_ylabel(ylabel)
    n = rows[0]["episodes"] if rows else 0
    for a, t in zip(ax[:2], ("speed", "drops"), strict=True):
        a.set_xticks(x, labels)
        a.set_xlabel("seed")
        a.set_title(f"held-out {t}: {n} x 20 s, 95 % intervals")
        a.legend(loc="best")
        a.grid(alpha=0.3)
    for run, r in zip(runs, rows, strict=True):
        ev = run / "eval.csv"
        if not ev.is_file():
            continue
        with ev.open() as f:
            e = list(csv.DictReader(f))
        steps = [int(v["steps"]) for v in e]
        ax[2].plot(
            steps, [float(v["speed_rad_s"]) for v in e], "o-", label=f"seed {r['seed']} speed"
        )
        ax[2].plot(
            steps,
            [float(v["drop_rate"]) for v in e],
            "x--",
            alpha=0.6,
            label=f"seed {r['seed']} drops",
        )
    ax[2].set_xlabel("env steps")
    ax[2].set_title("learning curves (validation, 20 x 20 s)")
    ax[2].legend(fontsize=7)
    ax[2].grid(alpha=0.3)
    fig.tight_layout()
    path = out / "seeds.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    p = ArgumentParser(
        prog="python -m train.ppo seeds",
        description=(__doc__ or "").split("\n\n")[0],
        epilog="Other options go to the trainer (python -m train.ppo --help).",
    )
    p.add_argument("--seeds", type=int, default=3, help="number of seeds")
    p.add_argument("--first-seed", type=int, default=1, help="first seed")
    p.add_argument("--episodes", type=int, default=TEST_GRASPS, help="held-out episodes per seed")
    p.add_argument("--out", default="runs/seeds", help="directory for the runs, CSV and chart")
    p.add_argument("--runs", nargs="+", default=None, help="evaluate these run dirs, no training")
    a, rest = p.parse_known_args(argv)
    if a.seeds < 1 or a.first_seed < 0 or not 1 <= a.episodes <= TEST_GRASPS:
        p.error(f"--seeds >= 1, --first-seed >= 0 and --episodes in [1, {TEST_GRASPS}]")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.runs:
        runs = [Path(r) for r in a.runs]
    else:
        runs = []
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            res = rotation.main([*rest, "--seed", str(seed), "--out", str(out)])
            runs.append(Path(res["run_dir"]))
    torch.set_num_threads(1)
    rows = evaluate_runs(runs, a.episodes)
    write_csv(out / "seeds.csv", rows, columns=COLUMNS)
    plot_seeds(rows, runs, out)
    sp = [r["speed_rad_s"] for r in rows]
    dr = [r["drop_rate"] for r in rows]
    print(
        f"{len(rows)} seeds: net speed {min(sp):.3f}-{max(sp):.3f} rad/s (mean {np.mean(sp):.3f}), "
        f"drop rate {min(dr):.3f}-{max(dr):.3f}; wrote {out / 'seeds.csv'} and {out / 'seeds.png'}"
    )
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
