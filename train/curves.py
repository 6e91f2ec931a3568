"""Learning curves of a rotation run: the training returns in its monitor files and the
evaluations in its ``eval.csv``, drawn to ``curve.png``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

__all__ = ["monitor_episodes", "monitor_returns", "plot_curve", "return_label", "steps_label"]


def monitor_episodes(run_dir: Path) -> list[dict[str, str]]:
    """Every episode row of the run's monitor files (SB3 ``Monitor``: ``r``, ``l``, ``t`` and
    the ``info_keywords`` columns, as text), in wall-time order (``t``; each env's monitor
    counts from nearly the same start)."""
    rows = []
    for p in sorted((run_dir / "monitor").glob("*.monitor.csv")):
        with p.open() as f:
            lines = [ln for ln in f if not ln.startswith("#")]
        rows += list(csv.DictReader(lines))
    return sorted(rows, key=lambda r: float(r["t"]))


def monitor_returns(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """(cumulative env steps at each episode end, episode return) over all monitor files, in
    wall-time order."""
    rows = monitor_episodes(run_dir)
    if not rows:
        return np.zeros(0), np.zeros(0)
    length = np.array([int(r["l"]) for r in rows])
    return np.cumsum(length), np.array([float(r["r"]) for r in rows])


def steps_label(x: float) -> str:
    """A step count for an axis: ``0``, ``500``, ``100k``, ``1.6M``."""
    if abs(x) >= 1e6:
        return f"{x / 1e6:g}M"
    if abs(x) >= 1e3:
        return f"{x / 1e3:g}k"
    return f"{x:g}"


def return_label(run_dir: Path) -> str:
    """The return axis' label: the run's training episode length (``config.json``'s
    ``episode_steps``; 64, the main job's, when the run has none)."""
    cfg = run_dir / "config.json"
    steps = json.loads(cfg.read_text()).get("episode_steps", 64) if cfg.is_file() else 64
    return f"training episode return [rad/s summed over {steps} steps]"


def plot_curve(run_dir: Path, target_speed: float, out: Path | None = None) -> Path:
    """curve.png: training episode return (the run's episodes, smoothed) and the evaluated
    rotation speed [rad/s, left axis] and drop rate [%, right axis] over env steps; the
    dotted line is the speed target ``target_speed`` [rad/s] (``train.rotation.TARGET_SPEED``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    steps, ret = monitor_returns(run_dir)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    if len(ret):
        w = max(1, min(200, len(ret) // 20))
        smooth = np.convolve(ret, np.ones(w) / w, mode="valid")
        ax[0].plot(steps, ret, ".", ms=1, alpha=0.15, color="C0")
        ax[0].plot(steps[w - 1 :], smooth, color="C0", label=f"mean of {w} episodes")
        ax[0].legend(loc="lower right")
    ax[0].set_xlabel("env steps")
    ax[0].set_ylabel(return_label(run_dir))
    ax[0].set_title("training return")
    ev = run_dir / "eval.csv"
    if ev.is_file():
        with ev.open() as f:
            rows = list(csv.DictReader(f))
        if rows:
            x = [int(r["steps"]) for r in rows]
            ax[1].plot(x, [float(r["speed_rad_s"]) for r in rows], "o-", label="speed")
            label = f"target speed (>= {target_speed:g} rad/s)"
            ax[1].axhline(target_speed, color="gray", lw=0.8, ls=":", label=label)
            drops = ax[1].twinx()  # a fraction has its own axis: not read against rad/s
            drops.plot(x, [100.0 * float(r["drop_rate"]) for r in rows], "s--", color="C3",
                       label="drop rate")  # fmt: skip
            drops.set_ylim(0.0, 100.0)
            drops.set_ylabel("drop rate [% of episodes]", color="C3")
            lines = ax[1].get_legend_handles_labels()
            more = drops.get_legend_handles_labels()
            ax[1].legend(lines[0] + more[0], lines[1] + more[1], loc="upper left")
    ax[1].set_xlabel("env steps")
    ax[1].set_ylabel("rotation speed [rad/s]")
    ax[1].set_title("validation: deterministic policy, training start grasps")
    for a in ax:
        a.grid(alpha=0.3)
        a.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
        a.xaxis.set_major_formatter(FuncFormatter(lambda x, _: steps_label(x)))
    fig.tight_layout()
    out = out or run_dir / "curve.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
