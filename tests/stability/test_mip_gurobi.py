"""The optional Gurobi backend of stability.mip (gurobipy; skipped where it is not installed):
the same answers as SCIP and HiGHS on test_mip_backends' random MIPs, native indicators and
SOS2, statuses, the size-limited licence as a clear status, and one refinement query."""

from __future__ import annotations

import math

import numpy as np
import pytest

gp = pytest.importorskip("gurobipy")

from test_mip_backends import brute_force, random_model  # noqa: E402  (same generators)

from stability import MaxDisturbance, MethodError, ModelError, mip  # noqa: E402
from stability import solve as solve_grasp  # noqa: E402
from stability.bench.grasps import balanced_commands  # noqa: E402
from stability.examples import random_fingers  # noqa: E402
from stability.mip import MipModel, solve  # noqa: E402
from stability.mip import _gurobi as grb  # noqa: E402
from stability.model.run import MipOptions  # noqa: E402

INFEASIBLE = ("infeasible", "infeasible_or_unbounded")


def _same_status(a: str, b: str) -> bool:
    return a == b or (a in INFEASIBLE and b in INFEASIBLE)


def test_gurobi_is_listed_and_accepted_by_the_methods(monkeypatch):
    assert mip.BACKENDS == ("highs", "scip", "gurobi")
    assert "gurobi" in mip.available_backends()
    assert MipOptions(backend="gurobi").backend == "gurobi"
    assert MipOptions().backend == mip.DEFAULT_BACKEND == "highs"  # defaults unchanged
    monkeypatch.setattr(mip, "available_backends", lambda: ["highs", "scip"])
    with pytest.raises(MethodError, match="pip install gurobipy"):
        MipOptions(backend="gurobi")


@pytest.mark.parametrize("with_sos2", [False, True])
def test_same_answers_as_scip_and_highs_on_random_models(with_sos2):
    rng = np.random.default_rng(12 + with_sos2)  # test_mip_backends' models
    counts = {"optimal": 0, "infeasible": 0, "indicators": 0, "sos2": 0}
    for _ in range(40):
        m = random_model(rng, with_sos2)
        counts["indicators"] += len(m.indicators)
        counts["sos2"] += len(m.sos2)
        status, best = brute_force(m)
        counts[status] += 1
        g = solve(m, "gurobi")
        for other in (solve(m, "scip"), solve(m, "highs")):
            assert _same_status(g.status, other.status), (other.backend, g.status, other.status)
        assert _same_status(g.status, status), (g.status, g.message, m.summary())
        if status == "optimal":
            for other in ("scip", "highs"):
                want = solve(m, other).objective
                assert g.objective == pytest.approx(want, rel=1e-6, abs=1e-9), other
            assert g.objective == pytest.approx(best, rel=1e-6, abs=1e-9)
            assert max(g.violations.values()) <= 1e-6
            assert g.message.startswith("Gurobi status OPTIMAL")
    assert counts["optimal"] >= 15 and counts["infeasible"] >= 1
    assert counts["indicators"] >= 40 and counts["sos2"] == (40 if with_sos2 else 0)


def test_native_indicators_need_no_bounds_and_take_equalities():
    """Indicators on free variables (HiGHS' big-M refuses them) and ``==`` indicators of
    either activity."""
    for on, want, want_y in ((1, 1.0, 2.0), (0, -14.0, -7.0)):
        m = MipModel("free")
        x = m.add_var(-math.inf, math.inf, name="free_x")
        y = m.add_var(-math.inf, math.inf, name="free_y")
        z = m.add_var(kind="B")
        m.add_indicator(z, [x], [1.0], "<=", 1.0)  # z = 1 => x <= 1
        m.add_indicator(z, [x, y], [1.0, 1.0], "==", 3.0)  # z = 1 => x + y = 3
        m.add_indicator(z, [y], [1.0], "==", -7.0, active=0)  # z = 0 => y = -7
        m.add_indicator(z, [x], [1.0], "==", -7.0, active=0)  # z = 0 => x = -7
        m.add_constraint([y], [1.0], "<=", 2.5)
        m.add_constraint([z], [1.0], "==", on)
        m.set_objective([x, y], [1.0, 1.0 - on], maximize=True)  # z = 0: x + y
        with pytest.raises(ModelError, match="free_x"):
            solve(m, "highs")
        r = solve(m, "gurobi")
        assert r.optimal and r.objective == pytest.approx(want)
        assert r.x[y] == pytest.approx(want_y)
        assert r.objective == pytest.approx(solve(m, "scip").objective)


