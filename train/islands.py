"""The islands-and-bridges benchmark (thesis Fig. curves): ``python -m train.islands``.

Trains PPO (:mod:`train.islands_ppo`: same wrapper stack, settings and seeding) for every
configuration and scores it two ways, each with a 95 % Wilson interval
(:func:`train.stats.wilson_interval`):

- **the thesis' measure**: the success rate of the *stochastic* policy with the shield in
  place, through training, from the training episodes themselves (thesis: "we used PPO to
  train a stochastic policy ... after training the shield remains in place. We show the
  success rates ... throughout the training process"), in windows of ``--window`` steps;
- **ours**: at the end of training, on held-out episodes (the run's ``test`` streams,
  :mod:`train.seeding`, which neither training nor tuning drew from), the stochastic policy
  with the shield, the deterministic policy with the shield and the deterministic policy
  without it. The three evaluations face the same start/goal pairs (paired envs). During
  training the deterministic policy with the shield can also be scored every
  ``--eval-every`` steps on ``--eval-episodes`` validation episodes (off by default).

Configurations: every shield x reward x map (``--env-ids``: the five-island map with a dead
end, ``ihm/IslandsBridges-v0``, and the four-island ring, ``ihm/IslandsBridgesRing-v0``) with
the ``--net`` networks (2x64), plus the network-size study: ``--study-nets`` (2x16 and
2x256) for ``--study-shields`` x ``--study-rewards`` x ``--study-envs``. Each configuration
runs ``--seeds`` independent run seeds (1..N; the study ``--study-seeds``, 2 by default, to
keep the whole benchmark within 45 minutes on 2 cores). Jobs run in ``--workers`` processes,
the slowest first.

Writes to ``--out``::

    islands.csv       one row per (configuration, seed, measure, step); measures:
                      train_stochastic (training episodes that ended in the window up to
                      ``steps``), train_stochastic_final (the last ``--final-window`` steps),
                      eval_deterministic (validation, during training, with --eval-every),
                      final_stochastic,
                      final_deterministic, final_deterministic_noshield (test, at the end)
    islands.png       success vs training steps, one panel per map and reward, one colour per
                      shield: solid the thesis' measure, dashed the deterministic policy
                      (mean over seeds; band: the pooled 95 % interval of the thesis' measure)
    islands_nets.png  the same for the network-size study
    summary.md        the final table (also printed): per configuration the pooled success
                      and its 95 % interval for each measure (episode noise given the trained
                      policies, see train.stats), and the per-seed values of the thesis'
                      measure and of the deterministic policy (the seed-to-seed spread)

``--quick`` is a smoke-sized run (1 seed, 5000 steps, 2x16 nets, no network study).
"""

from __future__ import annotations

import csv
import math
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
import torch
from stable_baselines3.common.callbacks import BaseCallback
from tqdm import tqdm

from stability.io import write_csv
from train.evaluation import evaluate_success
from train.islands_ppo import (
    REWARDS,
    SHIELDS,
    Config,
    TrainStats,
    build_envs,
    build_model,
    make_eval_envs,
)
from train.sb3 import build_parser, normalizer, opt, seed_everything
from train.seeding import RunSeeds
from train.stats import wilson_interval

__all__ = [
    "COLUMNS",
    "MAPS",
    "MEASURES",
    "NETS",
    "BenchConfig",
    "main",
    "plot",
    "read_csv",
    "run_job",
    "save_rows",
    "summary_table",
    "training_windows",
]

NETS = {"small": [16, 16], "medium": [64, 64], "large": [256, 256]}
"""Network sizes; policy and value nets are separate and of equal size."""

MAPS = {"ihm/IslandsBridges-v0": "dead-end", "ihm/IslandsBridgesRing-v0": "ring"}
"""Short names of the maps in tables and charts (other env ids are shown as they are)."""

MEASURES = {
    "train_stochastic": "thesis: stochastic, shield, training episodes",
    "train_stochastic_final": "thesis measure over the last --final-window steps",
    "eval_deterministic": "deterministic, shield, validation episodes during training",
    "final_stochastic": "stochastic, shield, held-out",
    "final_deterministic": "deterministic, shield, held-out",
    "final_deterministic_noshield": "deterministic, no shield, held-out",
}
"""What each ``measure`` of the CSV is."""

