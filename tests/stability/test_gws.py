"""Tests of the grasp-wrench-space baseline, ``method="gws"`` (stability/gws.py)."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest
from scipy.optimize import linprog

from stability import (
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    MethodError,
    OptimalCommands,
    available_methods,
    gws,
    solve,
)

TOL = 1e-9


def thesis_grasp(mu: float = 0.5) -> Grasp:
    """The three-contact grasp of thesis ch. 4 (fig. grasp2)."""
    return Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=mu)


def antipodal(mu: float) -> Grasp:
    """Two opposing planar contacts on the x axis, pushing towards each other."""
    return Grasp(points=[[-1, 0], [1, 0]], normals=[[1, 0], [-1, 0]], mu=mu)


def random_grasp(rng: np.random.Generator, dim: int, m: int) -> Grasp:
    """Contacts on the unit circle/sphere, normals roughly towards the centre."""
    p = rng.normal(size=(m, dim))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    n = -p + 0.4 * rng.normal(size=(m, dim))
    return Grasp(points=p, normals=n, mu=rng.uniform(0.2, 1.0, size=m))


def assert_residuals(sol) -> None:
    res = sol.residuals()
    assert res["equilibrium"] <= TOL, res
    assert res["friction_cone"] <= TOL, res
    assert res["normal_sign"] <= TOL, res


# -- registration -----------------------------------------------------------------------
def test_registered_for_existence_and_max_disturbance_only():
    g = thesis_grasp()
    assert "gws" in available_methods(g, Existence(wrench=[0, 1, 0]))
    assert "gws" in available_methods(g, MaxDisturbance(direction=[0, 1, 0]))
    with pytest.raises(MethodError):
        solve(g, OptimalCommands(wrench=[0, 1, 0]), method="gws")
    with pytest.raises(MethodError):  # no hand model: commands are refused
        solve(g, Existence(wrench=[0, 1, 0], commands=[1.0]), method="gws")


# -- Existence ---------------------------------------------------------------------------
def _exact_planar_min_normal(g: Grasp, w: np.ndarray) -> float | None:
    """Independent check: least total normal force balancing ``w`` with the cone in
    H-form (|c_t| <= mu c_n), scipy's HiGHS; None when infeasible."""
    m = g.m
    A_ub = np.zeros((2 * m, 2 * m))
    for i in range(m):
        A_ub[2 * i, [2 * i, 2 * i + 1]] = [-g.mu[i], 1.0]
        A_ub[2 * i + 1, [2 * i, 2 * i + 1]] = [-g.mu[i], -1.0]
    bounds = [(0, None), (None, None)] * m
    cost = np.tile([1.0, 0.0], m)
    r = linprog(cost, A_ub, np.zeros(2 * m), g.G, -w, bounds=bounds, method="highs")
    assert r.status in (0, 2)
    return r.fun if r.status == 0 else None


def test_existence_random_planar_residuals_and_agreement():
    rng = np.random.default_rng(0)
    n_stable = n_unstable = 0
    for _ in range(40):
        g = random_grasp(rng, 2, int(rng.integers(1, 5)))
        w = rng.normal(size=3)
        sol = solve(g, Existence(wrench=w), method="gws")
        ref = _exact_planar_min_normal(g, w)
        assert sol.stable == (ref is not None)
        assert sol.stats["ignores"] == "preload, compliance, maximum dissipation"
        assert sol.motion is None and sol.states is None
        if sol.stable:
            n_stable += 1
            assert sol.forces.shape == (g.m, 2)
            assert_residuals(sol)
            assert sol.forces[:, 0].sum() == pytest.approx(ref, rel=1e-7, abs=1e-9)
        else:
            n_unstable += 1
            assert sol.forces is None
    assert n_stable >= 5 and n_unstable >= 5  # both branches exercised


def test_existence_random_spatial_residuals():
    rng = np.random.default_rng(1)
    n_stable = 0
    for _ in range(30):
        g = random_grasp(rng, 3, int(rng.integers(2, 5)))
        w = rng.normal(size=6)
        sol = solve(g, Existence(wrench=w), method="gws", edges=8)
        if sol.stable:
            n_stable += 1
            assert sol.forces.shape == (g.m, 3)
            assert_residuals(sol)  # inner pyramid: cone residual is exactly satisfiable
        else:
            assert sol.forces is None
    assert n_stable >= 5


