"""The planar solver (thesis ch. 4): the thesis' table, state counts, exactness."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest

from stability import Existence, Grasp, MaxDisturbance, solve
from stability import planar as pl

# The thesis' 3-contact grasp (Fig. grasp2): two walls and a floor, mu = 0.5.
THREE = Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)

# thesis Table tab:three_contact: (w, P, stable, c1, c2, c3)
TABLE = [
    ((0, 0, 0), 0, True, (0, 0), (0, 0), (0, 0)),
    ((0, 0, 0), 1, True, (1, -0.5), (1, 0), (1, 0.5)),
    ((0, -1, 0), 0, True, (0, 0), (1, 0), (0, 0)),
    ((0, -2, 0), 0, True, (0, 0), (2, 0), (0, 0)),
    ((0, 1, 0), 0, False, None, None, None),
    ((0, 1, 0), 1, True, (1, -0.5), (0, 0), (1, 0.5)),
    ((0, 1.1, 0), 1, False, None, None, None),
]


def random_grasp(rng: np.random.Generator, m: int) -> Grasp:
    pts = rng.uniform(-1, 1, (m, 2))
    ang = rng.uniform(0, 2 * np.pi, m)
    return Grasp(pts, np.stack([np.cos(ang), np.sin(ang)], axis=1), rng.uniform(0.2, 1.0, m))


@pytest.mark.parametrize(("w", "P", "stable", "c1", "c2", "c3"), TABLE)
def test_thesis_table(w, P, stable, c1, c2, c3):
    sol = solve(THREE, Existence(wrench=w, preload=P), method="planar")
    assert sol.stable is stable
    if not stable:
        assert sol.forces is None
        return
    np.testing.assert_allclose(sol.forces, [c1, c2, c3], atol=1e-6)
    # motions are not unique: the returned one must satisfy the model
    res = sol.residuals()
    assert set(res) == {
        "equilibrium",
        "normal_sign",
        "friction_cone",
        "spring_law",
        "max_dissipation",
        "slide_alignment",
    }
    assert max(res.values()) <= 1e-9, res


def test_thesis_max_disturbance():
    up = solve(THREE, MaxDisturbance(direction=(0, 1, 0), preload=1.0), method="planar")
    assert up.value == pytest.approx(1.0, abs=1e-9)
    assert not up.stats["capped"]
    assert up.max_residual() <= 1e-9
    np.testing.assert_allclose(up.forces, [(1, -0.5), (0, 0), (1, 0.5)], atol=1e-9)
    none = solve(THREE, MaxDisturbance(direction=(0, 1, 0), preload=0.0), method="planar")
    assert none.value == pytest.approx(0.0, abs=1e-12)
    for P in (0.0, 1.0):
        down = solve(THREE, MaxDisturbance(direction=(0, -1, 0), preload=P, cap=50.0))
        assert down.value == 50.0 and down.stats["capped"]
        assert down.max_residual() <= 1e-9
        # pushed down, the walls slip and carry mu * P each; the floor carries the rest
        np.testing.assert_allclose(down.forces, [(P, 0.5 * P), (50 - P, 0), (P, -0.5 * P)])


def test_max_disturbance_is_the_existence_boundary():
    """Existence flips exactly at MaxDisturbance.value on random grasps (exact LP answer)."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(150):
        g = random_grasp(rng, int(rng.integers(2, 6)))
        d = rng.normal(size=3)
        p = rng.uniform(0, 2)
        sol = solve(g, MaxDisturbance(direction=d, preload=p, cap=100.0))
        if not sol.stable or sol.stats["capped"] or sol.value < 1e-6:
            continue
        assert sol.max_residual() <= 1e-7
        assert solve(g, Existence(wrench=sol.value * d, preload=p)).stable
        beyond = sol.value * (1 + 1e-5) + 1e-6
        assert not solve(g, Existence(wrench=beyond * d, preload=p)).stable
        checked += 1
    assert checked >= 20


@pytest.mark.parametrize("m", range(2, 10))
def test_slip_state_count_matches_thesis(m):
    """#faces = 4m^2 - 4m + 2 (thesis: 10, 26, 50, ..., 290), plus the origin."""
    rng = np.random.default_rng(m)
    g = random_grasp(rng, m)
    counts = pl.count_slip_faces(g)
    assert counts["total"] == 4 * m * m - 4 * m + 2
    assert counts["regions"] == m * (m - 1) + 2
    assert counts["facets"] == 2 * m * (m - 1)
    S = pl.slip_states(g)
    assert not S[0].any()  # the all-rolling state comes first
    assert len(np.unique(S, axis=0)) == len(S)
    # distinct states: every face has its own sign vector, except that for m = 2 both rays
    # of the one line where both contacts roll share the all-rolling vector with the origin
    expected = 4 * m * m - 4 * m + 3 if m > 2 else 9
    assert len(S) == expected


@pytest.mark.parametrize("m", range(2, 8))
def test_slip_states_match_thesis_algorithm(m):
    """Sphere enumeration == the thesis' LP + dual polyhedron + minimum cycle basis."""
    g = random_grasp(np.random.default_rng(100 + m), m)
    ours = {s.tobytes() for s in pl.slip_states(g)}
    thesis = {s.tobytes() for s in pl.slip_states_thesis(g)}
    assert ours == thesis


