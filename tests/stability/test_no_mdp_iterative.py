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
    assert res["slide_alignment"] > 0.1  # ... as a force too
    assert abs(sol.motion[5]) > 0  # the virtual rotation that wedges it
    # max_residual covers every condition of the model, the dropped ones included; the
    # method's own promise is max_residual(enforced=True)
    assert sol.max_residual() == max(res.values()) >= res["max_dissipation"]
    assert sol.max_residual(enforced=True) <= TOL * (1 + np.abs(sol.forces).max())
    assert sol.max_residual(["max_dissipation"]) == res["max_dissipation"]
    assert sol.max_residual("spring_law") == res["spring_law"]
    with pytest.raises(ValueError, match="unknown condition"):
        sol.max_residual(["dissipation"])
    with pytest.raises(ValueError, match="not both"):
        sol.max_residual(["equilibrium"], enforced=True)


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


def _finger_grasp(points, normals, mu, levers) -> stability.Grasp:
    """A grasp of ``examples.random_fingers``' kind: one single-joint finger per contact."""
    J = np.zeros((9, 3))
    for i, lever in enumerate(levers):
        J[3 * i : 3 * i + 3, i] = lever
    return stability.Grasp(points, normals, mu, J=J, R=np.eye(3))


# random_fingers(default_rng(100), 3), the 6th grasp with balanced commands, the commands
# scaled by U(0.5, 1.5) (an unbalanced hand)
STALL = _finger_grasp(
    [[0.041060003140630616, -0.014449969051880052, 0.02460232786732005],
     [-0.028328832481151638, -0.03736217787096891, -0.017365048660828147],
     [-0.03446571495678896, 0.009455903539013027, -0.03496713286470961]],
    [[-0.8771207121379666, 0.12781613492995939, -0.4629495566367384],
     [0.6844775285184296, 0.6766625641970934, 0.2713269009285975],
     [0.6569966953478809, -0.10592153450683145, 0.7464154143837614]],
    [0.544902954271998, 0.9176279732831323, 0.5570455845167634],
    [[0.08744334292952993, 0.011884168252161924, -0.010273690236534296],
     [0.041223482123624866, 0.02256634169723202, 0.0022178063263411673],
     [0.0530137680051235, 0.004333350861338424, 0.0031775470063598412]],
)  # fmt: skip
STALL_COMMANDS = [0.24405324561828293, 0.03431292913724439, 0.05720861954124723]
STALL_DIRECTION = [-0.37539751213102085, 0.8413813484396946, 0.38330975798793687,
                   0.05336013832214345, 0.009198022210292481, -0.035997997729474554]  # fmt: skip


def test_iterative_looks_down_the_ray_where_the_commanded_preload_stalls():
    """The commands alone leave a net wrench of 0.0102 N that the scheme cannot reduce
    within gamma: the hand follows the object at its commanded forces, so the net wrench is
    the same all along the ray and the least-motion step is 0 ("converged", unstable). The
    exact model holds the commands (the object moves by 1.8, a step of 180). It used to
    answer "solved" with value None in 0.03 s; the look down the ray finds the equilibrium."""
    q = MaxDisturbance(STALL_DIRECTION, commands=STALL_COMMANDS, cap=100.0)
    sol = solve(STALL, q, method="iterative")
    assert sol.status == "solved" and sol.stable and sol.value > 0.3  # refinement: 0.431
    assert sol.stats["far_moves"] >= 1
    assert sol.stats["preload_trace"][-1]["net"] < 1e-6
    check_residuals(sol)
    pre = solve(STALL, Existence(np.zeros(6), commands=STALL_COMMANDS), method="iterative")
    assert pre.status == "solved" and pre.stable


def test_iterative_gives_no_max_disturbance_from_an_unstable_preload():
    """Commands that the grasp cannot hold alone (exact: s = 0 unstable) while the
    disturbance along ``d`` is held up to the cap (exact 100): the scheme, which applies the
    disturbance from the commands' equilibrium, says it has no answer instead of
    "unstable" for every s (it used to: status "solved", value None)."""
    g = _finger_grasp(
        [[-0.016998040084154124, -0.003458233089067638, -0.04689463996235783],
         [0.022914635472962293, 0.012193448801664048, 0.04273452102764761],
         [0.04498009073133548, -0.01703819038148803, -0.013656189304670522]],
        [[0.38870848720981427, 0.018269513582511557, 0.9211796441761596],
         [-0.5532255444377313, -0.21359902365692346, -0.8051813175144993],
         [-0.9423056292044965, 0.3187279793614226, 0.10233560642172751]],
        [0.8091114491825875, 0.4585767045057795, 0.3562742055963973],
        [[0.0867071891787016, -0.004462334516836372, -0.028047507929626524],
         [0.08928278474656381, 0.0032910636428425894, 0.0019760046293048872],
         [0.07373846881579325, 0.013837280766331743, 0.003210903430438472]],
    )  # fmt: skip
    f = [0.06663765023430937, 0.08977494126502132, 0.14718188539265256]
    d = [0.8050488070443366, 0.4899387893322257, -0.33219516005733657, 0.035200153884361034,
         -0.009976266359620992, -0.012814050674290716]  # fmt: skip
    q = MaxDisturbance(d, commands=f, cap=100.0)
    sol = solve(g, q, method="iterative")
    assert sol.status == "not_converged" and sol.stable is None and sol.value is None
    assert "commanded preload alone is unstable" in sol.stats["message"]
    ex = solve(g, q, method="exact", time_limit=60)
    assert ex.status == "solved" and ex.stable and ex.value == pytest.approx(100.0)


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