COLUMNS = [
    "env_id",
    "map",
    "shield",
    "reward",
    "net",
    "seed",
    "measure",
    "steps",
    "episodes",
    "successes",
    "failures",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_length",
    "intervention_rate",
    "wall_s",
]


@dataclass
class BenchConfig:
    """Options of the benchmark (``--quick`` changes those left at their defaults)."""

    env_ids: list[str] = opt(list(MAPS), "maps (Gymnasium ids), one chart row each")
    shields: list[str] = opt(list(SHIELDS), "shields to compare", choices=SHIELDS)
    rewards: list[str] = opt(list(REWARDS), "reward modes (one chart column each)", choices=REWARDS)
    net: str = opt("medium", "networks of the main grid (small: 2x16, medium: 2x64, large: 2x256)")
    study_nets: list[str] = opt(
        ["small", "large"], "network-size study: the other sizes (none: --study-nets with no value)"
    )
    study_shields: list[str] = opt(["smart"], "shields of the network-size study")
    study_rewards: list[str] = opt(["sparse"], "rewards of the network-size study")
    study_envs: list[str] = opt(["ihm/IslandsBridgesRing-v0"], "maps of the network-size study")
    seeds: int = opt(3, "independent run seeds per configuration (1..N)")
    study_seeds: int = opt(
        2, "run seeds of the network-study configurations (1..N; fewer repeats keep 45 min)"
    )
    steps: int = opt(200_000, "training steps per run")
    window: int = opt(10_000, "steps per point of the thesis' (training-episode) curve")
    final_window: int = opt(20_000, "last steps whose training episodes give its final value")
    eval_every: int = opt(
        0, "also score the deterministic policy every this many steps (0: only at the end)"
    )
    eval_episodes: int = opt(100, "validation episodes per evaluation during training")
    final_episodes: int = opt(500, "held-out episodes of each final evaluation, per seed")
    eval_envs: int = opt(8, "envs per evaluation (episodes run in parallel)")
    workers: int = opt(2, "parallel worker processes (1: run in this process)")
    # PPO settings default to train.ppo's, so the benchmark follows its tuning
    n_envs: int = opt(Config.n_envs, "training envs per run")
    n_steps: int = opt(Config.n_steps, "PPO rollout length per env")
    batch_size: int = opt(Config.batch_size, "PPO minibatch size")
    learning_rate: float = opt(Config.learning_rate, "Adam learning rate")
    out: str = opt("bench_out/islands", "output directory (islands.csv, *.png, summary.md)")
    quick: bool = opt(False, "smoke-sized run: 1 seed, 5000 steps, 2x16 nets, no network study")
    progress: bool = opt(True, "show a tqdm progress bar over all training steps")


QUICK = {
    "seeds": 1,
    "study_seeds": 1,
    "steps": 5000,
    "window": 2500,
    "final_window": 2500,
    "eval_every": 2500,
    "eval_episodes": 20,
    "final_episodes": 20,
    "net": "small",
    "study_nets": [],
}


def parse_config(argv: Sequence[str] | None = None) -> BenchConfig:
    """Parse the command line (argparse exits with 2 and a message on bad options)."""
    parser = build_parser(BenchConfig, "python -m train.islands", (__doc__ or "").split("\n")[0])
    for action in parser._actions:  # the study lists may be given empty
        if action.dest in ("study_nets", "study_shields", "study_rewards", "study_envs"):
            action.nargs = "*"
    args = vars(parser.parse_args(argv))
    if args["quick"]:
        for name, value in QUICK.items():
            if args[name] == parser.get_default(name):
                args[name] = value
    bc = BenchConfig(**args)
    problems = [
        f"--{flag}: unknown net {n!r} (choose from {list(NETS)})"
        for flag, names in (("net", [bc.net]), ("study-nets", bc.study_nets))
        for n in names
        if n not in NETS
    ]
    problems += [
        f"--study-shields: unknown shield {s!r}" for s in bc.study_shields if s not in SHIELDS
    ]
    problems += [
        f"--study-rewards: unknown reward {r!r}" for r in bc.study_rewards if r not in REWARDS
    ]
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids)

    problems += [
        f"unknown env id {e!r} (registered: {[k for k in gym.registry if k.startswith('ihm/')]})"
        for e in dict.fromkeys([*bc.env_ids, *bc.study_envs])
        if e not in gym.registry
    ]
    positive = ("seeds", "study_seeds", "steps", "window", "final_window", "eval_episodes")
    positive = (*positive, "final_episodes")
    for name in (*positive, "eval_envs", "workers", "n_envs", "n_steps", "batch_size"):
        if getattr(bc, name) < 1:
            problems.append(f"--{name.replace('_', '-')} must be >= 1")
    if bc.eval_every < 0:
        problems.append("--eval-every must be >= 0")
    if bc.n_envs >= 1 and bc.steps % bc.n_envs:
        problems.append(f"--steps must be a multiple of --n-envs ({bc.n_envs}): a vector step "
                        "advances every env")  # fmt: skip
    if problems:
        parser.error("; ".join(problems))
    return bc


