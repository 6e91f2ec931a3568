"""Does a shield help the hand learn? ``python -m train.shield_study`` (thesis ch. 7).

One protocol for every shield of ``--shields`` (default: none, the thesis' QP shield, the
QP shield on the drop criteria with the object's drift, and the lookahead yardstick:
:data:`shields.SHIELDS`): for each of ``--seeds`` seeds, the main job's configuration
(``python -m train.ppo`` with its defaults, plus ``--shield``; every option after the
study's own goes to the trainer) trains for ``--total-steps`` env steps inside the shield,
which stays on for the validations and the final evaluation. Then, per run:

- **safety while learning**: drops per 1,000 training env steps (the monitor files: the
  episodes that ended by a drop over the steps of the completed episodes), and the
  cumulative drops over env steps (the 16 envs' episodes merged by their end times, which
  the monitors count from nearly the same start);
- **learning speed**: the env steps at which a validation (every 100k steps, 20 x 20 s)
  first reached ``TARGET_SPEED`` (0.5 rad/s net turn), empty when none did (the summary
  then counts the run's budget);
- **result**: the kept policy (``best/``) on ``--episodes`` fresh held-out episodes of 20 s
  (test grasps no training run uses, :func:`train.heldout.evaluate_heldout`), shield on:
  net turn [rad/s] with its 95 % interval, drops with their Wilson interval;
- **cost**: shield interventions per step (training and evaluation), the shield's wall time
  per policy step (mean over training, ``train_shield_ms``; median and 95th percentile over
  the evaluation's steps [ms]), the training wall time and env steps per second.

A run directory under ``--runs/<shield>/`` that already holds a finished run of that seed
and budget is measured, not trained again; a run's measures are kept in
``--out/runs/<shield>__<seed>.json``, so a study can be run a few runs at a time, on
several machines, and the report rebuilt from the files (``--report``). Writes to
``--out`` (default ``docs/bench/shield_study``):

    shield_study.csv          one row per run (the measures above)
    shield_study_summary.csv  per shield: mean, min and max over its seeds
    shield_study.png          learning curves (validation net turn, mean and seed band),
                              cumulative training drops, final speed and drops per run
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from shields import SHIELDS
from stability.cli import ArgumentParser
from stability.io import write_csv
from train import rotation
from train.curves import monitor_episodes, steps_label
from train.heldout import TEST_GRASPS, evaluate_heldout
from train.policy import load_policy

__all__ = ["COLUMNS", "DEFAULT_SHIELDS", "find_run", "main", "measure_run", "plot", "summarize"]

DEFAULT_SHIELDS = ("none", "qp", "qp-drift", "lookahead")
COLUMNS = [
    "shield", "seed", "run", "steps", "train_minutes", "steps_per_s", "train_episodes",
    "train_drops", "drops_per_1000", "train_interventions_per_step", "train_shield_ms",
    "first_target_steps",
    "episodes", "speed_rad_s", "speed_lo", "speed_hi", "drops", "drop_rate", "drop_lo",
    "drop_hi", "interventions_per_step", "shield_ms_median", "shield_ms_p95",
]  # fmt: skip
SUMMED = ["drops_per_1000", "first_target_steps", "speed_rad_s", "drop_rate",
          "train_interventions_per_step", "interventions_per_step", "shield_ms_median",
          "train_minutes"]  # fmt: skip
CURVE_BINS = 24  # points of the cumulative training-drop curve


def find_run(runs: Path, shield: str, seed: int, steps: int) -> Path | None:
    """The newest finished run of ``shield`` and ``seed`` under ``runs/<shield>`` with at
    least ``steps`` env steps (its ``eval.json`` written; the trainer rounds the budget up to
    whole rollouts), or None."""
    found = []
    for d in sorted((runs / shield).glob("FourFingerRotate-*")):
        try:
            cfg = json.loads((d / "config.json").read_text())
            ev = json.loads((d / "eval.json").read_text())
        except (OSError, ValueError):
            continue
        if cfg.get("seed") == seed and cfg.get("shield", "none") == shield:
            if ev.get("num_timesteps", 0) >= steps:
                found.append(d)
    return found[-1] if found else None


def training_log(run_dir: Path) -> dict[str, np.ndarray]:
    """Every training episode of the monitor files in wall-time order: ``steps`` (cumulative
    env steps at its end), ``dropped``, ``interventions`` and ``shield_s`` (0 without a
    shield)."""
    rows = monitor_episodes(run_dir)
    length = np.array([int(r["l"]) for r in rows], dtype=np.int64)
    return {
        "length": length,
        "steps": np.cumsum(length),
        "dropped": np.array([r.get("dropped") == "True" for r in rows], dtype=bool),
        "interventions": np.array(
            [int(r.get("shield_episode_interventions") or 0) for r in rows], dtype=np.int64
        ),
        "shield_s": np.array(
            [float(r.get("shield_episode_seconds") or 0.0) for r in rows], dtype=np.float64
        ),
    }


def validation_curve(run_dir: Path) -> list[dict[str, float]]:
    """The run's validations (``eval.csv``): steps, net turn [rad/s], drop rate."""
    path = run_dir / "eval.csv"
    if not path.is_file():
        return []
    with path.open() as f:
        return [
            {
                "steps": int(r["steps"]),
                "speed": float(r["speed_rad_s"]),
                "drops": float(r["drop_rate"]),
            }
            for r in csv.DictReader(f)
        ]


