"""What coarser physics changes in what the policy sees: ``python -m train.bench fidelity``.

From states of the shipped policy's rollouts, one policy step (50 ms) under each physics
setting of :data:`FIDELITY` (timestep, substeps, solver, tolerance), compared with a
converged reference (0.5 ms x 100, Newton to 1e-12): the reward (the object's yaw rate),
the object's position and the observed link normal forces (:func:`timestep_fidelity`;
:func:`envs.four_finger.policy_step_outcomes`). Writes ``--out``/four_finger_fidelity.csv
(it loads a trained policy, which lives in ``train``; ``python -m envs.bench --fidelity``
names this command).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from envs.four_finger import FourFingerRotate, policy_step_outcomes, save_state
from stability.io import write_csv
from train.policy import SHIPPED, load_policy

__all__ = ["FIDELITY", "add_parser", "run", "timestep_fidelity"]

FIDELITY = (  # label, timestep [s], substeps, solver, tolerance
    ("1 ms x 50, Newton converged", 0.001, 50, "newton", 1e-12),
    ("2 ms x 25, PGS 1e-8", 0.002, 25, "pgs", 1e-8),
    ("2 ms x 25, PGS 1e-6", 0.002, 25, "pgs", 1e-6),
    ("2 ms x 25, PGS 1e-4 (shipped)", 0.002, 25, "pgs", 1e-4),
    ("2 ms x 25, PGS 1e-3", 0.002, 25, "pgs", 1e-3),
    ("2.5 ms x 20, PGS 1e-4", 0.0025, 20, "pgs", 1e-4),
    ("3.125 ms x 16, PGS 1e-4", 0.003125, 16, "pgs", 1e-4),
)


def timestep_fidelity(episodes: int = 12, every: int = 4) -> list[dict[str, object]]:
    """What the policy sees under coarser physics: from states of the shipped policy's
    rollouts (every ``every``-th step of ``episodes`` episodes, with that step's action
    applied), one policy step (50 ms) per setting of :data:`FIDELITY`, compared with a
    converged reference (0.5 ms x 100, Newton to 1e-12): the reward (the object's yaw rate
    [rad/s]), the object's position [mm] and the observed link normal forces [N]
    (largest link error per state); median and 95th percentile over the states."""
    act, kw = load_policy(SHIPPED)
    env = FourFingerRotate(**kw)
    d, ph = env.data, env.physics
    states = []
    for ep in range(episodes):
        obs, _ = env.reset(seed=ep)
        for t in range(64):
            a = act(obs)
            if t % every == 0:  # the state the step starts from, setpoints already moved
                ctrl0 = d.ctrl.copy()
                step = np.clip(a, -1, 1) * env.max_setpoint_step
                d.ctrl[:] = np.clip(d.ctrl + step, ph.ctrl_lo, ph.ctrl_hi)
                states.append(save_state(env))
                d.ctrl[:] = ctrl0
            obs, _, terminated, _, _ = env.step(a)
            if terminated:
                break

    ref = policy_step_outcomes(env, states, 0.0005, 100, "newton", 1e-12)
    rows = []
    for label, *setting in FIDELITY:
        e = policy_step_outcomes(env, states, *setting) - ref  # type: ignore[arg-type]
        yaw, pos = np.abs(e[:, 0]), np.linalg.norm(e[:, 1:4], axis=1)
        force = np.abs(e[:, 4:]).max(axis=1)
        rows.append(
            {
                "setting": label,
                "states": len(states),
                "yaw_rate_err_median": round(float(np.median(yaw)), 4),
                "yaw_rate_err_p95": round(float(np.percentile(yaw, 95)), 4),
                "pos_err_mm_median": round(float(np.median(pos)), 4),
                "pos_err_mm_p95": round(float(np.percentile(pos, 95)), 4),
                "force_err_median": round(float(np.median(force)), 4),
                "force_err_p95": round(float(np.percentile(force, 95)), 4),
                "yaw_rate_median_abs": round(float(np.median(np.abs(ref[:, 0]))), 4),
            }
        )
    return rows


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """The ``fidelity`` subcommand."""
    p = sub.add_parser(
        "fidelity",
        help="what coarser physics changes in one policy step",
        description=(__doc__ or "").split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--episodes", type=int, default=12, help="episodes of the shipped policy")
    p.add_argument("--every", type=int, default=4, help="steps between the states taken")
    p.add_argument("--out", default="bench_out", help="directory for the CSV")
    p.set_defaults(run=run, parser=p)
    return p


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    """Measure, print, write four_finger_fidelity.csv; returns the rows."""
    if args.episodes < 1 or args.every < 1:
        args.parser.error("--episodes and --every must be >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = timestep_fidelity(args.episodes, args.every)
    write_csv(out / "four_finger_fidelity.csv", rows)
    for r in rows:
        print(
            f"{r['setting']:32s} yaw rate error {r['yaw_rate_err_median']:.3f} "
            f"(p95 {r['yaw_rate_err_p95']:.3f}) rad/s, object {r['pos_err_mm_median']:.3f} mm, "
            f"link force {r['force_err_median']:.3f} N"
        )
    print(f"wrote {out / 'four_finger_fidelity.csv'} ({time.perf_counter() - t0:.0f} s)")
    return rows
