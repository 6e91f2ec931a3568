"""MuJoCo Menagerie's Robotiq 2F-85 read with ``compliance="mujoco"`` (docs/linkage.md).

The model is not part of this repository: the tests run where a Menagerie checkout sits at
``../shared/menagerie`` next to the repository, and skip otherwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ihm.contacts import SceneGrasp, grasp_from_mujoco
from ihm.experiments import menagerie_2f85 as m2f85
from ihm.resistance import ResistanceOptions, simulated_resistance
from ihm.sim_maps import scene_disturbance
from stability import Existence, Solution, solve

XML = Path(__file__).resolve().parents[3] / "shared/menagerie/robotiq_2f85/2f85.xml"

pytestmark = pytest.mark.skipif(not XML.is_file(), reason=f"no Menagerie checkout at {XML}")


def _push(grasp: SceneGrasp, name: str, time_limit: float, cap: float = m2f85.CAP,
          limit: tuple[float, float] | None = None) -> Solution:  # fmt: skip
    """The axis push ``name`` from the settled state (the ramp's motion limit by default)."""
    q = scene_disturbance(grasp, m2f85.object_direction(grasp, name), grasp.commands, cap, limit)
    return solve(grasp, q, method="modesearch", time_limit=time_limit)


def _noslip_breakaway(name: str) -> float:
    model, data = m2f85.settled(XML)
    model.opt.noslip_iterations = m2f85.NOSLIP_ITERATIONS
    r = simulated_resistance(model, data, m2f85.axis(name),
                             options=ResistanceOptions(cap=100.0, check_rate=False))  # fmt: skip
    assert r.reason == "slip"
    return r.value


@pytest.fixture(scope="module")
def grasp() -> SceneGrasp:
    model, data = m2f85.settled(XML)
    return grasp_from_mujoco(model, data, reduce="line", compliance="mujoco")


def test_settled_state_is_the_models_rest(grasp: SceneGrasp) -> None:
    """One command per column of R, and with MuJoCo's normal forces as preload the weight
    alone is held where MuJoCo left it: no motion, the preload's forces."""
    assert grasp.commands.shape == (grasp.R.shape[1],)
    assert np.all(grasp.stiffness > 1e4)  # N/m: soft contacts of a few 1e4-1e5 N/m
    sol = solve(grasp, Existence(grasp.gravity_wrench, commands=grasp.commands,
                                 preload=grasp.forces[:, 0]), method="modesearch")  # fmt: skip
    assert sol.stable
    shift, turn, hand = m2f85.motion_size(sol)
    assert max(shift, hand) < 1e-5 and turn < 1e-3
    assert np.allclose(sol.forces.reshape(-1, 3)[:, 0], grasp.forces[:, 0], rtol=0.05, atol=0.5)


def test_sideways_push_matches_the_breakaway(grasp: SceneGrasp) -> None:
    """+y: the model's exact point (every contact sticking, no motion) holds 44.4 N; MuJoCo
    with noslip breaks away at 44.8 N from the same settled state."""
    sol = _push(grasp, "+y", 5.0)
    assert sol.lower is not None and 40.0 < sol.lower < 50.0
    assert 1 / 1.5 <= sol.lower / _noslip_breakaway("+y") <= 1.5


def test_downward_push_within_the_ramps_motion(grasp: SceneGrasp) -> None:
    """+z: without a motion limit the model holds the cap only by sliding the box metres
    down the pads' 0.7-degree wedge (a first-order mechanism); within the ramp's 2 mm and
    0.05 rad it holds about MuJoCo's noslip breakaway (68.8 N)."""
    free = _push(grasp, "+z", 30.0, limit=(np.inf, np.inf))
    assert free.stable and free.stats.get("capped")
    assert m2f85.motion_size(free)[0] > 1.0
    held = _push(grasp, "+z", 30.0)
    assert held.status == "solved" and held.residuals()["motion_limit"] <= 1e-9
    assert m2f85.motion_size(held)[0] <= 2e-3 * (1 + 1e-6)
    assert 1 / 1.5 <= held.value / _noslip_breakaway("+z") <= 1.5