def test_thesis_grasp_gws_says_stable_both_ways():
    """GWS calls w = (0, 1, 0) stable although, without preload, it is not.

    Balancing (0, 1, 0) needs net hand force (0, -1): only friction at contacts 1
    and 3 can supply it, c_t1 = -c_n1/2, c_t3 = +c_n3/2 with c_n1 = c_n3 (x balance),
    zero net torque (-c_t1 - c_t2 - c_t3 = 0) and -(c_n1 + c_n3)/2 = -1, so the
    least total normal force is 2. The passive model (planar method) says this
    wrench needs a preload; GWS ignores that. (0, -1, 0) is pushed straight into
    contact 2: c_n2 = 1, total normal force 1.
    """
    g = thesis_grasp()
    up = solve(g, Existence(wrench=[0, 1, 0]), method="gws")
    assert up.stable
    assert_residuals(up)
    assert up.forces[:, 0].sum() == pytest.approx(2.0, abs=1e-9)  # least normal force
    np.testing.assert_allclose(up.forces, [[1, -0.5], [0, 0], [1, 0.5]], atol=1e-9)
    down = solve(g, Existence(wrench=[0, -1, 0], preload=5.0), method="gws")
    assert down.stable
    np.testing.assert_allclose(down.forces, [[0, 0], [1, 0], [0, 0]], atol=1e-9)


def test_thesis_grasp_is_force_closure_so_every_wrench_is_balanced():
    """Contacts 1 and 3 alone are an antipodal pair with mu = 0.5 > 0 (the segment
    joining them lies inside both friction cones), a planar force-closure grasp
    (Nguyen 1988); the thesis says so too (sec. 3.2). So GWS balances any wrench."""
    g = thesis_grasp()
    assert gws.force_closure(g)
    rng = np.random.default_rng(2)
    for w in rng.normal(size=(20, 3)) * 10:
        sol = solve(g, Existence(wrench=w), method="gws")
        assert sol.stable
        assert_residuals(sol)


def test_pulling_is_unstable():
    """A single finger below the object cannot hold it against a wrench that
    lifts the object off the finger (+n): that would need c_n = -1."""
    g = Grasp(points=[[0, -1]], normals=[[0, 1]], mu=0.5)
    off = solve(g, Existence(wrench=[0, 1, 0]), method="gws")
    assert not off.stable and off.forces is None
    into = solve(g, Existence(wrench=[0, -1, 0]), method="gws")
    assert into.stable
    np.testing.assert_allclose(into.forces, [[1, 0]], atol=1e-12)
    gs = Grasp(points=[[0, 0, -1]], normals=[[0, 0, 1]], mu=0.5)
    assert not solve(gs, Existence(wrench=[0, 0, 1, 0, 0, 0]), method="gws").stable
    assert solve(gs, Existence(wrench=[0, 0, -1, 0, 0, 0]), method="gws").stable


def test_pyramid_is_inner_approximation_deterministic():
    """One contact at the origin, n = z, t1 = x, t2 = y, mu = 1. The hand must
    supply frame force (1, a, b) with |(a, b)| = 0.95 at 45 degrees. The 4-edge
    pyramid (edges on the t axes) has inscribed radius mu cos(pi/4) ~ 0.707 < 0.95
    along 45 degrees; the 32-edge one reaches cos(pi/32) ~ 0.995 > 0.95."""
    g = Grasp(points=[[0, 0, 0]], normals=[[0, 0, 1]], mu=1.0, tangents=[[1, 0, 0]])
    a = b = 0.95 / np.sqrt(2)
    w = -np.array([a, b, 1, 0, 0, 0])
    assert not solve(g, Existence(wrench=w), method="gws", edges=4).stable
    sol = solve(g, Existence(wrench=w), method="gws", edges=32)
    assert sol.stable
    assert_residuals(sol)
    assert sol.stats["edges"] == 32 and not sol.stats["exact_cone"]


def test_spatial_edges_monotone_random():
    """Inner approximation: stable with 4 edges => stable with 32 edges."""
    rng = np.random.default_rng(3)
    s4 = s32 = 0
    for _ in range(60):
        g = random_grasp(rng, 3, int(rng.integers(2, 4)))
        w = rng.normal(size=6)
        st4 = solve(g, Existence(wrench=w), method="gws", edges=4).stable
        st32 = solve(g, Existence(wrench=w), method="gws", edges=32).stable
        assert st32 or not st4
        s4 += st4
        s32 += st32
    assert s4 >= 3 and s32 > s4  # the test is not vacuous: 32 edges admit more