def measure_run(run_dir: Path, shield: str, episodes: int = TEST_GRASPS) -> dict[str, Any]:
    """The module docstring's measures of one run: ``{"row": ..., "validation": [...],
    "drop_curve": [[steps, cumulative drops], ...]}``."""
    cfg = json.loads((run_dir / "config.json").read_text())
    ev = json.loads((run_dir / "eval.json").read_text())
    log = training_log(run_dir)
    steps = int(log["steps"][-1]) if len(log["steps"]) else 0
    drops = int(log["dropped"].sum())
    val = validation_curve(run_dir)
    first = next((v["steps"] for v in val if v["speed"] >= rotation.TARGET_SPEED), "")
    act, kw = load_policy(run_dir)
    r = evaluate_heldout(act, kw, episodes, shield=shield)
    edges = np.linspace(0, steps, CURVE_BINS + 1)[1:] if steps else np.zeros(0)
    cum = np.cumsum(log["dropped"])
    idx = np.searchsorted(log["steps"], edges, side="right") - 1
    curve = [[int(e), int(cum[i]) if i >= 0 else 0] for e, i in zip(edges, idx, strict=True)]
    row = {
        "shield": shield,
        "seed": cfg["seed"],
        "run": run_dir.name,
        "steps": ev.get("num_timesteps", steps),
        "train_minutes": round(ev["train_seconds"] / 60, 1),
        "steps_per_s": ev.get("steps_per_second", ""),
        "train_episodes": len(log["length"]),
        "train_drops": drops,
        "drops_per_1000": round(1000 * drops / steps, 3) if steps else "",
        "train_interventions_per_step": round(log["interventions"].sum() / steps, 4)
        if steps
        else "",
        "train_shield_ms": round(1e3 * log["shield_s"].sum() / steps, 3) if steps else "",
        "first_target_steps": first,
        "episodes": r["episodes"],
        "speed_rad_s": round(r["speed_rad_s"], 3),
        "speed_lo": round(r["speed_ci95"][0], 3),
        "speed_hi": round(r["speed_ci95"][1], 3),
        "drops": r["drops"],
        "drop_rate": round(r["drop_rate"], 3),
        "drop_lo": round(r["drop_ci95"][0], 3),
        "drop_hi": round(r["drop_ci95"][1], 3),
        "interventions_per_step": round(r.get("interventions_per_step", 0.0), 4),
        "shield_ms_median": round(r["shield_ms_median"], 3) if "shield_ms_median" in r else "",
        "shield_ms_p95": round(r["shield_ms_p95"], 3) if "shield_ms_p95" in r else "",
    }
    return {"row": row, "validation": val, "drop_curve": curve}


