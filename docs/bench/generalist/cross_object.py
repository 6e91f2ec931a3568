"""Each shipped robust rotation policy on each training object, nominal and at the full
ranges' worst corner (10 held-out episodes x 20 s each): which policy starts the generalist.

Run from the repository root: ``python docs/bench/generalist/cross_object.py`` (about 2 min);
writes ``docs/bench/generalist/cross_object.csv``.
"""

from pathlib import Path

import torch

from envs.four_finger import PhysicsSample
from stability.io import write_csv
from train.heldout import evaluate_heldout
from train.policy import load_policy

WORST = PhysicsSample(0.5, 0.5, 2.0, 0.8, 1, (0.005, 0.001, 0.05))
CASES = (("nominal", None), (WORST.label(), WORST))

torch.set_num_threads(1)
rows = []
for name in ("sphere_robust", "cylinder_robust", "cube_robust"):
    act, kw = load_policy(Path(f"policies/four_finger_{name}"))
    for obj in ("sphere", "cylinder", "cube"):
        for label, physics in CASES:
            k = {**kw, "object": obj, "turned_prob": 0.0, "replay_prob": 0.0}
            r = evaluate_heldout(act, k, 10, 20.0, physics=physics)
            rows.append({"policy": f"four_finger_{name}", "object": obj, "physics": label,
                         "episodes": r["episodes"], "speed_rad_s": round(r["speed_rad_s"], 3),
                         "drops": r["drops"]})  # fmt: skip
            print(rows[-1], flush=True)
write_csv(Path("docs/bench/generalist/cross_object.csv"), rows, list(rows[0]))
