"""PPO training (stable-baselines3): ``python -m train.ppo [islands] [options]``.

- ``python -m train.ppo [options]``: the main job, the four-finger in-hand rotation policy
  of thesis ch. 7 (:mod:`train.rotation`; ``python -m train.ppo --help`` lists its options);
- ``python -m train.ppo seeds --seeds N [options]``: the main job for N seeds, each evaluated
  on held-out start grasps, with a CSV and chart of the spread (:mod:`train.seeds`);
- ``python -m train.ppo islands [options]``: PPO on a shielded islands-and-bridges env
  (:mod:`train.islands_ppo`; ``python -m train.ppo islands --help``).

``--resume RUN_DIR`` picks the trainer from the run's config.json. This module only
dispatches; the SB3 plumbing both trainers share is :mod:`train.sb3`, their evaluation
loop :mod:`train.evaluation`.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from train import islands_ppo, rotation

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """``python -m train.ppo``: the four-finger rotation main job (:func:`train.rotation.main`)
    by default; ``islands`` as the first argument trains on the islands-and-bridges toy
    (:func:`train.islands_ppo.main`). ``--resume RUN_DIR`` picks the trainer from the run's
    config.json. Returns the trainer's final evaluation."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "islands":
        return islands_ppo.main(argv[1:])
    if argv and argv[0] == "seeds":
        from train import seeds

        return {"seeds": seeds.main(argv[1:])}
    if "--resume" in argv:
        i = argv.index("--resume")
        cfg_file = Path(argv[i + 1]) / "config.json" if i + 1 < len(argv) else None
        if cfg_file is not None and cfg_file.is_file():
            if "object" not in json.loads(cfg_file.read_text()):  # rotation runs name one
                return islands_ppo.main(argv)
    return rotation.main(argv)


if __name__ == "__main__":
    main()