def _jobs(bc: BenchConfig) -> list[dict[str, Any]]:
    """The main grid and the network study, slowest first (large nets, then medium, small)."""
    jobs = [
        {"env_id": e, "shield": s, "reward": r, "net": bc.net, "seed": seed}
        for e in bc.env_ids
        for s in bc.shields
        for r in bc.rewards
        for seed in range(1, bc.seeds + 1)
    ]
    jobs += [
        {"env_id": e, "shield": s, "reward": r, "net": n, "seed": seed}
        for n in bc.study_nets
        if n != bc.net
        for e in bc.study_envs
        for s in bc.study_shields
        for r in bc.study_rewards
        for seed in range(1, bc.study_seeds + 1)
    ]
    cost = {"large": 0, "medium": 1, "small": 2}
    return sorted(jobs, key=lambda j: cost.get(j["net"], 1))  # stable: grid order within


def training_windows(
    episodes: Sequence[tuple[int, bool, bool, int]], total: int, window: int
) -> list[tuple[int, int, int, int]]:
    """Training episodes binned by the step they ended at: ``(end, episodes, successes,
    failures)`` per window ``(end - window, end]``, ``end = window, 2 window, ..., total``
    (the last window ends at ``total``). ``episodes`` holds :class:`train.islands_ppo.TrainStats`
    entries ``(step, success, failure, length)``."""
    ends = list(range(window, total, window)) + [total]
    out = []
    lo = 0
    for end in ends:
        sel = [e for e in episodes if lo < e[0] <= end]
        out.append((end, len(sel), sum(e[1] for e in sel), sum(e[2] for e in sel)))
        lo = end
    return out


def _row(job: dict[str, Any], measure: str, steps: int, res: dict[str, Any], wall: float):
    n, k = int(res["episodes"]), int(res["successes"])
    lo, hi = wilson_interval(k, n)
    return {
        **job,
        "map": MAPS.get(job["env_id"], job["env_id"]),
        "measure": measure,
        "steps": steps,
        "episodes": n,
        "successes": k,
        "failures": int(res["failures"]),
        "success_rate": k / n if n else float("nan"),
        "ci_low": lo,
        "ci_high": hi,
        "mean_length": res.get("mean_length", float("nan")),
        "intervention_rate": res.get("intervention_rate", float("nan")),
        "wall_s": round(wall, 2),
    }


