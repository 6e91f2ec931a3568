"""method="exact" (the exact problem by SCIP's spatial branch-and-bound; formerly "spatial")
and refinement's certificates: known answers, residuals of the exact conditions (maximum
dissipation included), agreement with planar and refinement, bad input, the old name."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from stability import (
    Existence,
    GraspError,
    MaxDisturbance,
    MethodError,
    OptimalCommands,
    available_methods,
    examples,
    solve,
)

Z = [0, 0, 1, 0, 0, 0]


def _exact_check(sol, tol=1e-7) -> None:
    """Every condition of the exact problem holds, maximum dissipation and the circular
    cone included (refinement only bounds the cone's excess)."""
    assert sol.status == "solved" and sol.stable
    assert "max_dissipation" in sol.conditions and "friction_cone" in sol.conditions
    scale = 1.0 + float(np.abs(sol.forces).max())
    assert sol.max_residual() <= tol * scale, sol.residuals()


def test_pinch_spot_checks() -> None:
    """The thesis' pinch: 2 mu tau / lever = 2.22 N along z exactly; 1 N unstable with no
    commands; 2.2 N stable and 2.5 N unstable with 0.1 N m."""
    g = examples.pinch()
    sol = solve(g, MaxDisturbance(Z, commands=0.1, cap=100.0), method="exact")
    _exact_check(sol)
    assert sol.value == pytest.approx(examples.PINCH_MAX_Z, rel=1e-6)
    assert sol.stats["polished"]  # the exact LP of SCIP's modes took over: residuals ~ 0
    w = np.array(Z, dtype=float)
    assert solve(g, Existence(-1.0 * w), method="exact").stable is False
    assert solve(g, Existence(-2.2 * w, commands=0.1), method="exact").stable is True
    assert solve(g, Existence(-2.5 * w, commands=0.1), method="exact").stable is False


@pytest.mark.parametrize("direction", [(0, 1, 0), (1, 1, 0.02), (-1, 0.5, 0)])
def test_agrees_with_planar_on_the_embedded_grasp(direction) -> None:
    """Two independent exact methods: planar's slip-state enumeration on the thesis'
    three-contact grasp and exact on the same grasp embedded in z = 0."""
    planar = solve(examples.three_planar(), MaxDisturbance(direction, preload=1.0, cap=100.0),
                   method="planar")  # fmt: skip
    q = MaxDisturbance(examples.embed_wrench(direction), preload=1.0, cap=100.0)
    sol = solve(examples.three_embedded(), q, method="exact")
    _exact_check(sol)
    assert sol.value == pytest.approx(planar.value, rel=1e-5)


def test_tendon_finger_agrees_with_refinement_and_its_certificate() -> None:
    """The tendon finger pushed along +y (where a coarse relaxation and no_mdp hold 100 N):
    exact's optimum, refinement's converged bound (above it, within 1e-4) and
    refinement's certified exact point (stats exact_value) agree."""
    g = examples.tendon_finger()
    q = MaxDisturbance([0, 1, 0, 0, 0, 0], commands=examples.TENDON_FORCE, cap=100.0)
    ex = solve(g, q, method="exact")
    _exact_check(ex)
    ref = solve(g, q, method="refinement")
    assert ex.value <= ref.value * (1 + 1e-9)  # the relaxation contains the exact problem
    assert ref.value == pytest.approx(ex.value, rel=1e-4)
    assert ref.stats["exact_value"] == pytest.approx(ex.value, rel=1e-6)


def test_optimal_commands_and_robustness() -> None:
    """Pinch holding 1 N along -z: the least largest command is mu c_n = 1/2 per contact,
    i.e. lever / (2 mu) = 0.045 N m on both fingers (exact and refinement agree); a
    normal uncertainty never raises the max disturbance."""
    g = examples.pinch()
    w = [0, 0, -1.0, 0, 0, 0]
    want = examples.PINCH_LEVER / (2 * examples.PINCH_MU)
    sp = solve(g, OptimalCommands(w), method="exact")
    _exact_check(sp)
    assert sp.value == pytest.approx(want, rel=1e-5)
    assert sp.commands.max() == pytest.approx(want, rel=1e-5)
    ref = solve(g, OptimalCommands(w), method="refinement")
    assert ref.value == pytest.approx(sp.value, rel=1e-3)
    q = MaxDisturbance([0, 0.3, 1, 0, 0, 0], commands=0.1, cap=100.0)
    nominal = solve(g, q, method="exact").value
    robust = solve(g, q, method="exact", normal_uncertainty=math.radians(2.5)).value
    assert robust <= nominal * (1 + 1e-6)


def test_robust_spring_law_uses_the_true_slide() -> None:
    """With eta > 0 the slide bound s enters the spring law, so it must equal |d_t| (a
    free s would unload any contact): on the preloaded embedded grasp the robust answer
    never exceeds the nominal one and its s equals |d_t| (stats violations "slide")."""
    g = examples.three_embedded()
    q = MaxDisturbance(examples.embed_wrench((1, 1, 0.02)), preload=1.0, cap=100.0)
    nominal = solve(g, q, method="exact")
    robust = solve(g, q, method="exact", normal_uncertainty=0.2)
    assert robust.status == "solved" and robust.value <= nominal.value * (1 + 1e-6)
    assert robust.stats["violations"]["slide"] <= 1e-7


def test_refinement_existence_certificate_is_exact() -> None:
    """A stable refinement answer whose relaxed point survives the exact LP with its
    modes is returned as that exact point: every condition, maximum dissipation and the
    circular cone included."""
    g = examples.tendon_finger()
    sol = solve(g, Existence([0, 1.0, 0, 0, 0, 0], commands=examples.TENDON_FORCE),
                method="refinement")  # fmt: skip
    assert sol.stats["certified"]
    _exact_check(sol)


def test_bad_input_and_time_out() -> None:
    g = examples.pinch()
    q = MaxDisturbance(Z, commands=0.1)
    with pytest.raises(MethodError, match="SCIP"):
        solve(g, q, method="exact", backend="highs")
    with pytest.raises(GraspError):
        solve(examples.three_planar(), MaxDisturbance((0, 1, 0)), method="exact")
    for bad in ({"feastol": 0.0}, {"gap": 1.0}, {"normal_uncertainty": -0.1},
                {"motion_bound": 0.5}, {"frobnicate": 1}):  # fmt: skip
        with pytest.raises(GraspError):
            solve(g, q, method="exact", **bad)
    t = solve(examples.tendon_finger(), MaxDisturbance([0, 0, 1, 0, 0, 0], commands=1.0),
              method="exact", time_limit=0.01)  # fmt: skip
    assert t.status == "timeout" and t.stable is None


def test_old_name_spatial_still_works_and_warns() -> None:
    """``method="spatial"`` is the old name of ``exact``: the same answer, a
    DeprecationWarning that names the new one, and ``exact`` itself does not warn."""
    g = examples.pinch()
    q = MaxDisturbance(Z, commands=0.1, cap=100.0)
    with pytest.warns(DeprecationWarning, match="'exact'"):
        old = solve(g, q, method="spatial")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = solve(g, q, method="exact")
    assert old.method == new.method == "exact"
    assert old.value == new.value
    assert "spatial" not in available_methods() and "exact" in available_methods()
