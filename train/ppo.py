"""PPO training (stable-baselines3): ``python -m train.ppo [islands] [options]``.

- ``python -m train.ppo [options]``: the main job, the four-finger in-hand rotation policy
  of thesis ch. 7 (:mod:`train.rotation`; ``python -m train.ppo --help`` lists its options);
- ``python -m train.ppo seeds --seeds N [options]``: the main job for N seeds, each evaluated
  on held-out start grasps, with a CSV and chart of the spread (:mod:`train.seeds`);
- ``python -m train.ppo generalist [options]``: one rotation policy for the sphere, the cylinder
  and the cube over the full randomised ranges (``--generalist``:
  :data:`train.rotation_config.GENERALIST`; docs/four_finger_generalist.md);
- ``python -m train.ppo islands [options]``: PPO on a shielded islands-and-bridges env
  (:mod:`train.islands_ppo`; ``python -m train.ppo islands --help``).

Both tasks run in the one trainer :func:`train.trainer.train` (:data:`TASKS`). ``--resume
RUN_DIR`` picks the task that the run's config.json records
(:func:`train.trainer.run_task`). This module only dispatches; the SB3 plumbing the tasks
share is :mod:`train.sb3`, their evaluation loop :mod:`train.evaluation`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from train import islands_ppo, rotation
from train.trainer import Task, run_task, train

__all__ = ["TASKS", "main"]

TASKS: dict[str, Task] = {t.name: t for t in (rotation.TASK, islands_ppo.TASK)}
"""The tasks by the name their runs' config.json records."""


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """``python -m train.ppo``: the four-finger rotation main job (:data:`train.rotation.TASK`)
    by default; ``islands`` as the first argument trains on the islands-and-bridges toy
    (:data:`train.islands_ppo.TASK`), ``seeds`` runs the main job for several seeds,
    ``generalist`` the rotation task with ``--generalist``.
    ``--resume RUN_DIR`` picks the task from the run's config.json. Returns the trainer's
    final evaluation."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "islands":
        return train(islands_ppo.TASK, argv[1:])
    if argv and argv[0] == "generalist":
        return train(rotation.TASK, ["--generalist", *argv[1:]])
    if argv and argv[0] == "seeds":
        from train import seeds

        return {"seeds": seeds.main(argv[1:])}
    if "--resume" in argv:
        i = argv.index("--resume")
        run_dir = Path(argv[i + 1]) if i + 1 < len(argv) else None
        if run_dir is not None and (run_dir / "config.json").is_file():
            name = run_task(run_dir)
            if name not in TASKS:
                raise SystemExit(f"python -m train.ppo: error: --resume {run_dir}: task {name!r}")
            return train(TASKS[name], argv)
    return train(rotation.TASK, argv)


if __name__ == "__main__":
    main()
