"""The thesis' grasp experiments (chapters 5 and 6) checked against MuJoCo physics.

The thesis checked its predictions with a load cell on a real hand; we check ours against
simulation: each experiment settles a scene (:mod:`ihm.scenes`), predicts the resistible
load with the stability methods on the grasp read off MuJoCo (:mod:`ihm.sim_maps`) and
measures it by ramping the load on the object in MuJoCo (:mod:`ihm.resistance`), with the
fingers nonbackdrivable (:mod:`ihm.ratchet`) as the thesis models the hands. Each writes
``OUT/<name>.csv`` (one row per prediction or measurement), ``OUT/<name>.png`` and
``OUT/<name>_summary.json`` (the agreement figures: :func:`ihm.sim_maps.agreement`, ratios).

Run ``python -m ihm.experiments NAME [NAME ...] --out docs/experiments`` (``--quick`` for
a coarse direction grid). Names: see :data:`EXPERIMENTS`.
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["EXPERIMENTS", "ExperimentError", "MUJOCO_READ", "run_experiment"]

from stability import GraspError

from ..sim_maps import ramp_limit

#: how every experiment reads a grasp with MuJoCo's stiffness
#: (:func:`ihm.grasp_from_mujoco`): the hand's points within the ramp's 2 mm of the object
#: that do not touch it yet become contacts at their gap (:mod:`ihm.near`), every contact
#: the motion the ramp allows can close, and each contact follows MuJoCo's static law as
#: a convex piecewise-linear spring (:mod:`ihm.contact_law`)
MUJOCO_READ: dict[str, Any] = {"compliance": "mujoco", "near": ramp_limit()[0],
                               "contact_law": "fitted"}  # fmt: skip

#: experiment name -> "module:function"; the function takes (out, quick, workers) and
#: returns a JSON-serialisable summary.
EXPERIMENTS: dict[str, str] = {
    "barrett_box": "ihm.experiments.barrett:box",
    "barrett_box_3d": "ihm.experiments.barrett:box_3d",
    "barrett_cube": "ihm.experiments.barrett:cube",
    "barrett_flask": "ihm.experiments.barrett:flask",
    "tendon_box": "ihm.experiments.tendon:tendon_box",
    "linkage_box": "ihm.experiments.linkage:linkage_box",
}


class ExperimentError(GraspError):
    """Unknown experiment name."""


def _function(name: str) -> Callable[..., dict[str, Any]]:
    if name not in EXPERIMENTS:
        raise ExperimentError(
            f"unknown experiment {name!r}; choose one of {', '.join(sorted(EXPERIMENTS))}"
        )
    module, func = EXPERIMENTS[name].split(":")
    return getattr(importlib.import_module(module), func)


def run_experiment(
    name: str, out: str | Path = "docs/experiments", quick: bool = False, workers: int = 1
) -> dict[str, Any]:
    """Run experiment ``name``; writes its CSV, PNG and ``<name>_summary.json`` into ``out``
    and returns the summary."""
    fn = _function(name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = fn(out, quick=quick, workers=workers)
    (out / f"{name}_summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    return summary
