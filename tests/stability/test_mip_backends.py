"""The MIP layer (stability.mip): HiGHS (big-M, log SOS2), SCIP (native) and, where gurobipy is
installed, Gurobi (native; more in test_mip_gurobi.py) against each other and against an
independent brute force (every binary assignment and SOS2 segment, one LP each
through scipy.optimize.linprog), plus statuses and errors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog

from stability import MethodError, ModelError, mip
from stability.mip import MipModel, solve
from stability.mip._highs import reformulate

BACKENDS = mip.available_backends()


def brute_force(model: MipModel) -> tuple[str, float | None]:
    """Optimal objective by enumeration: binaries fixed, indicators as plain rows where active,
    SOS2 members outside the chosen segment fixed to 0; one LP each. No integer (non-binary)
    variables."""
    assert "I" not in model.kind
    n = model.n_vars
    binaries = [j for j in range(n) if model.kind[j] == "B"]
    segments = [range(max(len(s.idx) - 1, 1)) for s in model.sos2]
    best = None
    sign = -1.0 if model.maximize else 1.0
    for bits in itertools.product((0, 1), repeat=len(binaries)):
        for segs in itertools.product(*segments):
            lb, ub = np.array(model.lb), np.array(model.ub)
            lb[binaries] = ub[binaries] = bits
            for s, g in zip(model.sos2, segs, strict=True):
                if len(s.idx) > 2:
                    off = np.delete(s.idx, [g, g + 1])
                    if np.any(lb[off] > 0) or np.any(ub[off] < 0):
                        break
                    lb[off] = ub[off] = 0.0
            else:
                rows = [(r.idx, r.val, r.lo, r.hi) for r in model.rows]
                for ind in model.indicators:
                    if lb[ind.z] == ind.active:
                        lo = ind.rhs if ind.sense in (">=", "==") else -np.inf
                        hi = ind.rhs if ind.sense in ("<=", "==") else np.inf
                        rows.append((ind.idx, ind.val, lo, hi))
                A_ub, b_ub = [], []
                for idx, val, lo, hi in rows:
                    a = np.zeros(n)
                    a[idx] = val
                    if np.isfinite(hi):
                        A_ub.append(a)
                        b_ub.append(hi)
                    if np.isfinite(lo):
                        A_ub.append(-a)
                        b_ub.append(-lo)
                res = linprog(
                    sign * model.objective,
                    A_ub=np.array(A_ub) if A_ub else None,
                    b_ub=np.array(b_ub) if b_ub else None,
                    bounds=list(zip(lb, ub, strict=True)),
                    method="highs",
                )
                if res.status == 0:
                    val = sign * res.fun + model.offset
                    if best is None or sign * val < sign * best:
                        best = val
    return ("infeasible", None) if best is None else ("optimal", best)


def random_model(rng: np.random.Generator, with_sos2: bool) -> MipModel:
    m = MipModel("random")
    x = m.add_vars(int(rng.integers(2, 5)), -5.0, 5.0, name="x")
    z = m.add_vars(int(rng.integers(1, 4)), kind="B", name="z")
    for _ in range(int(rng.integers(1, 4))):
        k = rng.choice(len(x), size=2, replace=False)
        lo = rng.uniform(-6, 0)
        m.add_row(x[k], rng.normal(size=2), lo, lo + rng.uniform(0.5, 8))
    for _ in range(int(rng.integers(1, 4))):
        k = rng.choice(len(x), size=int(rng.integers(1, 3)), replace=False)
        sense = str(rng.choice(["<=", ">=", "=="]))
        m.add_indicator(int(rng.choice(z)), x[k], rng.normal(size=len(k)), sense,
                        float(rng.uniform(-3, 3)), active=int(rng.integers(0, 2)))  # fmt: skip
    idx = list(x) + list(z)
    if with_sos2:
        lam = m.add_vars(int(rng.integers(3, 7)), 0.0, rng.uniform(0.5, 2.0), name="lam")
        m.add_sos2(lam, weights=rng.permutation(len(lam)))
        m.add_constraint(np.append(lam, x[0]), np.append(rng.uniform(-2, 2, len(lam)), -1.0),
                         "==", 0.0)  # fmt: skip
        idx += list(lam)
    m.set_objective(idx, rng.normal(size=len(idx)), maximize=bool(rng.integers(0, 2)))
    return m


@pytest.mark.parametrize("with_sos2", [False, True])
def test_backends_agree_with_brute_force_on_random_models(with_sos2):
    rng = np.random.default_rng(12 + with_sos2)
    counts = {"optimal": 0, "infeasible": 0}
    for _ in range(40):
        m = random_model(rng, with_sos2)
        status, best = brute_force(m)
        counts[status] += 1
        for backend in BACKENDS:
            r = solve(m, backend)
            assert r.status == status or (
                status == "infeasible" and r.status == "infeasible_or_unbounded"
            ), (backend, r.status, r.message, m.summary())
            if status == "optimal":
                assert r.objective == pytest.approx(best, abs=1e-6), backend
                assert m.objective_value(r.x) == pytest.approx(r.objective, abs=1e-6)
                assert max(r.violations.values()) <= 1e-6
    assert counts["optimal"] >= 15 and counts["infeasible"] >= 1  # both kinds exercised


def test_scip_is_available_and_both_backends_listed():
    assert BACKENDS[:2] == ["highs", "scip"]  # pyscipopt is a dependency
    assert BACKENDS[2:] in ([], ["gurobi"])  # gurobipy is optional (test_mip_gurobi.py)


def test_piecewise_linear_minimum_through_sos2():
    """min f(x) of a nonconvex piecewise-linear f on x >= 3.5: 1.0 at x = 5 (a convex
    relaxation would give 1.5 at the left end)."""
    xs = np.arange(6.0)
    fs = np.array([3.0, 1.0, 2.0, 0.5, 2.5, 1.0])
    for backend in BACKENDS:
        m = MipModel("pwl")
        lam = m.add_vars(6, 0, 1, name="lam")
        x, f = m.add_var(0, 5, name="x"), m.add_var(-10, 10, name="f")
        m.add_constraint(lam, 1.0, "==", 1)
        m.add_constraint(np.append(lam, x), np.append(xs, -1), "==", 0)
        m.add_constraint(np.append(lam, f), np.append(fs, -1), "==", 0)
        m.add_sos2(lam)
        m.add_constraint([x], [1.0], ">=", 3.5)
        m.set_objective([f], [1.0])
        r = solve(m, backend)
        assert r.optimal and r.objective == pytest.approx(1.0, abs=1e-7)
        assert r.x[x] == pytest.approx(5.0, abs=1e-7)


def test_log_encoding_uses_log_many_binaries_and_big_m_from_bounds():
    m = MipModel("enc")
    lam = m.add_vars(9, 0.0, 2.0)  # 8 segments -> 3 binaries
    m.add_sos2(lam)
    x = m.add_var(-3.0, 7.0)
    z = m.add_var(kind="B")
    m.add_indicator(z, [x], [1.0], "<=", 1.0)  # M = 7 - 1 = 6
    m.add_indicator(z, [x], [1.0], ">=", -5.0, active=0)  # holds on [-3, 7]: no row
    flat = reformulate(m)
    assert flat.kind.count("B") == 1 + 3
    big_m = [r for r in flat.rows if r.name.startswith("ind")]
    assert len(big_m) == 1
    np.testing.assert_allclose(big_m[0].val, [1.0, 6.0])
    assert big_m[0].hi == pytest.approx(7.0)
    # every segment is reachable, and with it no third member: max sum is the pair's 3.0
    for g, backend in itertools.product(range(8), BACKENDS):
        probe = MipModel("probe")
        lam2 = probe.add_vars(9, 0.0, 2.0)
        probe.add_sos2(lam2)
        probe.add_constraint([lam2[g], lam2[g + 1]], [1.0, 1.0], "==", 3.0)
        probe.set_objective(lam2, 1.0, maximize=True)
        r = solve(probe, backend)
        assert r.optimal and r.objective == pytest.approx(3.0)
    two_apart = MipModel("apart")
    lam3 = two_apart.add_vars(9, 0.0, 2.0)
    two_apart.add_sos2(lam3)
    two_apart.add_constraint([lam3[2], lam3[4]], [1.0, 1.0], ">=", 1.5)
    two_apart.add_constraint([lam3[2]], [1.0], ">=", 0.5)
    two_apart.add_constraint([lam3[4]], [1.0], ">=", 0.5)
    for backend in BACKENDS:
        assert solve(two_apart, backend).status in ("infeasible", "infeasible_or_unbounded")


def test_forced_time_out_gives_status_timeout():
    """A market-split instance (hard for branch and bound) with a tiny time limit."""
    rng = np.random.default_rng(3)
    for backend in BACKENDS:
        m = MipModel("split")
        z = m.add_vars(40, kind="B")
        for _ in range(4):
            a = rng.integers(0, 100, size=40)
            m.add_constraint(z, a, "==", float(a.sum() // 2))
        m.set_objective(z, rng.normal(size=40))
        r = solve(m, backend, time_limit=0.05)
        assert r.status == "timeout", (backend, r.status, r.message)
        assert r.x is None or max(r.violations.values()) <= 1e-6


def test_solver_failures_and_wrong_answers_become_status_error(monkeypatch):
    m = MipModel("toy")
    x = m.add_var(0, 10)
    z = m.add_var(kind="B")
    m.add_indicator(z, [x], [1.0], ">=", 4.0)
    m.add_constraint([z], [1.0], "==", 1.0)
    m.set_objective([x], [1.0])

    def boom(*args):
        raise RuntimeError("SCIP exploded")

    monkeypatch.setattr("stability.mip._scip.solve_scip", boom)
    r = solve(m, "scip")
    assert r.status == "error" and "SCIP exploded" in r.message and r.x is None

    def wrong(*args):  # an "optimal" point that violates the indicator (x < 4 with z = 1)
        return {"status": "optimal", "x": np.array([1.0, 1.0]), "objective": 1.0,
                "bound": 1.0, "nodes": 0, "message": "", "time_s": 0.0}  # fmt: skip

    monkeypatch.setattr("stability.mip._highs.solve_highs", wrong)
    r = solve(m, "highs")
    assert r.status == "error" and "indicators" in r.message


def test_unknown_and_missing_backend(monkeypatch):
    m = MipModel()
    m.add_var(0, 1)
    with pytest.raises(MethodError, match="unknown MIP backend 'cplex'"):
        solve(m, "cplex")
    monkeypatch.setattr(mip, "available_backends", lambda: ["highs"])
    with pytest.raises(MethodError, match="pip install pyscipopt"):
        solve(m, "scip")


def test_statuses_infeasible_and_unbounded():
    m = MipModel("inf")
    x = m.add_var(0, 1)
    m.add_constraint([x], [1.0], ">=", 2.0)
    u = MipModel("unb")
    y = u.add_var(0, math.inf)
    u.add_var(kind="B")
    u.set_objective([y], [1.0], maximize=True)
    for backend in BACKENDS:
        assert solve(m, backend).status in ("infeasible", "infeasible_or_unbounded")
        assert solve(u, backend).status in ("unbounded", "infeasible_or_unbounded")


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda m: m.add_var(0, 1, kind="X"), "kind must be one of"),
        (lambda m: m.add_var(2, 1), "empty bounds"),
        (lambda m: m.add_var(math.nan, 1), "bad bounds"),
        (lambda m: m.add_row([0, 5], [1, 1], 0, 1), "out of range"),
        (lambda m: m.add_row([0], [math.inf], 0, 1), "finite"),
        (lambda m: m.add_row([0], [1.0], 2, 1), "bad sides"),
        (lambda m: m.add_constraint([0], [1.0], "<", 1), "sense must be"),
        (lambda m: m.add_indicator(0, [1], [1.0], "<=", 1.0), "must be a binary"),
        (lambda m: m.add_indicator(2, [1], [1.0], "<=", math.inf), "rhs must be finite"),
        (lambda m: m.add_indicator(2, [1], [1.0], "<=", 1.0, active=2), "active must be"),
        (lambda m: m.add_sos2([0, 0, 1]), "distinct"),
        (lambda m: m.add_sos2([0, 1, 2], weights=[1, 1, 2]), "weights must be distinct"),
        (lambda m: m.violations(np.zeros(2)), "a point has 3 entries"),
    ],
)
def test_model_errors(build, match):
    m = MipModel("bad")
    m.add_var(0, 1)
    m.add_var(-1, 1)
    m.add_var(kind="B")
    with pytest.raises(ModelError, match=match):
        build(m)


def test_big_m_needs_finite_bounds_but_scip_does_not():
    m = MipModel("free")
    x = m.add_var(-math.inf, math.inf, name="free_x")
    z = m.add_var(kind="B")
    m.add_indicator(z, [x], [1.0], "<=", 1.0)
    m.add_constraint([z], [1.0], "==", 1.0)
    m.set_objective([x], [1.0], maximize=True)
    with pytest.raises(ModelError, match="free_x"):
        solve(m, "highs")
    r = solve(m, "scip")
    assert r.optimal and r.objective == pytest.approx(1.0)
    with pytest.raises(ModelError, match="time_limit"):
        solve(m, "scip", time_limit=-1)


@pytest.mark.parametrize("log_sos2", [True, False])
def test_convex_combination_sos2_against_brute_force(monkeypatch, log_sos2):
    """SOS2 sets whose members sum to a fixed total (refinement's ``sum z = 1``: the encoding
    then uses that total as its big-U, stability.mip.model.sos2_total), on random models:
    SCIP encoded (its default) and with its own SOS2 handler, and HiGHS, all against
    enumeration of the segments."""
    import stability.mip._scip as scip_backend

    monkeypatch.setattr(scip_backend, "LOG_SOS2", log_sos2)
    rng = np.random.default_rng(31)
    optimal = 0
    for _ in range(25):
        m = MipModel("convex")
        x = m.add_vars(2, -4.0, 4.0, name="x")
        n = int(rng.integers(4, 10))
        lam = m.add_vars(n, 0.0, 1.0, name="lam")
        m.add_sos2(lam)
        m.add_constraint(lam, 1.0, "==", 1.0)  # a convex combination
        pts = rng.normal(size=(n, 2)) * 3.0
        for t in range(2):  # x = sum lam_j p_j: a point on the polyline p_0 .. p_{n-1}
            m.add_constraint(np.append(lam, x[t]), np.append(pts[:, t], -1.0), "==", 0.0)
        a = rng.normal(size=2)
        m.add_constraint(x, a, "<=", float(rng.uniform(-1.0, 2.0)))
        m.set_objective(x, rng.normal(size=2), maximize=bool(rng.integers(0, 2)))
        status, best = brute_force(m)
        optimal += status == "optimal"
        for backend in BACKENDS:
            r = solve(m, backend)
            assert r.status == status or (
                status == "infeasible" and r.status == "infeasible_or_unbounded"
            ), (backend, r.status)
            if status == "optimal":  # (HiGHS: 1e-6 off, its integrality tolerance)
                assert r.objective == pytest.approx(best, abs=1e-5), backend
    assert optimal >= 15


def test_scip_keeps_its_own_sos2_where_the_encoding_cannot_go():
    """Members with an infinite upper bound have no big-U: SCIP states that set with its SOS2
    handler (HiGHS refuses it), and the answer still keeps two adjacent members."""
    from stability.mip._scip import _log_sos2

    m = MipModel("unbounded")
    lam = m.add_vars(4, 0.0, math.inf, name="lam")
    m.add_sos2(lam)
    m.add_constraint(lam, 1.0, "<=", 5.0)
    m.set_objective(lam, [1.0, 0.0, 3.0, 2.0], maximize=True)  # best pair: members 2, 3
    enc, native = _log_sos2(m)
    assert len(native) == 1 and enc.n_vars == m.n_vars
    r = solve(m, "scip")
    assert r.optimal and r.objective == pytest.approx(15.0)
    assert np.count_nonzero(r.x[lam] > 1e-9) <= 2
    with pytest.raises(ModelError, match="finite ub"):
        solve(m, "highs")