def test_native_sos2_piecewise_minimum_and_adjacency():
    """test_mip_backends' nonconvex piecewise-linear minimum (1.0 at x = 5, where a convex
    relaxation gives 1.5), every segment of a 9-member SOS2 reachable, and two members two
    apart never both nonzero; members with a negative lower bound too (no encoding needs
    bounds)."""
    xs = np.arange(6.0)
    fs = np.array([3.0, 1.0, 2.0, 0.5, 2.5, 1.0])
    m = MipModel("pwl")
    lam = m.add_vars(6, 0, 1, name="lam")
    x, f = m.add_var(0, 5, name="x"), m.add_var(-10, 10, name="f")
    m.add_constraint(lam, 1.0, "==", 1)
    m.add_constraint(np.append(lam, x), np.append(xs, -1), "==", 0)
    m.add_constraint(np.append(lam, f), np.append(fs, -1), "==", 0)
    m.add_sos2(lam, weights=np.arange(6.0)[::-1])  # reversed weights: the same set
    m.add_constraint([x], [1.0], ">=", 3.5)
    m.set_objective([f], [1.0])
    r = solve(m, "gurobi")
    assert r.optimal and r.objective == pytest.approx(1.0, abs=1e-7)
    assert r.x[x] == pytest.approx(5.0, abs=1e-7)
    for g in range(8):
        probe = MipModel("probe")
        lam2 = probe.add_vars(9, -1.0, 2.0)
        probe.add_sos2(lam2)
        probe.add_constraint([lam2[g], lam2[g + 1]], [1.0, 1.0], "==", 3.0)
        probe.set_objective(lam2, 1.0, maximize=True)
        r = solve(probe, "gurobi")
        assert r.optimal and r.objective == pytest.approx(3.0)
        assert r.violations["sos2"] == 0.0
    apart = MipModel("apart")
    lam3 = apart.add_vars(9, 0.0, 2.0)
    apart.add_sos2(lam3)
    apart.add_constraint([lam3[2], lam3[4]], [1.0, 1.0], ">=", 1.5)
    apart.add_constraint([lam3[2]], [1.0], ">=", 0.5)
    apart.add_constraint([lam3[4]], [1.0], ">=", 0.5)
    assert solve(apart, "gurobi").status in INFEASIBLE