# -- Ferrari-Canny / force closure --------------------------------------------------------
@pytest.mark.parametrize("mu,ts", [(0.5, 1.0), (0.5, 2.0), (1.0, 1.0), (0.2, 0.5)])
def test_ferrari_canny_antipodal_analytic(mu, ts):
    """Two opposing contacts at (-1, 0), (1, 0), normals +-x. With k = mu / ts the
    primitive wrenches (fx, fy, tz / ts) are the tetrahedron
        v1 = (1, mu, -k), v2 = (1, -mu, k), v3 = (-1, -mu, -k), v4 = (-1, mu, k)
    (torque p_x f_y - p_y f_x). The face v2 v3 v4 has normal
        (v3 - v2) x (v4 - v2) = (-2, 0, -2k) x (-2, 2mu, 0) = 4 (k mu, k, -mu),
    and v2 . (k mu, k, -mu) = -mu k, so its distance from the origin is
        mu k / sqrt(k^2 mu^2 + k^2 + mu^2).
    The maps (x, y, z) -> (x, -y, -z) and (-x, -y, z) permute the vertices
    transitively, so all four faces are at that distance: eps. For mu = 0.5,
    ts = 1 it is 0.5 / sqrt(2.25) = 1/3."""
    k = mu / ts
    expected = mu * k / np.sqrt(k**2 * mu**2 + k**2 + mu**2)
    assert gws.ferrari_canny(antipodal(mu), torque_scale=ts) == pytest.approx(expected, rel=1e-9)
    if mu == 0.5 and ts == 1.0:
        assert expected == pytest.approx(1 / 3)


def test_primitive_wrenches_antipodal():
    W = gws.primitive_wrenches(antipodal(0.5))
    np.testing.assert_allclose(
        W, [[1, 0.5, -0.5], [1, -0.5, 0.5], [-1, -0.5, -0.5], [-1, 0.5, 0.5]], atol=1e-15
    )
    gs = random_grasp(np.random.default_rng(4), 3, 3)
    assert gws.primitive_wrenches(gs, edges=5).shape == (15, 6)


def test_force_closure_true_and_false():
    # frictionless antipodal pair: a segment of wrenches, no torque or fy: not closure
    assert gws.ferrari_canny(antipodal(0.0)) == 0.0
    assert not gws.force_closure(antipodal(0.0))
    # single contact: origin is a vertex of the cone, never inside
    assert not gws.force_closure(Grasp(points=[[0, -1]], normals=[[0, 1]], mu=1.0))
    # full-dimensional hull not containing the origin: every finger pushes +y
    g_up = Grasp(points=[[-1, 0], [0, 0], [1, 0]], normals=[[0, 1]] * 3, mu=0.5)
    assert gws.ferrari_canny(g_up) == 0.0
    # spatial: an antipodal pair cannot resist torque about its own axis
    g2 = Grasp(points=[[-1, 0, 0], [1, 0, 0]], normals=[[1, 0, 0], [-1, 0, 0]], mu=0.5)
    assert not gws.force_closure(g2)
    # spatial: three hard fingers at 120 degrees on the equator, mu = 0.5
    ang = 2 * np.pi * np.arange(3) / 3
    p = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    g3 = Grasp(points=p, normals=-p, mu=0.5)
    assert gws.force_closure(g3)
    assert gws.force_closure(g3, edges=4)


# -- MaxDisturbance (L1 GWS) ---------------------------------------------------------------
def test_max_disturbance_antipodal_hand_derived():
    """Antipodal pair, mu = 0.5, sum c_n <= 1 (with c_n1 = c_n3 by x balance except
    in x). d = (-1, 0, 0): contact 1 pushes +x with all the normal force: s = 1.
    d = (0, -1, 0): y balance c_t1 - c_t3 = s, torque -c_t1 - c_t3 = 0, so s =
    2 c_t1 <= 2 mu c_n1 = mu (c_n1 = 1/2): s = 0.5. d = (0, 0, 1) likewise 0.5."""
    g = antipodal(0.5)
    for d, expected in [((-1, 0, 0), 1.0), ((0, -1, 0), 0.5), ((0, 0, 1), 0.5)]:
        sol = solve(g, MaxDisturbance(direction=d), method="gws")
        assert sol.stable and sol.value == pytest.approx(expected, abs=1e-9)
        assert not sol.stats["capped"]
        assert_residuals(sol)
        assert sol.forces[:, 0].sum() <= 1 + 1e-9
    # scaling the direction scales the value inversely
    sol2 = solve(g, MaxDisturbance(direction=(0, -2, 0)), method="gws")
    assert sol2.value == pytest.approx(0.25, abs=1e-9)


def test_max_disturbance_frictionless_pair():
    """mu = 0: only normal forces. Along x s = 1 (one finger, c_n = 1); along y
    nothing resists, s = 0, which GWS still calls stable (c = 0 at s = 0)."""
    g = antipodal(0.0)
    x = solve(g, MaxDisturbance(direction=(-1, 0, 0)), method="gws")
    assert x.value == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(x.forces, [[1, 0], [0, 0]], atol=1e-9)
    y = solve(g, MaxDisturbance(direction=(0, 1, 0)), method="gws")
    assert y.stable and y.value == pytest.approx(0.0, abs=1e-12)
    assert_residuals(y)


