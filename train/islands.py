"""The islands-and-bridges benchmark (thesis Fig. curves): ``python -m train.islands``.

Trains PPO (:mod:`train.ppo`, same wrapper stack and seeding) for every
combination of shield x reward x network size x seed and evaluates the
deterministic policy, with the shield kept in place, every ``--eval-every``
steps on ``--eval-episodes`` episodes. Jobs run in ``--workers`` processes.

Writes to ``--out``::

    islands.csv   one row per (shield, reward, net, seed, eval point)
    islands.png   success rate vs training steps: one panel per reward, one
                  colour per shield, line style per net size; the line is the
                  mean over seeds, the band spans min..max
    summary.md    the final table (also printed): final success rate per
                  configuration (mean, min, max over seeds) and the first
                  evaluated step where the mean reaches 99 %

By default every shield and reward runs with the medium nets (2x64, train.ppo's
default) and the smart shield also with the small ones (2x16: the network-size
study; ``--nets medium small large`` adds 2x256, about twice as slow to train);
``--study-shields none simple smart`` gives the full cross. ``--quick`` is a
smoke-sized run (1 seed, 5k steps, small nets, 20 episodes).
"""

from __future__ import annotations

import csv
import multiprocessing as mp
import sys
import time
from collections import defaultdict
from collections.abc import Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from train.ppo import REWARDS, SHIELDS, Config, build_parser, opt

__all__ = ["NETS", "BenchConfig", "main", "plot", "run_job", "summary_table"]

NETS = {"small": [16, 16], "medium": [64, 64], "large": [256, 256]}
"""Network sizes of the study; policy and value nets are separate and of equal size."""

COLUMNS = [
    "env_id",
    "shield",
    "reward",
    "net",
    "pi",
    "vf",
    "seed",
    "steps",
    "success_rate",
    "failure_rate",
    "mean_return",
    "mean_length",
    "intervention_rate",
    "episodes",
    "wall_s",
]


@dataclass
class BenchConfig:
    """Options of the benchmark (``--quick`` changes those left at their defaults)."""

    shields: list[str] = opt(list(SHIELDS), "shields to compare", choices=SHIELDS)
    rewards: list[str] = opt(list(REWARDS), "reward modes (one chart panel each)", choices=REWARDS)
    nets: list[str] = opt(
        ["medium", "small"],
        "network sizes (small: 2x16, medium: 2x64, large: 2x256); the first runs for every "
        "shield, the others for --study-shields only",
    )
    study_shields: list[str] = opt(
        ["smart"], "shields also trained with the other --nets (the network-size study)"
    )
    seeds: int = opt(3, "seeds per configuration (1..N)")
    steps: int = opt(200_000, "training steps per run")
    eval_every: int = opt(20_000, "evaluate every this many training steps (and at 0)")
    eval_episodes: int = opt(100, "episodes per evaluation (deterministic policy, shielded)")
    final_episodes: int = opt(200, "episodes of the last evaluation (at --steps)")
    workers: int = opt(2, "parallel worker processes (1: run in this process)")
    env_id: str = opt("ihm/IslandsBridges-v0", "Gymnasium id of the environment")
    # PPO settings default to train.ppo's, so the benchmark follows its tuning
    n_envs: int = opt(Config.n_envs, "training envs per run")
    n_steps: int = opt(Config.n_steps, "PPO rollout length per env")
    batch_size: int = opt(Config.batch_size, "PPO minibatch size")
    learning_rate: float = opt(Config.learning_rate, "Adam learning rate")
    out: str = opt("bench_out/islands", "output directory (islands.csv, islands.png, summary.md)")
    quick: bool = opt(False, "smoke-sized run: 1 seed, 5000 steps, small nets, 20 episodes")
    progress: bool = opt(True, "show a tqdm progress bar over all training steps")


QUICK = {
    "seeds": 1,
    "steps": 5000,
    "eval_every": 2500,
    "eval_episodes": 20,
    "final_episodes": 20,
    "nets": ["small"],
}


