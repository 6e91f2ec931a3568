"""Policies trained on coarser physics run on finer physics: ``python -m train.bench transfer``.

Evaluates the shipped policy (trained at 2 ms) and one trained at 2.5 ms
(``policies/four_finger_sphere_2.5ms``, ``python -m train.ppo --timestep 0.0025``, same
seed and budget) under 1, 2 and 2.5 ms physics, from the same start grasps
(:func:`timestep_transfer`, :func:`train.policy.evaluate`). Writes
``--out``/four_finger_transfer.csv (about 10 min with the defaults; ``python -m envs.bench
--transfer`` names this command).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from envs.four_finger import grasp_cache
from stability.io import write_csv
from train.policy import SHIPPED, evaluate, load_policy
from train.rotation import env_physics

__all__ = ["TRANSFER_POLICIES", "TRANSFER_TIMESTEPS", "add_parser", "run", "timestep_transfer"]

TRANSFER_POLICIES = ("four_finger_sphere", "four_finger_sphere_2.5ms")  # in policies/
TRANSFER_TIMESTEPS = (0.001, 0.002, 0.0025)  # [s]; 0.05 s / timestep substeps each


def timestep_transfer(episodes: int = 100, seconds: float = 20.0) -> list[dict[str, object]]:
    """Does a policy trained on coarser physics still work on finer physics? Each policy of
    :data:`TRANSFER_POLICIES` (its training timestep in its config.json), deterministic,
    under each timestep of :data:`TRANSFER_TIMESTEPS` (20 Hz policy in every case), over
    ``episodes`` episodes of ``seconds`` from the same start grasps (the shipped env's
    cache, 2 ms): mean and median speed [rad/s] and drops."""
    start = grasp_cache("sphere", True)
    rows = []
    for name in TRANSFER_POLICIES:
        act, kw = load_policy(SHIPPED.parent / name)
        for timestep in TRANSFER_TIMESTEPS:
            physics = env_physics(timestep)
            label = f"{timestep * 1e3:g} ms x {physics['frame_skip']}"
            # n_grasps 1: the env's own start cache is not used (start_grasps)
            env_kw = {**kw, **physics, "n_grasps": 1}
            r = evaluate(act, env_kw, episodes, seconds, start_grasps=start)
            rows.append(
                {
                    "policy": name,
                    "trained_timestep_s": kw["sim"].timestep,
                    "physics": label,
                    "episodes": episodes,
                    "speed_rad_s": round(r["speed_rad_s"], 3),
                    "speed_median_rad_s": round(r["speed_median_rad_s"], 3),
                    "drops": int(round(r["drop_rate"] * episodes)),
                }
            )
    return rows


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """The ``transfer`` subcommand."""
    p = sub.add_parser(
        "transfer",
        help="policies trained at 2 and 2.5 ms under 1, 2, 2.5 ms physics",
        description=(__doc__ or "").split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--episodes", type=int, default=100, help="episodes per policy and physics")
    p.add_argument("--seconds", type=float, default=20.0, help="episode length [s]")
    p.add_argument("--out", default="bench_out", help="directory for the CSV")
    p.set_defaults(run=run, parser=p)
    return p


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    """Evaluate, print, write four_finger_transfer.csv; returns the rows."""
    if args.episodes < 1 or not args.seconds > 0:
        args.parser.error("--episodes must be >= 1 and --seconds > 0")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = timestep_transfer(args.episodes, args.seconds)
    write_csv(out / "four_finger_transfer.csv", rows)
    for r in rows:
        print(
            f"{r['policy']:28s} under {r['physics']:12s}: {r['speed_rad_s']:.3f} rad/s "
            f"(median {r['speed_median_rad_s']:.3f}), {r['drops']}/{r['episodes']} drops"
        )
    print(f"wrote {out / 'four_finger_transfer.csv'} ({time.perf_counter() - t0:.0f} s)")
    return rows