def summarize(rows: Sequence[dict[str, Any]], order: Sequence[str]) -> list[dict[str, Any]]:
    """Per shield (in ``order``): runs, and the mean, min and max of :data:`SUMMED` over its
    seeds (a run that never reached the target counts as the budget in
    ``first_target_steps``, and ``first_target_reached`` counts the runs that did)."""
    out = []
    for shield in order:
        sel = [r for r in rows if r["shield"] == shield]
        if not sel:
            continue
        s: dict[str, Any] = {"shield": shield, "runs": len(sel)}
        s["first_target_reached"] = sum(r["first_target_steps"] != "" for r in sel)
        for k in SUMMED:
            vals = [
                float(r["steps"]) if k == "first_target_steps" and r[k] == "" else r[k] for r in sel
            ]
            v = np.array([float(x) for x in vals if x != ""])
            if len(v):
                s[k], s[f"{k}_min"], s[f"{k}_max"] = (
                    round(float(v.mean()), 4), round(float(v.min()), 4), round(float(v.max()), 4)
                )  # fmt: skip
        out.append(s)
    return out


def plot(runs: Sequence[dict[str, Any]], order: Sequence[str], path: Path) -> Path:
    """shield_study.png (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    fig, ax = plt.subplots(2, 2, figsize=(12, 8.5))
    fmt = FuncFormatter(lambda x, _: steps_label(x))
    for c, shield in enumerate(order):
        sel = [r for r in runs if r["row"]["shield"] == shield]
        if not sel:
            continue
        color, label = f"C{c}", f"{shield} ({len(sel)} seeds)"
        for key, a in (("validation", ax[0, 0]), ("drop_curve", ax[0, 1])):
            if key == "validation":
                n = min(len(r["validation"]) for r in sel)
                if n == 0:
                    continue
                x = np.array([v["steps"] for v in sel[0]["validation"][:n]])
                y = np.array([[v["speed"] for v in r["validation"][:n]] for r in sel])
            else:
                n = min(len(r["drop_curve"]) for r in sel)
                if n == 0:
                    continue
                x = np.array([0] + [p[0] for p in sel[0]["drop_curve"][:n]])
                y = np.array([[0] + [p[1] for p in r["drop_curve"][:n]] for r in sel])
            a.plot(x, y.mean(axis=0), "o-", ms=3, color=color, label=label)
            a.fill_between(x, y.min(axis=0), y.max(axis=0), color=color, alpha=0.2)
        for a, key, lo, hi in ((ax[1, 0], "speed_rad_s", "speed_lo", "speed_hi"),
                               (ax[1, 1], "drop_rate", "drop_lo", "drop_hi")):  # fmt: skip
            v = np.array([r["row"][key] for r in sel], dtype=float)
            err = [v - [r["row"][lo] for r in sel], [r["row"][hi] for r in sel] - v]
            xs = c + np.linspace(-0.15, 0.15, len(sel))
            a.errorbar(xs, v, yerr=err, fmt="o", color=color, capsize=3)
            a.bar(c, v.mean(), width=0.5, color=color, alpha=0.3)
    ax[0, 0].axhline(rotation.TARGET_SPEED, color="gray", ls=":", label="0.5 rad/s")
    ax[0, 0].set(title="validation net turn (mean, band: min-max over seeds)",
                 xlabel="env steps", ylabel="rad/s")  # fmt: skip
    ax[0, 1].set(title="drops while training (cumulative; band: min-max over seeds)",
                 xlabel="env steps", ylabel="dropped training episodes")  # fmt: skip
    n_ep = runs[0]["row"]["episodes"] if runs else 0
    ax[1, 0].set(title=f"final net turn: {n_ep} held-out x 20 s per run (95 % interval)",
                 ylabel="rad/s")  # fmt: skip
    ax[1, 1].set(title="final drop rate per run (Wilson 95 %)", ylabel="drop rate")
    for a in ax[0]:
        a.xaxis.set_major_formatter(fmt)
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    for a in ax[1]:
        a.set_xticks(range(len(order)), order)
        a.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Train what is missing, measure what is unmeasured, write the report; returns the
    per-shield summary."""
    p = ArgumentParser(
        prog="python -m train.shield_study",
        description=(__doc__ or "").split("\n\n")[0],
        epilog="Other options go to the trainer (python -m train.ppo --help). Shields: "
        + "; ".join(f"{k}: {v}" for k, v in SHIELDS.items()),
    )
    p.add_argument("--shields", default=",".join(DEFAULT_SHIELDS),
                   help=f"comma-separated, of {list(SHIELDS)}")  # fmt: skip
    p.add_argument("--seeds", type=int, default=3, help="seeds per shield")
    p.add_argument("--first-seed", type=int, default=1, help="first seed")
    p.add_argument("--total-steps", type=int, default=1_200_000, help="env steps per run")
    p.add_argument("--episodes", type=int, default=TEST_GRASPS, help="held-out episodes per run")
    p.add_argument("--runs", default="runs/shield_study", help="run directories, per shield")
    p.add_argument("--out", default="docs/bench/shield_study", help="CSV, chart, per-run files")
    p.add_argument("--report", action="store_true",
                   help="rebuild the report from --out/runs/*.json only")  # fmt: skip
    a, rest = p.parse_known_args(argv)
    shields = [s for s in a.shields.split(",") if s]
    bad = [s for s in shields if s not in SHIELDS]
    if bad or not shields:
        p.error(f"--shields: unknown {bad}; choose from {list(SHIELDS)}")
    if a.seeds < 1 or a.first_seed < 0 or a.total_steps < 1:
        p.error("--seeds >= 1, --first-seed >= 0, --total-steps >= 1")
    if not 1 <= a.episodes <= TEST_GRASPS:
        p.error(f"--episodes must be in [1, {TEST_GRASPS}]")
    out, runs_root = Path(a.out), Path(a.runs)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    if not a.report:
        import torch

        for shield in shields:
            for seed in range(a.first_seed, a.first_seed + a.seeds):
                file = out / "runs" / f"{shield}__{seed}.json"
                if file.is_file():
                    continue
                run = find_run(runs_root, shield, seed, a.total_steps)
                if run is None:
                    res = rotation.main(
                        [*rest, "--shield", shield, "--seed", str(seed),
                         "--total-steps", str(a.total_steps), "--out", str(runs_root / shield)]
                    )  # fmt: skip
                    run = Path(res["run_dir"])
                torch.set_num_threads(1)
                m = measure_run(run, shield, a.episodes)
                file.write_text(json.dumps(m, indent=1) + "\n")
                r = m["row"]
                print(
                    f"{shield} seed {seed}: {r['drops_per_1000']} drops per 1000 training steps, "
                    f"net {r['speed_rad_s']} rad/s, drops {r['drops']}/{r['episodes']}"
                )
    measured = [json.loads(f.read_text()) for f in sorted((out / "runs").glob("*.json"))]
    order = [s for s in SHIELDS if any(m["row"]["shield"] == s for m in measured)]
    rows = sorted((m["row"] for m in measured), key=lambda r: (order.index(r["shield"]), r["seed"]))
    write_csv(out / "shield_study.csv", rows, columns=COLUMNS)
    summary = summarize(rows, order)
    cols = ["shield", "runs", "first_target_reached"] + [
        f"{k}{x}" for k in SUMMED for x in ("", "_min", "_max")
    ]
    write_csv(out / "shield_study_summary.csv", summary, columns=cols)
    plot(measured, order, out / "shield_study.png")
    for s in summary:
        print(
            f"{s['shield']:>12} ({s['runs']} runs): {s.get('drops_per_1000', '')} drops per 1000 "
            f"training steps; net {s.get('speed_rad_s', '')} rad/s "
            f"({s.get('speed_rad_s_min', '')}-{s.get('speed_rad_s_max', '')}); drop rate "
            f"{s.get('drop_rate', '')}; {s.get('interventions_per_step', '')} interventions "
            f"per step; shield {s.get('shield_ms_median', '')} ms per step"
        )
    print(f"wrote {out / 'shield_study.csv'}, {out / 'shield_study_summary.csv'}, "
          f"{out / 'shield_study.png'}")  # fmt: skip
    return summary


if __name__ == "__main__":
    main(sys.argv[1:])