def run_job(bc: BenchConfig, job: dict[str, Any], queue: Any = None) -> list[dict[str, Any]]:
    """Train one configuration and score it; returns its CSV rows.

    ``queue`` (optional) receives the number of training steps done since the last report,
    for the progress bar of the parent process.
    """
    torch.set_num_threads(1)
    cfg = Config(  # every PPO setting not named here is train.islands_ppo's default
        env_id=job["env_id"],
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
        progress=False,
    )
    # ---- seeds, all in one place (as in train.ppo) ----
    seeds = RunSeeds(cfg.seed)
    seed_everything(seeds.global_seed)
    train_env = build_envs(cfg, seeds)
    model = build_model(cfg, train_env)
    val_envs = make_eval_envs(cfg, seeds, "validation", bc.eval_envs)
    # ---------------------------------------------------
    norm = normalizer(train_env)
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    stats = TrainStats()
    reported = 0

    def report(steps: int) -> None:
        nonlocal reported
        if queue is not None and steps > reported:
            queue.put(steps - reported)
        reported = max(reported, steps)

    class Schedule(BaseCallback):
        """Deterministic evaluations every ``eval_every`` steps; stop at the step budget."""

        next_eval = bc.eval_every

        def _on_step(self) -> bool:
            if self.num_timesteps >= bc.steps:
                return False  # stop at the budget, not at the end of the rollout
            if bc.eval_every and self.num_timesteps >= self.next_eval:
                res = evaluate_success(model, val_envs, bc.eval_episodes, normalize=norm)
                wall = time.perf_counter() - t0
                rows.append(_row(job, "eval_deterministic", self.num_timesteps, res, wall))
                while self.next_eval <= self.num_timesteps:
                    self.next_eval += bc.eval_every
            return True

        def _on_rollout_end(self) -> None:
            report(min(self.num_timesteps, bc.steps))

    model.learn(bc.steps, callback=[stats, Schedule()])
    steps = min(int(model.num_timesteps), bc.steps)
    wall = time.perf_counter() - t0
    for end, n, k, f in training_windows(stats.episodes, steps, bc.window):
        res = {"episodes": n, "successes": k, "failures": f}
        rows.append(_row(job, "train_stochastic", end, res, wall))
    last = [e for e in stats.episodes if e[0] > steps - bc.final_window]
    res = {
        "episodes": len(last),
        "successes": sum(e[1] for e in last),
        "failures": sum(e[2] for e in last),
        "mean_length": float(np.mean([e[3] for e in last])) if last else float("nan"),
    }
    rows.append(_row(job, "train_stochastic_final", steps, res, wall))

    # held-out: the "test" streams; the three evaluations face the same episodes
    finals = [("final_stochastic", False, None), ("final_deterministic", True, None)]
    if cfg.shield != "none":
        finals.append(("final_deterministic_noshield", True, "none"))
    for measure, deterministic, shield in finals:
        test_envs = make_eval_envs(cfg, seeds, "test", bc.eval_envs, shield=shield)
        torch.manual_seed(seeds.policy_seed("test"))  # action sampling of the stochastic policy
        res = evaluate_success(
            model, test_envs, bc.final_episodes, deterministic=deterministic, normalize=norm
        )
        rows.append(_row(job, measure, steps, res, time.perf_counter() - t0))
        for env in test_envs:
            env.close()
    if cfg.shield == "none":  # without a shield the two deterministic scores are one
        rows.append({**rows[-1], "measure": "final_deterministic_noshield"})
    report(bc.steps)
    train_env.close()
    for env in val_envs:
        env.close()
    return rows


def _run_job_star(args: tuple) -> list[dict[str, Any]]:
    return run_job(*args)


def _key(r: dict[str, Any]) -> tuple:
    order = {m: i for i, m in enumerate(MEASURES)}
    return (
        r["env_id"],
        r["net"],
        SHIELDS.index(r["shield"]) if r["shield"] in SHIELDS else 9,
        r["reward"],
        int(r["seed"]),
        order.get(r["measure"], 9),
        int(r["steps"]),
    )


def save_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """``islands.csv``: the :data:`COLUMNS` of the rows sorted by configuration, seed,
    measure and steps."""
    write_csv(path, sorted(rows, key=_key), COLUMNS)


def read_csv(path: Path) -> list[dict[str, Any]]:
    """Rows of a written ``islands.csv`` with numbers parsed (to re-plot or re-summarise)."""
    ints = ("seed", "steps", "episodes", "successes", "failures")
    floats = ("success_rate", "ci_low", "ci_high", "mean_length", "intervention_rate", "wall_s")
    with path.open() as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ints:
            r[k] = int(r[k])
        for k in floats:
            r[k] = float(r[k])
    return rows


Config3 = tuple[str, str, str, str]  # env_id, shield, reward, net