def test_slip_states_cover_sampled_motions():
    """Every sign pattern of T r for random motions r is one of the enumerated states."""
    rng = np.random.default_rng(3)
    for m in (3, 5, 8):
        g = random_grasp(rng, m)
        T, _ = pl.motion_planes(g)
        S = {s.tobytes() for s in pl.slip_states(g)}
        r = rng.normal(size=(20000, 3))
        sampled = {s.tobytes() for s in np.sign(r @ T.T).astype(np.int8)}
        assert sampled <= S
        assert len(sampled) == m * (m - 1) + 2  # every region is hit at this sample size
        # lines: motion along T_i x T_j rolls at i and j
        for i, j in [(0, 1), (1, 2)]:
            v = np.cross(T[i], T[j])
            for sgn in (1, -1):
                s = np.sign(np.round(sgn * v @ T.T, 12)).astype(np.int8)
                assert s.tobytes() in S


@pytest.mark.parametrize("m", [3, 5, 8])
def test_detachment_state_count(m):
    rng = np.random.default_rng(10 + m)
    g = random_grasp(rng, m)
    # preloaded: generic affine arrangement, sum_{k<=3} C(m, k) regions
    U = pl.detachment_states(g, preload=rng.uniform(0.5, 1.5, m))
    assert len(U) == sum(comb(m, k) for k in range(4))
    # without preload the planes pass through the origin: m(m-1) + 2 regions
    assert len(pl.detachment_states(g, preload=0.0)) == m * (m - 1) + 2


def test_contact_states_cover_sampled_motions():
    """Joint (slip, detach) states of random motions are all enumerated, and the
    joint enumeration is far smaller than the product of the two sets."""
    rng = np.random.default_rng(11)
    g = random_grasp(rng, 6)
    p = rng.uniform(0.2, 1.0, 6)
    S, U = pl.contact_states(g, preload=p)
    have = {np.concatenate([s, u]).tobytes() for s, u in zip(S, U, strict=True)}
    T, N = pl.motion_planes(g)
    r = rng.normal(size=(50000, 3)) * rng.uniform(0.1, 5, (50000, 1))
    s = np.sign(r @ T.T).astype(np.int8)
    u = (r @ N.T - p <= 0).astype(np.int8)
    sampled = {np.concatenate([a, b]).tobytes() for a, b in zip(s, u, strict=True)}
    assert sampled <= have
    assert len(S) < len(pl.slip_states(g)) * len(pl.detachment_states(g, p))


def test_gws_wrong_where_planar_is_right():
    """Force closure says the unloaded grasp resists lifting; passively it does not."""
    w = (0, 1, 0)
    assert solve(THREE, Existence(wrench=w), method="gws").stable
    assert not solve(THREE, Existence(wrench=w), method="planar").stable
    # with preload 1 both agree, and the planar forces are the thesis' ones
    assert solve(THREE, Existence(wrench=w, preload=1.0), method="planar").stable


def test_large_m_solutions_satisfy_model():
    rng = np.random.default_rng(5)
    g = random_grasp(rng, 20)
    for _ in range(3):
        sol = solve(g, Existence(wrench=rng.normal(size=3) * 3, preload=1.0))
        if sol.stable:
            assert sol.max_residual() <= 1e-7


# Regression cases from review: singular state systems whose round-off "solved" them
# (false stable with huge motions), and grasps whose answer changed with their units.
SINGULAR = [
    ([[1, 1], [0, 1]], [[1, -1], [0, -1]], 0.0, [0, 0, -1], [0, 0]),
    ([[-1, -1], [0, -1], [0, -1]], [[1, 1], [-1, 0], [0, 1]], 0.3, [-1, -1, -1], 0.0),
    ([[1, -1], [1, -2], [-2, 2]], [[-1, -1], [1, -1], [1, -1]], 1.0, [2, -1, 0], [0, 0, 1]),
]


@pytest.mark.parametrize(("pts", "nrm", "mu", "w", "pre"), SINGULAR)
def test_singular_systems_are_not_solutions(pts, nrm, mu, w, pre):
    g = Grasp(pts, nrm, mu)
    assert not solve(g, Existence(wrench=w, preload=pre)).stable
    md = solve(g, MaxDisturbance(direction=w, preload=pre, cap=1e3))
    assert not md.stats["capped"]
    assert md.value is None or md.value < 1e-9


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_answers_do_not_depend_on_units(scale):
    """Points * L with torques * L (and any force scale k) is the same grasp problem."""
    rng = np.random.default_rng(42)
    for _ in range(25):
        m = int(rng.integers(2, 5))
        pts = rng.uniform(-1, 1, (m, 2))
        ang = rng.uniform(0, 2 * np.pi, m)
        nrm = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        w = rng.normal(size=3)
        p = rng.uniform(0, 1.5, m)
        k = 1e4 if scale != 1.0 else 1.0
        ref = solve(Grasp(pts, nrm, 0.4), Existence(wrench=w, preload=p))
        ws = np.array([w[0], w[1], w[2] * scale]) * k
        sol = solve(Grasp(pts * scale, nrm, 0.4), Existence(wrench=ws, preload=p * k))
        assert sol.stable == ref.stable
        if sol.stable:
            assert sol.max_residual() <= 1e-7 * k * (1 + np.abs(ws).max())
        d = solve(Grasp(pts, nrm, 0.4), MaxDisturbance(direction=w, preload=p, cap=50.0))
        ds = solve(
            Grasp(pts * scale, nrm, 0.4), MaxDisturbance(direction=ws, preload=p * k, cap=1e6)
        )
        if d.stable and not d.stats["capped"]:
            assert ds.value == pytest.approx(d.value, rel=1e-6, abs=1e-9)