def test_statuses_timeout_infeasible_unbounded():
    rng = np.random.default_rng(3)  # test_mip_backends' market-split instance
    m = MipModel("split")
    z = m.add_vars(40, kind="B")
    for _ in range(4):
        a = rng.integers(0, 100, size=40)
        m.add_constraint(z, a, "==", float(a.sum() // 2))
    m.set_objective(z, rng.normal(size=40))
    r = solve(m, "gurobi", time_limit=0.05)
    if r.status == "optimal":
        pytest.skip("Gurobi solved the market-split instance within 0.05 s")
    assert r.status == "timeout", (r.status, r.message)
    assert "TIME_LIMIT" in r.message
    assert r.x is None or max(r.violations.values()) <= 1e-6
    inf = MipModel("inf")
    x = inf.add_var(0, 1)
    inf.add_var(kind="B")
    inf.add_constraint([x], [1.0], ">=", 2.0)
    assert solve(inf, "gurobi").status in INFEASIBLE
    unb = MipModel("unb")
    y = unb.add_var(0, math.inf)
    unb.add_var(kind="B")
    unb.set_objective([y], [1.0], maximize=True)
    assert solve(unb, "gurobi").status in ("unbounded", "infeasible_or_unbounded")
    lp = MipModel("lp")  # no integers: an LP, whose bound is its objective
    v = lp.add_var(0, 4)
    lp.set_objective([v], [2.0], maximize=True, offset=1.0)
    r = solve(lp, "gurobi")
    assert r.optimal and r.objective == pytest.approx(9.0) and r.bound == pytest.approx(9.0)


def test_gurobi_counts_rows_indicators_and_sos2_like_gurobi():
    m = MipModel("count")
    x = m.add_vars(4, 0, 1)
    z = m.add_var(kind="B")
    m.add_row(x[:2], 1.0, 0.5, 1.5)  # ranged: two rows
    m.add_row(x[2:], 1.0, 1.0, 1.0)  # equality: one
    m.add_row(x[1:3], 1.0)  # free: none
    m.add_indicator(z, [x[3]], [1.0], "==", 0.25)  # one general constraint
    m.add_sos2(x[:3])
    m.add_sos2(x[2:])  # two members: no constraint
    assert grb.gurobi_size(m) == (5, 2 + 1 + 1 + 1)


def _needs_size_limited_licence():
    if not grb._size_limited():
        pytest.skip("the installed Gurobi licence is not size-limited")


def test_model_over_the_licence_limit_is_a_clear_status():
    _needs_size_limited_licence()
    m = MipModel("big")
    x = m.add_vars(2100, 0, 1)
    m.add_constraint(x, 1.0, "<=", 3.0)
    m.set_objective(x, 1.0, maximize=True)
    r = solve(m, "gurobi")
    assert r.status == "error" and r.x is None
    assert "size-limited licence covers models up to 2000 variables and 2000 constraints" in (
        r.message
    )
    assert "this model has 2100 variables and 1 constraints" in r.message
    rows = MipModel("rows")  # few variables, 1001 ranged rows = 2002 constraints
    y = rows.add_vars(2, 0, 1)
    for _ in range(1001):
        rows.add_row(y, 1.0, 0.0, 1.5)
    r = solve(rows, "gurobi")
    assert r.status == "error" and "2 variables and 2002 constraints" in r.message


def test_licence_error_from_gurobi_gets_the_same_message(monkeypatch):
    """With the pre-check fooled (as under a full licence), Gurobi's own refusal (error
    10010) is turned into the same message, not a bare GurobiError."""
    _needs_size_limited_licence()
    monkeypatch.setattr(grb, "_size_limited", lambda: False)
    m = MipModel("big")
    x = m.add_vars(1990, 0, 1)
    z = m.add_vars(20, kind="B")
    m.add_constraint(x, 1.0, "<=", 3.0)
    m.set_objective(np.append(x, z), 1.0, maximize=True)
    r = solve(m, "gurobi")
    assert r.status == "error" and r.x is None
    assert "size-limited licence" in r.message and "2010 variables" in r.message
    assert "Model too large" in r.message  # Gurobi's own words are kept


def test_refinement_max_disturbance_agrees_with_scip():
    """One refinement query on a 3-contact random-finger grasp (as stability.bench grasps
    builds them): the same largest disturbance as SCIP."""
    rng = np.random.default_rng(11)
    while True:
        g = random_fingers(rng, 3)
        f = balanced_commands(g)
        if f is not None:
            break
    d = rng.normal(size=6) * np.array([1, 1, 1, 0.05, 0.05, 0.05])
    q = MaxDisturbance(d / np.linalg.norm(d), commands=f, cap=100.0)
    ref = solve_grasp(g, q, method="refinement", backend="scip", time_limit=120)
    sol = solve_grasp(g, q, method="refinement", backend="gurobi", time_limit=120)
    assert ref.status == sol.status == "solved", (ref.stats, sol.stats)
    assert sol.stable == ref.stable
    # both are exact points (lower bounds) under their relaxation's bound: each backend's
    # value lies under the other's bound, and they agree within the bracket's 1e-4
    assert ref.value <= sol.upper * (1 + 1e-9) and sol.value <= ref.upper * (1 + 1e-9)
    assert sol.value == pytest.approx(ref.value, rel=1e-4)
    assert sol.stats["mips"] >= 1


def test_refinement_regressions_of_the_other_backends():
    """Where SCIP once under-reported (the barrett grasp with its weight as the base load,
    tests/stability/test_solver_regressions.py) and where SCIP's presolve called a feasible
    round infeasible (barrett_cube, a torque about x, test_scip_presolve.py): Gurobi gives
    the right answers without any re-check."""
    from test_solver_regressions import BASE, COMMANDS, S_MAX, _direction, _grasp

    from ihm import load_scene
    from ihm.contacts import grasp_from_mujoco

    q = MaxDisturbance(_direction(22.5), commands=COMMANDS, cap=10.0, base=BASE)
    sol = solve_grasp(_grasp(), q, method="refinement", backend="gurobi")
    assert sol.stable and sol.stats["certified"]
    assert sol.value == pytest.approx(S_MAX, rel=1e-4)
    assert sol.max_residual() <= 1e-7
    cube = grasp_from_mujoco(*load_scene("barrett_cube", preload=[0.0, 0.1, 0.1, 0.02]))
    q = MaxDisturbance([0, 0, 0, 1.0, 0, 0], commands=[0.0, 0.1, 0.1, 0.03], cap=100)
    sol = solve_grasp(cube, q, method="refinement", backend="gurobi", time_limit=60)
    assert sol.stable and sol.value == pytest.approx(0.0314, rel=1e-2)
    # every condition, friction aligned against a slide of 170 (force units) included:
    # 1.1e-6 N, from the Jacobian round-off the model zeroes (the same with SCIP)
    assert sol.max_residual() < 1e-5