def _pooled(rows: list[dict[str, Any]], measure: str) -> dict[Config3, dict[int, list]]:
    """(config) -> steps -> list of (seed, episodes, successes) over seeds."""
    by: dict[Config3, dict[int, list]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["measure"] == measure:
            key = (r["env_id"], r["shield"], r["reward"], r["net"])
            by[key][int(r["steps"])].append((int(r["seed"]), int(r["episodes"]), r["successes"]))
    return by


def _curve(points: dict[int, list]) -> np.ndarray:
    """steps, pooled success rate (all seeds' episodes), pooled Wilson low and high.

    Pooled, like the summary table: a seed that finishes more episodes in a window weighs
    more, which is what "the success rate of the training episodes" means; per-seed values
    are in the CSV and the summary table."""
    return np.array([[s, *_pool(v)] for s, v in sorted(points.items())], dtype=float)


def _pool(points: list) -> tuple[float, float, float]:
    """Pooled success rate of ``(seed, episodes, successes)`` entries and its 95 % Wilson
    interval (nan without episodes)."""
    n, k = sum(x[1] for x in points), sum(x[2] for x in points)
    lo, hi = wilson_interval(int(k), int(n))
    return (k / n if n else math.nan), lo, hi


def _main_net(keys: set[Config3] | dict[Config3, Any]) -> str:
    """The net of most configurations (the main grid's; the others are the network study)."""
    counts: dict[str, int] = defaultdict(int)
    for key in keys:
        counts[key[3]] += 1
    return max(counts, key=counts.get) if counts else ""


COLOURS = {"none": "tab:red", "simple": "tab:blue", "smart": "tab:green"}
NET_COLOURS = {"small": "tab:orange", "medium": "tab:green", "large": "tab:purple"}


def plot(rows: list[dict[str, Any]], path: Path, nets: bool = False, title: str = "") -> bool:
    """Success vs training steps (thesis Fig. curves), one panel per (map, reward).

    ``nets=False``: the main grid (the most common net), one colour per shield. ``nets=True``:
    the network-size study, one colour per net, for the configurations run with several nets.
    Solid: the thesis' measure, pooled over seeds, with its 95 % band; dashed with markers: the
    deterministic policy with the shield (validation during training if run, held-out at the
    end), pooled.
    Returns False (and writes nothing) when there is nothing to draw.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    train = _pooled(rows, "train_stochastic")
    det = _pooled(rows, "eval_deterministic")
    for key, pts in _pooled(rows, "final_deterministic").items():
        det[key].update(pts)
    main_net = _main_net(train)
    if nets:
        groups = defaultdict(set)
        for e, s, r, n in train:
            groups[(e, s, r)].add(n)
        keys = [k for k in train if len(groups[k[:3]]) > 1]
    else:
        keys = [k for k in train if k[3] == main_net]
    if not keys:
        return False
    panels = sorted({(k[0], k[2]) for k in keys}, key=lambda p: (list(MAPS).index(p[0])
                    if p[0] in MAPS else 9, REWARDS.index(p[1])))  # fmt: skip
    maps = list(dict.fromkeys(p[0] for p in panels))
    rewards = [r for r in REWARDS if any(p[1] == r for p in panels)]
    fig, axes = plt.subplots(
        len(maps), len(rewards), figsize=(6 * len(rewards), 4.0 * len(maps)), squeeze=False
    )
    for ax_row, env_id in zip(axes, maps, strict=True):
        for ax, reward in zip(ax_row, rewards, strict=True):
            for key in sorted(keys, key=lambda k: (SHIELDS.index(k[1]), list(NETS).index(k[3]))):
                e, shield, rew, net = key
                if (e, rew) != (env_id, reward):
                    continue
                colour = NET_COLOURS.get(net, "k") if nets else COLOURS.get(shield, "k")
                size = "x".join(map(str, NETS.get(net, [])))
                label = f"{shield}, {size}" if nets else shield
                c = _curve(train[key])
                ax.plot(c[:, 0], c[:, 1], "-", color=colour, label=f"{label}: stochastic (thesis)")
                ax.fill_between(c[:, 0], c[:, 2], c[:, 3], color=colour, alpha=0.15, lw=0)
                if key in det:
                    d = _curve(det[key])
                    ax.plot(d[:, 0], d[:, 1], "--o", color=colour, ms=3, lw=1,
                            label=f"{label}: deterministic")  # fmt: skip
            ax.set_title(f"{MAPS.get(env_id, env_id)} map ({env_id}), {reward} reward", fontsize=9)
            ax.set_xlabel("training steps")
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
            ax.legend(loc="best", fontsize=7)
        ax_row[0].set_ylabel("success rate (shield in place)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _cell(points: list) -> str:
    rate, lo, hi = _pool(points)
    return "–" if math.isnan(rate) else f"{rate:.3f} [{lo:.3f}, {hi:.3f}]"


def _per_seed(points: list) -> str:
    return " / ".join(f"{k / n:.3f}" for _, n, k in sorted(points) if n) or "–"


def summary_table(rows: list[dict[str, Any]]) -> str:
    """Markdown table: per configuration, each final measure pooled over seeds with its 95 %
    Wilson interval, and the per-seed values of the thesis' measure and of the deterministic
    policy with the shield (seed 1 / 2 / 3)."""
    measures = [
        ("train_stochastic_final", "thesis: stochastic, shield, last training episodes"),
        ("final_stochastic", "stochastic, shield, held-out"),
        ("final_deterministic", "deterministic, shield, held-out"),
        ("final_deterministic_noshield", "deterministic, no shield, held-out"),
    ]
    pooled = {m: _pooled(rows, m) for m, _ in measures}
    head = "| map | shield | reward | net | " + " | ".join(t for _, t in measures)
    head += " | thesis measure, per seed | deterministic, shield, per seed |"
    lines = [head, "|" + "---|" * (6 + len(measures))]
    keys = {k for p in pooled.values() for k in p}
    main_net = _main_net(keys)
    keys = sorted(  # per map: the main grid, then the network study
        keys,
        key=lambda k: (
            list(MAPS).index(k[0]) if k[0] in MAPS else 9,
            k[3] != main_net,
            list(NETS).index(k[3]) if k[3] in NETS else 9,
            SHIELDS.index(k[1]) if k[1] in SHIELDS else 9,
            k[2],
        ),
    )
    for key in keys:
        env_id, shield, reward, net = key
        pts = {m: [x for v in pooled[m].get(key, {}).values() for x in v] for m, _ in measures}
        cells = [_cell(pts[m]) for m, _ in measures]
        cells += [_per_seed(pts["train_stochastic_final"]), _per_seed(pts["final_deterministic"])]
        size = "x".join(map(str, NETS.get(net, [])))
        lines.append(
            f"| {MAPS.get(env_id, env_id)} | {shield} | {reward} | {size} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Run the benchmark, write CSV, PNGs and summary; returns the rows."""
    bc = parse_config(argv)
    out = Path(bc.out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = _jobs(bc)
    print(
        f"{len(jobs)} runs x {bc.steps} steps: {bc.shields} x {bc.rewards} x {bc.env_ids} with "
        f"{bc.net} nets, network study {bc.study_nets} on {bc.study_shields} x "
        f"{bc.study_rewards} x {bc.study_envs}; {bc.seeds} seeds; final scores on "
        f"{bc.final_episodes} held-out episodes per seed; {bc.workers} workers -> {out}"
    )
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    # smoothing 0: rate and time left over the whole elapsed time (updates, evaluations)
    bar = tqdm(total=len(jobs) * bc.steps, unit="step", disable=not bc.progress, smoothing=0)
    if bc.workers == 1:

        class _Bar:  # a queue that moves the bar directly
            put = bar.update

        for job in jobs:
            rows += run_job(bc, job, _Bar())
            save_rows(out / "islands.csv", rows)
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
                    save_rows(out / "islands.csv", rows)
            while not queue.empty():
                bar.update(queue.get())
    bar.close()
    wall = time.perf_counter() - t0
    save_rows(out / "islands.csv", rows)
    finish(rows, out, f"{len(jobs)} runs of {bc.steps} steps, {bc.workers} workers, "
           f"{wall / 60:.1f} min wall")  # fmt: skip
    return rows


def finish(rows: list[dict[str, Any]], out: Path, note: str) -> str:
    """Charts and summary from the rows (also used to redraw from a CSV)."""
    seeds = len({r["seed"] for r in rows})
    plot(
        rows, out / "islands.png", title=f"PPO, {seeds} seed(s), pooled; band: 95% Wilson interval"
    )
    plot(rows, out / "islands_nets.png", nets=True, title="network size (separate pi/vf nets)")
    table = summary_table(rows)
    (out / "summary.md").write_text(f"{table}\n\n{note}\n")
    print(table)
    print(f"{note}; wrote islands.csv, islands.png, islands_nets.png, summary.md to {out}")
    return table


if __name__ == "__main__":
    main(sys.argv[1:])