def test_max_disturbance_cap():
    g = antipodal(0.5)
    sol = solve(g, MaxDisturbance(direction=(-1, 0, 0), cap=0.1), method="gws")
    assert sol.value == pytest.approx(0.1) and sol.stats["capped"]
    assert_residuals(sol)


def test_max_disturbance_matches_ferrari_canny():
    """For unit d the L1-GWS value is the distance from the origin to the hull
    boundary along -d, so it is >= eps for every d, and = eps along the normal
    of the hull facet nearest the origin."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(20):
        g = random_grasp(rng, 2, int(rng.integers(2, 5)))
        eps = gws.ferrari_canny(g)
        if eps <= 1e-6:
            continue
        checked += 1
        eq = ConvexHull(gws.primitive_wrenches(g)).equations
        a = eq[np.argmin(-eq[:, -1]), :-1]
        near = solve(g, MaxDisturbance(direction=-a), method="gws")
        assert near.value == pytest.approx(eps, rel=1e-7)
        for u in rng.normal(size=(10, 3)):
            u /= np.linalg.norm(u)
            assert solve(g, MaxDisturbance(direction=u), method="gws").value >= eps - 1e-9
    assert checked >= 3


def _cvxpy_max_disturbance(g: Grasp, d: np.ndarray, edges: int) -> float:
    """Reference: the same LP in cvxpy with explicit forces and cones in H-form.

    Planar: |c_t| <= mu c_n. Spatial: the inscribed pyramid's facets,
    cos(phi_j) c_t1 + sin(phi_j) c_t2 <= mu cos(pi/N) c_n, phi_j = (2j + 1) pi / N.
    """
    k = g.dim
    c = cp.Variable(k * g.m)
    s = cp.Variable()
    cons = [g.G @ c + s * d == 0, s >= 0, s <= 1e3]
    cn = c[0::k]
    cons += [cn >= 0, cp.sum(cn) <= 1]
    if k == 2:
        cons += [cp.abs(c[1::k]) <= cp.multiply(g.mu, cn)]
    else:
        phi = (2 * np.arange(edges) + 1) * np.pi / edges
        for j in range(edges):
            lhs = np.cos(phi[j]) * c[1::k] + np.sin(phi[j]) * c[2::k]
            cons.append(lhs <= np.cos(np.pi / edges) * cp.multiply(g.mu, cn))
    cp.Problem(cp.Maximize(s), cons).solve(solver=cp.CLARABEL)
    return float(s.value)


@pytest.mark.parametrize("dim", [2, 3])
def test_max_disturbance_matches_cvxpy_reference(dim):
    rng = np.random.default_rng(6 + dim)
    edges = 6
    for _ in range(6):
        g = random_grasp(rng, dim, int(rng.integers(2, 5)))
        d = rng.normal(size=3 if dim == 2 else 6)
        sol = solve(g, MaxDisturbance(direction=d), method="gws", edges=edges)
        ref = _cvxpy_max_disturbance(g, d, edges)
        assert sol.value == pytest.approx(ref, abs=1e-6)
        assert_residuals(sol)


# -- bad input ------------------------------------------------------------------------------
def test_bad_input_raises_grasp_error():
    g = thesis_grasp()
    gs = random_grasp(np.random.default_rng(7), 3, 3)
    for edges in (2, 0, -1, 2.5, True, "8"):
        with pytest.raises(GraspError):
            solve(gs, Existence(wrench=np.zeros(6)), method="gws", edges=edges)
    with pytest.raises(GraspError):
        gws.primitive_wrenches(gs, edges=2)
    with pytest.raises(GraspError):
        gws.ferrari_canny(g, torque_scale=0.0)
    with pytest.raises(GraspError):
        gws.ferrari_canny(g, torque_scale=np.nan)
    with pytest.raises(GraspError):
        solve(g, MaxDisturbance(direction=[0, 0, 0]), method="gws")
    with pytest.raises(GraspError):
        solve(g, MaxDisturbance(direction=[1, 0]), method="gws")
    with pytest.raises(GraspError):
        solve(g, MaxDisturbance(direction=[1, 0, np.inf]), method="gws")
    with pytest.raises(GraspError):
        solve(g, MaxDisturbance(direction=[1, 0, 0], cap=-1.0), method="gws")
    with pytest.raises(GraspError):
        solve(g, Existence(wrench=[0, 1, 0, 0, 0, 0]), method="gws")
    with pytest.raises(GraspError):
        solve(gs, Existence(wrench=[0, 1, 0]), method="gws")
    with pytest.raises(GraspError):
        solve(g, Existence(wrench=[0, 1, np.nan]), method="gws")
    with pytest.raises(GraspError):
        solve(g, Existence(wrench=[0, 1, 0], preload=-1.0), method="gws")
