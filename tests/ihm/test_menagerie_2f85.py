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
from stability import Existence, solve

XML = Path(__file__).resolve().parents[3] / "shared/menagerie/robotiq_2f85/2f85.xml"

pytestmark = pytest.mark.skipif(not XML.is_file(), reason=f"no Menagerie checkout at {XML}")


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
    sol = m2f85.ask(grasp, "+y", "modesearch", 5.0, preload=grasp.forces[:, 0])
    assert sol.lower is not None and 40.0 < sol.lower < 50.0
    model, data = m2f85.settled(XML)
    model.opt.noslip_iterations = m2f85.NOSLIP_ITERATIONS
    r = simulated_resistance(model, data, m2f85.axis("+y"),
                             options=ResistanceOptions(cap=100.0, check_rate=False))  # fmt: skip
    assert r.reason == "slip"
    assert 1 / 1.5 <= sol.lower / r.value <= 1.5


def test_downward_push_is_held_only_by_a_large_motion_beyond_friction(
    grasp: SceneGrasp,
) -> None:
    """+z: up to 65 N the model holds the box within micrometres; at the cap its answer
    slides the box metres down the pads' 0.7-degree wedge (a first-order mechanism)."""
    small = m2f85.ask(grasp, "+z", "modesearch", 30.0, cap=65.0, preload=grasp.forces[:, 0])
    assert small.stable and small.value == pytest.approx(65.0)
    assert m2f85.motion_size(small)[0] < 1e-4
    big = m2f85.ask(grasp, "+z", "modesearch", 30.0, preload=grasp.forces[:, 0])
    assert big.stable and big.stats.get("capped")
    assert m2f85.motion_size(big)[0] > 1.0
