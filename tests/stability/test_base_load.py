"""MaxDisturbance with a base load: the largest s with ``base + s d`` stable (the object's
weight in the MuJoCo scenes), on every method that answers MaxDisturbance."""

from __future__ import annotations

import numpy as np
import pytest

from stability import Existence, Grasp, GraspError, MaxDisturbance, solve
from stability.examples import PINCH_MAX_Z, pinch

UP = [0, 0, 1, 0, 0, 0]


@pytest.mark.parametrize("method", ["refinement", "no_mdp", "exact", "iterative"])
def test_pinch_with_a_base_load(method: str) -> None:
    """A base force b along z shifts the largest force along z by -b (analytic); beyond
    the pinch's 2.22 N the base alone is unstable."""
    g = pinch()
    tol = 0.01 if method == "iterative" else 1e-3
    for b in (1.0, -1.0, 0.5):
        sol = solve(g, MaxDisturbance(UP, commands=[0.1, 0.1], cap=100, base=[0, 0, b, 0, 0, 0]),
                    method=method)  # fmt: skip
        assert sol.stable
        assert sol.value == pytest.approx(PINCH_MAX_Z - b, rel=tol)
        np.testing.assert_allclose(sol.wrench, [0, 0, b + sol.value, 0, 0, 0], atol=1e-12)
        # G c + base + s d = 0 (iterative: its net-wrench tolerance, 1e-3 of the load scale)
        assert sol.residuals()["equilibrium"] < (3e-3 if method == "iterative" else 1e-8)
    sol = solve(g, MaxDisturbance(UP, commands=[0.1, 0.1], cap=100, base=[0, 0, 3, 0, 0, 0]),
                method=method)  # fmt: skip
    assert not sol.stable


def _thesis_planar() -> Grasp:
    return Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)


def test_planar_with_a_base_load_is_the_stability_boundary() -> None:
    """planar: base + v d is stable and base + 1.02 v d is not, for several directions."""
    g = _thesis_planar()
    base = np.array([0.1, 0.3, 0.05])
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(8):
        a = rng.uniform(0, 2 * np.pi)
        d = np.array([np.cos(a), np.sin(a), 0.0])
        sol = solve(g, MaxDisturbance(d, preload=1.0, cap=10, base=base), method="planar")
        assert sol.stable
        v = sol.value
        assert solve(g, Existence(base + v * d, preload=1.0), method="planar").stable
        if 0 < v < 10:
            assert not solve(g, Existence(base + 1.02 * v * d, preload=1.0), method="planar").stable
            checked += 1
    assert checked >= 3
    # a base the grasp cannot hold at all (pulling off the bottom contact, no preload):
    # unstable; pushing into it: held
    assert not solve(g, MaxDisturbance([1, 0, 0], preload=0.0, base=[0, 5, 0]), "planar").stable
    assert solve(g, MaxDisturbance([1, 0, 0], preload=0.0, base=[0, -5, 0]), "planar").stable


def test_gws_with_a_base_load_along_the_direction() -> None:
    """gws: a base t d along the direction takes t off the answer; t beyond it: unstable."""
    g = _thesis_planar()
    d = np.array([0.3, 1.0, 0.0])
    v0 = solve(g, MaxDisturbance(d, cap=100), method="gws").value
    assert 0 < v0 < 100
    for t in (0.25 * v0, 0.5 * v0):
        v = solve(g, MaxDisturbance(d, cap=100, base=t * d), method="gws").value
        assert v == pytest.approx(v0 - t, rel=1e-9)
    assert not solve(g, MaxDisturbance(d, cap=100, base=1.5 * v0 * d), method="gws").stable


def test_bad_base() -> None:
    with pytest.raises(GraspError, match="base"):
        solve(pinch(), MaxDisturbance(UP, commands=[0.1, 0.1], base=[0, 0, 1]))
    with pytest.raises(GraspError, match="base"):
        solve(pinch(), MaxDisturbance(UP, commands=[0.1, 0.1], base=[0, 0, np.nan, 0, 0, 0]))


def test_scene_grasp_with_round_off_jacobian_entries() -> None:
    """barrett_box as read from MuJoCo: the spread joint's Jacobian column has 1e-9 m/rad
    round-off entries next to 0.12 m/rad, which made SCIP's LPs fail ("error in LP solver")
    until the exact model zeroed entries below 1e-7 of the largest. Now the weight alone is
    stable, and refinement and iterative agree on the largest force along the object's +y
    with the weight as base load."""
    import ihm
    from ihm.contacts import grasp_from_mujoco

    model, data = ihm.load_scene("barrett_box")
    g = grasp_from_mujoco(model, data)
    cmd = ihm.scenes.default_preload(model)
    assert np.abs(g.J[:, 0]).min() < 1e-8 < np.abs(g.J[:, 0]).max()  # the round-off entries
    assert solve(g, Existence(g.gravity_wrench, commands=cmd), method="refinement").stable
    q = MaxDisturbance([0, 1, 0, 0, 0, 0], commands=cmd, cap=20, base=g.gravity_wrench)
    ref = solve(g, q, method="refinement", time_limit=60)
    it = solve(g, q, method="iterative", time_limit=60)
    assert ref.stable and it.stable and 1.0 < ref.value < 20
    assert it.value == pytest.approx(ref.value, rel=0.01)
