"""The 3D MIP methods (thesis ch. 5): ``no_mdp`` and ``iterative`` on hand-built grasps with
known answers, where ``no_mdp`` is wrong, against ``planar``, and on a MuJoCo scene."""

from __future__ import annotations

import numpy as np
import problems as P
import pytest

import stability
from stability import Existence, GraspError, MaxDisturbance, MethodError, solve
from stability import mip as smip

BACKENDS = ("highs", "scip")
METHODS = ("no_mdp", "iterative")
TOL = 1e-6  # residuals of the exact conditions
NET_TOL = 1e-3  # the iterative scheme's threshold on the net wrench, relative to the load


def check_residuals(sol) -> dict[str, float]:
    """Every enforced condition holds (iterative: equilibrium up to its net_tol)."""
    res = sol.residuals()
    for key in sol.conditions:
        if key not in res:
            continue
        scale = sol.stats["force_scale"]
        limit = NET_TOL * scale if (sol.method == "iterative" and key == "equilibrium") else TOL
        assert res[key] <= limit * (1 + np.abs(sol.forces).max()), (sol.method, key, res)
    return res


# ---------------------------------------------------------------------------------- pinch


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_pinch_max_force_along_z_is_analytic(method, backend):
    """2 mu tau / lever = 2.22 N: both fingers push with 1.11 N and friction holds mu times
    that; the iterative bisection lands within 5 % (we ask 0.1 %)."""
    q = MaxDisturbance(direction=(0, 0, 1, 0, 0, 0), commands=[P.PINCH_TORQUE] * 2, cap=100.0)
    sol = solve(P.pinch(), q, method=method, backend=backend)
    assert sol.status == "solved" and sol.stable
    rtol = 1e-6 if method == "no_mdp" else 2e-3
    assert sol.value == pytest.approx(P.PINCH_MAX_Z, rel=rtol)
    if method == "iterative":  # stable means a net wrench below net_tol of the load
        assert sol.value <= P.PINCH_MAX_Z * (1 + 2 * NET_TOL)
    assert not sol.stats["capped"]
    check_residuals(sol)
    # both fingers are still closing: f = f_c, and the contacts carry tau / lever each
    np.testing.assert_allclose(sol.actuator_forces, P.PINCH_TORQUE, rtol=1e-6)
    np.testing.assert_allclose(sol.forces[:, 0], P.PINCH_TORQUE / P.PINCH_LEVER, rtol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_pinch_without_commands_drops_a_lifted_box(method, backend):
    sol = solve(P.pinch(), Existence(wrench=(0, 0, 1, 0, 0, 0)), method=method, backend=backend)
    assert sol.status == "solved" and sol.stable is False and sol.forces is None
    with_cmd = Existence(wrench=(0, 0, 1, 0, 0, 0), commands=[P.PINCH_TORQUE] * 2)
    assert solve(P.pinch(), with_cmd, method=method, backend=backend).stable


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_pinch_passive_reaction_holds_a_push_into_a_finger(method, backend):
    """Pushing the box into finger 1 (at -x) is resisted up to the cap with no commands:
    the nonbackdrivable joint locks and its torque rises passively to lever * force."""
    cap = 50.0
    q = MaxDisturbance(direction=(-1, 0, 0, 0, 0, 0), cap=cap)
    sol = solve(P.pinch(), q, method=method, backend=backend)
    assert sol.stable and sol.value == pytest.approx(cap) and sol.stats["capped"]
    check_residuals(sol)
    assert sol.forces[1, 0] == pytest.approx(cap, rel=1e-6)
    assert sol.actuator_forces[1] == pytest.approx(P.PINCH_LEVER * cap, rel=1e-6)
    assert abs(sol.hand_motion[1]) <= 1e-9  # locked where it stood
    # the other finger has nothing to push: without a command it is not loaded
    assert sol.forces[0, 0] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("cap", [2e3, 1e6])
def test_backends_agree_at_large_caps(cap):
    """Large caps mean large model bounds: SCIP's presolve once answered 0 here."""
    q = MaxDisturbance(direction=(-1, 0, 0, 0, 0, 0), cap=cap)
    for backend in BACKENDS:
        sol = solve(P.pinch(), q, method="no_mdp", backend=backend)
        assert sol.stats["capped"] and sol.value == pytest.approx(cap, rel=1e-8), backend
        check_residuals(sol)


def test_no_mdp_raises_a_bound_that_decided():
    """A V of walls tilted 0.003 rad, mu = 0: holding 1 N down needs 1 / (2 sin 0.003) =
    167 N per wall, above the first force bound (100 x the load); no_mdp retries with a
    100x larger bound instead of answering "unstable" because of its own bound."""
    a = 0.003
    g = stability.Grasp([[-1, 0], [1, 0]], [[np.cos(a), np.sin(a)], [-np.cos(a), np.sin(a)]], 0.0)
    assert solve(g, Existence(wrench=(0, -1, 0))).stable  # planar, exact
    sol = solve(g, Existence(wrench=(0, -1, 0)), method="no_mdp")
    assert sol.stable and sol.stats["retried_bound_factor"] == 1e4
    np.testing.assert_allclose(sol.forces[:, 0], 1 / (2 * np.sin(a)), rtol=1e-6)


# ---------------------------------------------------------------------------------- wedge


@pytest.mark.parametrize("backend", BACKENDS)
def test_wedge_no_mdp_creates_energy(backend):
    """no_mdp holds a force along the walls up to the cap with no preload: the object turns,
    both springs compress, friction "holds" it. The applied force does no work on that
    motion while the springs store energy: the answer violates conservation of energy, and
    its maximum-dissipation residual shows it."""
    cap = 20.0
    g = P.wedge()
    sol = solve(g, MaxDisturbance(direction=P.WEDGE_FORCE_DIR, cap=cap), method="no_mdp",
                backend=backend)  # fmt: skip
    assert sol.stable and sol.value == pytest.approx(cap) and sol.stats["capped"]
    res = check_residuals(sol)
    work = float(sol.wrench @ sol.motion)  # by the applied force on the virtual motion
    stored = 0.5 * float(np.sum(sol.forces[:, 0] ** 2))  # unit springs, no preload
    assert stored > 1.0 and work <= 1e-9 * stored
    assert res["max_dissipation"] > 1.0  # friction does not oppose the sliding
    assert abs(sol.motion[5]) > 0  # the virtual rotation that wedges it


@pytest.mark.parametrize("backend", BACKENDS)
def test_wedge_iterative_and_planar_say_unstable(backend):
    g3, g2 = P.wedge(), P.wedge(planar=True)
    w = np.array(P.WEDGE_FORCE_DIR, dtype=float)
    it = solve(g3, Existence(wrench=w), method="iterative", backend=backend)
    assert it.status == "solved" and it.stable is False
    md = solve(g3, MaxDisturbance(direction=w, cap=20.0), method="iterative", backend=backend)
    assert md.stable and md.value == 0.0  # only s = 0 holds: no force along the walls
    assert solve(g2, Existence(wrench=(0, 1, 0)), method="planar").stable is False
    assert solve(g2, MaxDisturbance(direction=(0, 1, 0), cap=20.0), method="planar").value == 0
    # the same no_mdp wrong answer on the planar grasp
    assert solve(g2, Existence(wrench=(0, 1, 0)), method="no_mdp", backend=backend).stable


# ------------------------------------------------------------------------- underactuation

TENDON_WRENCHES = [
    (0, 0, 0, 0, 0, 0),
    (-0.5, 0, 0, 0, 0, 0),  # pulled away from the finger
    (0, 0.5, 0, 0, 0, 0),
    (1, 0, 0, 0, 0, 0),  # pushed into the finger
    (3, 0, 0, 0, 0, 0),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_underactuated_tendon_finger(method, backend):
    """R is 2 x 1: J^T c = R f, f >= f_c, f = f_c where the transmission moves, and a push
    into the finger locks the tendon with f > f_c."""
    g = P.tendon_finger()
    fc = P.TENDON_FORCE
    moving = locked = 0
    for w in TENDON_WRENCHES:
        sol = solve(g, Existence(wrench=w, commands=[fc]), method=method, backend=backend)
        assert sol.status == "solved" and sol.stable, (w, sol.stats)
        res = check_residuals(sol)
        assert res["hand_equilibrium"] <= 1e-9
        f = sol.actuator_forces[0]
        q = sol.hand_motion
        if sol.hand_reference is not None:
            q = q - sol.hand_reference
        v = float(g.R[:, 0] @ q)  # transmission motion
        tau = g.J.T @ sol.forces.reshape(-1)
        np.testing.assert_allclose(tau, g.R[:, 0] * f, atol=1e-9)
        assert f >= fc - 1e-9 and v >= -1e-9
        if v > 1e-6:
            assert f == pytest.approx(fc, abs=1e-9)
            moving += 1
        if f > fc + 1e-6:
            assert abs(v) <= 1e-9
            locked += 1
    assert locked >= 1  # (3, 0, ...) overpowers the tendon
    if method == "iterative":
        assert moving >= 1  # the commanded preload closed the finger


# ------------------------------------------------------------------ consistency with planar


@pytest.mark.parametrize(("w", "pre", "stable"), P.THREE_TABLE)
@pytest.mark.parametrize("method", METHODS)
def test_thesis_planar_table_embedded_in_3d(w, pre, stable, method):
    g3 = P.three_embedded()
    assert solve(P.three_planar(), Existence(wrench=w, preload=pre)).stable is stable
    for backend in BACKENDS:
        q = Existence(wrench=P.embed_wrench(w), preload=pre)
        sol = solve(g3, q, method=method, backend=backend)
        assert sol.status == "solved" and sol.stable is stable, (backend, sol.stats)
        if stable:
            check_residuals(sol)
    # the methods also take the planar grasp itself
    sol2 = solve(P.three_planar(), Existence(wrench=w, preload=pre), method=method)
    assert sol2.stable is stable


def test_barrett_box_through_grasp_from_mujoco():
    """A MuJoCo scene answers: the settled grasp holds its own weight with its commands, by
    both methods and both backends, and the answers carry their certificates."""
    ihm = pytest.importorskip("ihm")
    from ihm.contacts import grasp_from_mujoco

    model, data = ihm.load_scene("barrett_box")
    g = grasp_from_mujoco(model, data)
    assert g.J is not None and not g.planar
    q = Existence(wrench=g.gravity_wrench, commands=g.commands)
    for method in METHODS:
        for backend in BACKENDS:
            sol = solve(g, q, method=method, backend=backend)
            assert sol.status == "solved" and sol.stable, (method, backend, sol.stats)
            check_residuals(sol)
    # the weight pushes the box into the fingers (normals have +y parts, gravity is -y):
    # held passively with no commands; pulled the other way it needs the commands
    down = Existence(wrench=2 * g.gravity_wrench)
    assert solve(g, down, method="iterative").stable
    up = -2 * g.gravity_wrench
    assert solve(g, Existence(wrench=up, commands=g.commands), method="iterative").stable
    assert not solve(g, Existence(wrench=up), method="iterative").stable


# -------------------------------------------------------------- backends, errors, statuses


def test_backends_agree_on_random_existence_queries():
    """>= 50 random small grasps (3-6 single-joint fingers), random commands and wrenches:
    SCIP (native indicators) and HiGHS (big-M) give the same stable/unstable answers, and
    every stable answer satisfies the model."""
    rng = np.random.default_rng(7)
    n = agree = stable = 0
    for _ in range(60):
        m = int(rng.integers(3, 7))
        g = P.random_fingers(rng, m)
        q = Existence(wrench=P.random_wrench(rng), commands=rng.uniform(0, 0.1, m))
        a = solve(g, q, method="no_mdp", backend="highs")
        b = solve(g, q, method="no_mdp", backend="scip")
        assert a.status == b.status == "solved"
        n += 1
        agree += a.stable == b.stable
        stable += a.stable
        for s in (a, b):
            if s.stable:
                check_residuals(s)
    assert agree == n
    assert 5 <= stable <= n - 5  # the sample has both answers


def test_backends_agree_on_iterative_queries():
    rng = np.random.default_rng(11)
    for _ in range(8):
        m = int(rng.integers(3, 5))
        g = P.random_fingers(rng, m)
        q = Existence(wrench=P.random_wrench(rng), commands=rng.uniform(0.02, 0.1, m))
        a = solve(g, q, method="iterative", backend="highs")
        b = solve(g, q, method="iterative", backend="scip")
        assert a.status == b.status == "solved"
        assert a.stable == b.stable
        for s in (a, b):
            if s.stable:
                check_residuals(s)


def test_forced_timeout_is_a_status():
    for method in METHODS:
        q = MaxDisturbance(direction=(0, 0, 1, 0, 0, 0), commands=[0.1, 0.1])
        sol = solve(P.pinch(), q, method=method, time_limit=0.0)
        assert sol.status == "timeout" and sol.stable is None and sol.forces is None
        assert "time_limit" in sol.stats["message"]


def test_iteration_cap_is_a_status_not_a_guess():
    """Pushed into a finger with small steps, the pinch needs ~60 steps to load its spring."""
    q = Existence(wrench=(-3, 0, 0, 0, 0, 0))
    full = solve(P.pinch(), q, method="iterative", gamma=0.2)
    assert full.status == "solved" and full.stable and full.stats["iterations"] > 20
    nets = [t["net"] for t in full.stats["trace"]]
    assert all(b <= a + 1e-12 for a, b in zip(nets, nets[1:], strict=False))  # descends
    capped = solve(P.pinch(), q, method="iterative", gamma=0.2, max_iter=10)
    assert capped.status == "not_converged" and capped.stable is None


def test_bad_input_gets_clear_errors():
    g = P.pinch()
    q = Existence(wrench=np.zeros(6), commands=[0.1, 0.1])
    with pytest.raises(GraspError, match="commands must have shape"):
        solve(g, Existence(wrench=np.zeros(6), commands=[0.1, 0.1, 0.1]), method="no_mdp")
    with pytest.raises(GraspError, match="NaN"):
        solve(g, Existence(wrench=np.zeros(6), commands=[np.nan, 0.1]), method="iterative")
    with pytest.raises(GraspError, match="without a hand"):
        solve(P.wedge(), Existence(wrench=np.zeros(6), commands=[1.0]), method="no_mdp")
    with pytest.raises(GraspError, match="unknown MIP backend"):
        solve(g, q, method="no_mdp", backend="cplex")
    with pytest.raises(GraspError, match="unknown option"):
        solve(g, q, method="no_mdp", gama=1.0)
    with pytest.raises(GraspError, match="gamma"):
        solve(g, q, method="iterative", gamma=-1.0)
    with pytest.raises(GraspError, match="edges"):
        solve(g, q, method="no_mdp", edges=2)
    with pytest.raises(GraspError, match="shape"):
        solve(g, Existence(wrench=np.zeros(3)), method="iterative")


def test_missing_backend_names_the_package(monkeypatch):
    monkeypatch.setattr(smip, "available_backends", lambda: ["highs"])
    with pytest.raises(MethodError, match="pyscipopt"):
        solve(P.pinch(), Existence(wrench=np.zeros(6)), method="no_mdp", backend="scip")


def test_methods_are_registered_for_hands():
    g = P.pinch()
    q = Existence(wrench=np.zeros(6), commands=[0.1, 0.1])
    able = stability.available_methods(g, q)
    assert {"no_mdp", "iterative"} <= set(able)