def parse_config(argv: Sequence[str] | None = None) -> BenchConfig:
    """Parse the command line (argparse exits with 2 and a message on bad options)."""
    parser = build_parser(BenchConfig, "python -m train.islands", (__doc__ or "").split("\n")[0])
    args = vars(parser.parse_args(argv))
    if args["quick"]:
        for name, value in QUICK.items():
            if args[name] == parser.get_default(name):
                args[name] = value
    bc = BenchConfig(**args)
    problems = [f"--nets: unknown net {n!r} (choose from {list(NETS)})" for n in bc.nets]
    problems = [p for p, n in zip(problems, bc.nets, strict=True) if n not in NETS]
    problems += [
        f"--study-shields: unknown shield {s!r}" for s in bc.study_shields if s not in SHIELDS
    ]
    positive = ("seeds", "steps", "eval_every", "eval_episodes", "final_episodes", "workers")
    for name in (*positive, "n_envs", "n_steps", "batch_size"):
        if getattr(bc, name) < 1:
            problems.append(f"--{name.replace('_', '-')} must be >= 1")
    if problems:
        parser.error("; ".join(problems))
    return bc


def _jobs(bc: BenchConfig) -> list[dict[str, Any]]:
    """Every shield with the first net; the study shields also with the other nets."""
    return [
        {"shield": s, "reward": r, "net": n, "seed": seed}
        for i, n in enumerate(bc.nets)
        for s in bc.shields
        if i == 0 or s in bc.study_shields
        for r in bc.rewards
        for seed in range(1, bc.seeds + 1)
    ]


