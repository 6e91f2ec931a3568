"""When and why a rotation policy drops: the first N test grasps at the centre of the full
ranges (one step of latency, sensor noise), then without the latency, without the noise,
and at nominal physics; per case the drops and when each happened [s]. Writes a CSV::

    python docs/bench/generalist/drop_times.py POLICY_DIR OBJECT [OBJECT ...] --out F.csv
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import replace
from pathlib import Path

from envs.four_finger import Randomization, centre
from train.heldout import evaluate_heldout
from train.policy import load_policy


def cases() -> dict[str, object]:
    mid = centre(Randomization())
    return {"centre": mid, "no latency": replace(mid, latency=0),
            "no noise": replace(mid, noise=(0.0, 0.0, 0.0)), "nominal": None}  # fmt: skip


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("policy", type=Path)
    ap.add_argument("objects", nargs="+")
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    act, kw = load_policy(a.policy)
    rows = []
    for obj in a.objects:
        for name, physics in cases().items():
            r = evaluate_heldout(act, {**kw, "object": obj}, a.episodes, 20.0, physics=physics)
            times = r["drop_seconds"]
            late = sum(t > 10.0 for t in times)
            rows.append({"policy": str(a.policy), "object": obj, "case": name,
                         "episodes": r["episodes"], "drops": r["drops"], "after_10_s": late,
                         "speed_rad_s": round(r["speed_rad_s"], 3),
                         "drop_seconds": " ".join(f"{t:g}" for t in times)})  # fmt: skip
            print(rows[-1], flush=True)
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
