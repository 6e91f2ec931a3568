"""Compare rotation training runs: ``python -m train.compare RUN_DIR ... --out PATH``.

Groups run directories of :mod:`train.rotation` (``python -m train.ppo``) by a field of
their ``config.json`` (``--group-by``, default ``shield``: ``none`` or ``qp``; e.g.
``init_from`` to set runs started from another policy beside runs from scratch, or
``episode_steps``; a run without the field is in group ``none``) and charts, over env steps,
the training episode return (64-step episodes, each run's moving mean over ``--window``
episodes, binned to a common step grid) and the periodic evaluations (deterministic policy,
20 s episodes: rotation speed [rad/s] and drop rate), one thin line per run and the group
mean thick. Writes ``<out>.png`` and ``<out>.csv`` (one row per run: final evaluation, mean
return over the last 10 % of its training episodes) and prints the table.

    python -m train.compare runs/shield_effect/* --out docs/bench/shield_training
"""

from __future__ import annotations

import csv
import json
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from stability.cli import ArgumentParser
from stability.io import write_csv
from train.options import saved_value
from train.rotation import monitor_returns

__all__ = ["load_run", "main", "summarise"]


def load_run(run_dir: Path, group_by: str = "shield") -> dict:
    """One run: its group (``group_by`` in its config.json, a top-level key or a field of a
    group of settings: :func:`train.options.saved_value`), seed, training returns (steps,
    return) and evaluation rows."""
    cfg_file = run_dir / "config.json"
    if not cfg_file.is_file():
        raise SystemExit(f"{run_dir}: not a training run directory (no config.json)")
    cfg = json.loads(cfg_file.read_text())
    steps, ret = monitor_returns(run_dir)
    evals: list[dict[str, float]] = []
    ev = run_dir / "eval.csv"
    if ev.is_file():
        with ev.open() as f:
            evals = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    return {
        "dir": run_dir,
        "group": str(group if (group := saved_value(cfg, group_by)) is not None else "none"),
        "seed": int(cfg.get("seed", -1)),
        "steps": steps,
        "ret": ret,
        "evals": evals,
    }


def summarise(run: dict, group_by: str = "shield") -> dict[str, float | str | int]:
    """Final evaluation and the mean training return over the last 10 % of episodes; the
    run's group in the column ``group_by``."""
    ret = run["ret"]
    tail = ret[-max(1, len(ret) // 10) :] if len(ret) else np.zeros(0)
    last = run["evals"][-1] if run["evals"] else {}
    return {
        "run": run["dir"].name,
        group_by: run["group"],
        "seed": run["seed"],
        "env_steps": int(run["steps"][-1]) if len(run["steps"]) else 0,
        "final_return": round(float(tail.mean()), 4) if len(tail) else float("nan"),
        "eval_steps": int(last.get("steps", 0)),
        "eval_speed_rad_s": last.get("speed_rad_s", float("nan")),
        "eval_drop_rate": last.get("drop_rate", float("nan")),
    }


def _plot(runs: list[dict], out: Path, window: int, field: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = sorted({r["group"] for r in runs})
    colors = {g: f"C{i}" for i, g in enumerate(groups)}
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    top = max((r["steps"][-1] for r in runs if len(r["steps"])), default=1)
    grid = np.linspace(0, top, 60)
    for g in groups:
        curves = []
        for r in (r for r in runs if r["group"] == g):
            if len(r["ret"]) < window:
                continue
            sm = np.convolve(r["ret"], np.ones(window) / window, mode="valid")
            x = r["steps"][window - 1 :]
            ax[0].plot(x, sm, color=colors[g], lw=0.6, alpha=0.5)
            curves.append(np.interp(grid, x, sm, left=np.nan, right=np.nan))
        if curves:
            with warnings.catch_warnings():  # grid points past a shorter run: all NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(curves, axis=0)
            ax[0].plot(grid, mean, color=colors[g], lw=2.2,
                       label=f"{field} {g} ({len(curves)} runs)")  # fmt: skip
        for key, a in (("speed_rad_s", ax[1]), ("drop_rate", ax[2])):
            rows = [r["evals"] for r in runs if r["group"] == g and r["evals"]]
            for ev in rows:
                a.plot([e["steps"] for e in ev], [e[key] for e in ev], "o-", ms=3,
                       color=colors[g], lw=0.6, alpha=0.5)  # fmt: skip
            n = min((len(ev) for ev in rows), default=0)
            if n:
                xs = np.mean([[e["steps"] for e in ev[:n]] for ev in rows], axis=0)
                ys = np.mean([[e[key] for e in ev[:n]] for ev in rows], axis=0)
                a.plot(xs, ys, "o-", color=colors[g], lw=2.2, label=f"{field} {g}, mean")
    ax[0].set_title(f"training episode return (moving mean of {window})")
    ax[0].set_ylabel("return [rad/s summed over 64 steps]")
    ax[1].set_title("evaluation: rotation speed [rad/s]")
    ax[2].set_title("evaluation: drop rate")
    for a in ax:
        a.set_xlabel("env steps")
        a.grid(alpha=0.3)
        a.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> list[dict]:
    """Parse, load, chart, write the CSV; returns the summary rows."""
    p = ArgumentParser(prog="python -m train.compare", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("runs", nargs="+", type=Path, help="run directories")
    p.add_argument("--out", type=Path, required=True, help="output path without suffix")
    p.add_argument("--window", type=int, default=100, help="episodes in the moving mean")
    p.add_argument("--group-by", default="shield", help="config.json field that groups runs")
    args = p.parse_args(argv)
    if args.window < 1:
        p.error("--window must be >= 1")
    runs = [load_run(d, args.group_by) for d in args.runs if d.is_dir()]
    if not runs:
        p.error("no run directories given")
    rows = [summarise(r, args.group_by) for r in runs]
    rows.sort(key=lambda r: (str(r[args.group_by]), r["seed"]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out.with_suffix(".csv"), rows, columns=list(rows[0]))
    _plot(runs, args.out.with_suffix(".png"), args.window, args.group_by)
    cols = list(rows[0])
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(str(r[c]) for c in cols))
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