def run_job(bc: BenchConfig, job: dict[str, Any], queue: Any = None) -> list[dict[str, Any]]:
    """Train one configuration, evaluating every ``bc.eval_every`` steps; one row per evaluation.

    ``queue`` (optional) receives the number of training steps done since the
    last report, for the progress bar of the parent process.
    """
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from train.ppo import build_envs, build_model, evaluate, seed_everything, train_callbacks

    torch.set_num_threads(1)
    cfg = Config(  # every PPO setting not named here is train.ppo's default
        env_id=bc.env_id,
        shield=job["shield"],
        reward=job["reward"],
        total_steps=bc.steps,
        seed=job["seed"],
        n_envs=bc.n_envs,
        pi=NETS[job["net"]],
        vf=NETS[job["net"]],
        learning_rate=bc.learning_rate,
        n_steps=bc.n_steps,
        batch_size=bc.batch_size,
        eval_episodes=bc.eval_episodes,
        progress=False,
    )
    # ---- seeds, all in one place (as in train.ppo) ----
    seed_everything(cfg.seed)
    train_env, eval_env = build_envs(cfg, cfg.seed)
    model = build_model(cfg, train_env)  # PPO(seed=cfg.seed)
    # ---------------------------------------------------
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    reported = 0

    def record(episodes: int = bc.eval_episodes) -> None:
        nonlocal reported
        res = evaluate(model, eval_env, episodes)
        steps = min(int(model.num_timesteps), bc.steps)
        rows.append(
            {
                "env_id": cfg.env_id,
                **job,
                "pi": "x".join(map(str, cfg.pi)),
                "vf": "x".join(map(str, cfg.vf)),
                "steps": steps,
                **{k: res[k] for k in COLUMNS if k in res},
                "wall_s": round(time.perf_counter() - t0, 2),
            }
        )
        if queue is not None:
            queue.put(steps - reported)
        reported = steps

    class EvalEvery(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= bc.steps:
                return False  # stop at the budget, not at the end of the rollout
            if self.num_timesteps >= len(rows) * bc.eval_every:
                record()
            return True

    record()  # step 0: the untrained policy
    model.learn(bc.steps, callback=[*train_callbacks(cfg), EvalEvery()])
    record(bc.final_episodes)
    train_env.close()
    eval_env.close()
    return rows


def _run_job_star(args: tuple) -> list[dict[str, Any]]:
    return run_job(*args)


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """Rows sorted by configuration, seed and steps."""
    key = lambda r: (r["net"], r["shield"], r["reward"], r["seed"], r["steps"])  # noqa: E731
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(sorted(rows, key=key))


def _curves(rows: list[dict[str, Any]]) -> dict[tuple[str, str, str], np.ndarray]:
    """(shield, reward, net) -> array (n_points, 4): steps, mean, min, max over seeds."""
    by: dict[tuple[str, str, str], dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        by[(r["shield"], r["reward"], r["net"])][int(r["steps"])].append(float(r["success_rate"]))
    return {
        k: np.array([[s, np.mean(v), np.min(v), np.max(v)] for s, v in sorted(pts.items())])
        for k, pts in by.items()
    }


COLOURS = {"none": "tab:red", "simple": "tab:blue", "smart": "tab:green"}
STYLES = {"medium": "-", "small": ":", "large": "--"}


def plot(rows: list[dict[str, Any]], path: Path, title: str = "") -> None:
    """Success rate vs training steps, one panel per reward (thesis Fig. curves)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = _curves(rows)
    rewards = [r for r in REWARDS if any(k[1] == r for k in curves)]
    fig, axes = plt.subplots(1, len(rewards), figsize=(6 * len(rewards), 4.2), squeeze=False)
    for ax, reward in zip(axes[0], rewards, strict=True):
        for (shield, rew, net), c in sorted(curves.items()):
            if rew != reward:
                continue
            colour, style = COLOURS.get(shield, "k"), STYLES.get(net, ":")
            size = "x".join(map(str, NETS[net])) if net in NETS else net
            ax.plot(c[:, 0], c[:, 1], style, color=colour, label=f"{shield}, {net} net ({size})")
            ax.fill_between(c[:, 0], c[:, 2], c[:, 3], color=colour, alpha=0.15, lw=0)
        ax.set_title(f"{reward} reward")
        ax.set_xlabel("training steps")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[0][0].set_ylabel("success rate (deterministic, shield in place)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def summary_table(rows: list[dict[str, Any]]) -> str:
    """Markdown table: final success rate per configuration and first step with mean >= 99 %."""
    lines = [
        "| shield | reward | net | final success (mean [min, max]) | first step mean >= 0.99 |",
        "|---|---|---|---|---|",
    ]
    order = {s: i for i, s in enumerate(SHIELDS)}
    curves = _curves(rows)
    keys = sorted(curves, key=lambda k: (k[2], order.get(k[0], 9), k[1]))
    for shield, reward, net in keys:
        c = curves[(shield, reward, net)]
        hit = c[c[:, 1] >= 0.99, 0]
        first = f"{int(hit[0]):,}" if len(hit) else "never"
        mean, lo, hi = c[-1, 1:]
        lines.append(f"| {shield} | {reward} | {net} | {mean:.3f} [{lo:.3f}, {hi:.3f}] | {first} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Run the benchmark, write CSV, PNG and summary; returns the rows."""
    bc = parse_config(argv)
    out = Path(bc.out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = _jobs(bc)
    print(
        f"{len(jobs)} runs x {bc.steps} steps ({bc.shields} x {bc.rewards} x {bc.nets} x "
        f"{bc.seeds} seeds), eval every {bc.eval_every} steps on {bc.eval_episodes} episodes, "
        f"{bc.workers} workers -> {out}"
    )
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    bar = tqdm(total=len(jobs) * bc.steps, unit="step", disable=not bc.progress)
    if bc.workers == 1:

        class _Bar:  # a queue that moves the bar directly
            put = bar.update

        for job in jobs:
            rows += run_job(bc, job, _Bar())
            write_csv(out / "islands.csv", rows)
    else:
        ctx = mp.get_context("spawn")  # no forked torch/OpenMP state in the workers
        with ctx.Manager() as manager, ProcessPoolExecutor(bc.workers, mp_context=ctx) as pool:
            queue = manager.Queue()
            pending = {pool.submit(_run_job_star, (bc, job, queue)) for job in jobs}
            while pending:
                done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                while not queue.empty():
                    bar.update(queue.get())
                for fut in done:
                    rows += fut.result()
                    write_csv(out / "islands.csv", rows)
            while not queue.empty():
                bar.update(queue.get())
    bar.close()
    wall = time.perf_counter() - t0
    write_csv(out / "islands.csv", rows)
    title = (
        f"{bc.env_id}: PPO, {bc.seeds} seed(s), mean and min..max, "
        f"{bc.eval_episodes} eval episodes per point"
    )
    plot(rows, out / "islands.png", title)
    table = summary_table(rows)
    (out / "summary.md").write_text(
        f"{table}\n\n{len(jobs)} runs of {bc.steps} steps, {bc.workers} workers, "
        f"{wall / 60:.1f} min wall\n"
    )
    print(table)
    print(f"{len(jobs)} runs in {wall / 60:.1f} min; wrote islands.csv, islands.png, summary.md")
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
