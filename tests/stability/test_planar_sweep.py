"""Batched planar MaxDisturbance maps (``stability.planar.max_disturbance_map``) against
one ``solve(..., method="planar")`` per direction: same values, capped and stable flags."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_planar_degenerate import box_grasp

from stability import Grasp, GraspError, MaxDisturbance, MethodError, solve
from stability import planar as pl
from stability.maps import resistible_forces
from stability.planar import enumeration, sweep, system
from stability.planar.solve import unit_grasp

THREE = Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)


def fresh_three() -> Grasp:
    """The thesis grasp without the per-grasp state caches of earlier tests."""
    return Grasp(THREE.points, THREE.normals, THREE.mu)


def circle(n: int) -> np.ndarray:
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)


def per_direction(grasp, D, preload, cap, base=None):
    """The reference: one planar solve per direction."""
    vals = np.zeros(len(D))
    capped = np.zeros(len(D), dtype=bool)
    stable = np.zeros(len(D), dtype=bool)
    for k, d in enumerate(D):
        q = MaxDisturbance(direction=d, preload=preload, cap=cap, base=base)
        sol = solve(grasp, q, method="planar")
        stable[k] = sol.stable
        vals[k] = sol.value if sol.stable else 0.0
        capped[k] = sol.stats["capped"]
    return vals, capped, stable


def assert_same(batched, ref):
    vals, capped, stable = batched
    rvals, rcapped, rstable = ref
    np.testing.assert_array_equal(stable, rstable)
    np.testing.assert_array_equal(capped, rcapped)
    # 1e-9 relative; values that are zero up to round-off (1e-16) compare absolutely
    np.testing.assert_allclose(vals, rvals, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(("preload", "step"), [(0.0, 3), (1.0, 9)])
def test_thesis_map_equals_per_direction_solves(preload, step):
    D = circle(360)
    out = pl.max_disturbance_map(fresh_three(), D, preload, cap=10.0)
    vals, capped, stable = out
    # the loop is slow with preload (LP states): every step-th degree, 0/90/180/270 included
    sub = np.arange(0, 360, step)
    assert {0, 90, 180, 270} <= set(sub.tolist())
    assert_same(tuple(x[sub] for x in out), per_direction(THREE, D[sub], preload, 10.0))
    # all 360: what the thesis figure shows, and its mirror symmetry x -> -x
    assert stable.all()
    np.testing.assert_array_equal(capped, (D[:, 1] < 1e-12))  # any force not lifting
    assert vals[90] == pytest.approx(1.0 if preload else 0.0, abs=1e-9)
    mirror = (180 - np.arange(360)) % 360
    np.testing.assert_allclose(vals, vals[mirror], rtol=1e-9, atol=1e-12)
    if preload:
        assert np.all(vals[1:180] > 0.85) and np.all(vals[1:180] < 10.0)
    else:
        np.testing.assert_allclose(vals[1:180], 0.0, atol=1e-12)


def test_thesis_map_needs_no_lp(monkeypatch):
    """The thesis grasp's LP states are all ruled out by the range test, the bound or
    the precheck: the map is pure numpy (the per-direction loop solves ~24 LPs each)."""
    calls = []
    real = sweep.lp_state
    monkeypatch.setattr(sweep, "lp_state", lambda *a, **k: calls.append(1) or real(*a, **k))
    for preload in (0.0, 1.0):
        pl.max_disturbance_map(fresh_three(), circle(360), preload, cap=10.0)
    assert not calls


def test_unstable_directions_with_a_base_load():
    """A base wrench the grasp cannot hold alone: some directions are unstable (value 0,
    not capped), some finite, some capped."""
    ang = np.array([-2.23, -2.66, 2.99])
    g = Grasp([[-0.2, 0.43], [-0.44, -0.83], [0.94, 0.13]], np.c_[np.cos(ang), np.sin(ang)], 0.5)
    base = np.array([2.83, -0.92, 1.07])
    D = circle(72)
    vals, capped, stable = out = pl.max_disturbance_map(g, D, 0.5, cap=5.0, base=base)
    assert (~stable).sum() >= 10 and (stable & ~capped).sum() >= 5 and capped.sum() >= 5
    assert np.all(vals[~stable] == 0.0) and not capped[~stable].any()
    sub = np.arange(0, 72, 2)
    assert_same(tuple(x[sub] for x in out), per_direction(g, D[sub], 0.5, 5.0, base))


def test_thesis_with_base_that_lifts():
    """Thesis grasp pulled up by more than its preload holds: only downward directions
    make it stable again (capped), the rest are unstable."""
    D = circle(72)
    out = pl.max_disturbance_map(fresh_three(), D, 1.0, cap=10.0, base=(0.0, 1.5, 0.2))
    assert 0 < out[2].sum() < 72
    sub = np.arange(0, 72, 6)
    assert_same(tuple(x[sub] for x in out), per_direction(THREE, D[sub], 1.0, 10.0, (0, 1.5, 0.2)))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_grasps(seed):
    """Seeded random grasps, 3 or 4 contacts (4: the all-rolling state has 4 unknowns and
    goes through the zonotope bound), scalar and per-contact preloads, a base load and
    directions with torque on some."""
    rng = np.random.default_rng(100 + seed)
    m = 3 + seed % 2
    pts = rng.uniform(-1, 1, (m, 2)) * rng.uniform(0.2, 5.0)
    ang = rng.uniform(0, 2 * np.pi, m)
    g = Grasp(pts, np.c_[np.cos(ang), np.sin(ang)], rng.uniform(0.2, 1.0, m))
    preload = [0.0, 1.0, rng.uniform(0, 2, m), 0.5][seed]
    base = rng.normal(0, 0.5, 3) if seed >= 2 else None
    D = circle(72)
    if seed % 2:
        D[:, 2] = rng.normal(0, 0.5, 72)  # force and torque
    cap = 5.0
    out = pl.max_disturbance_map(g, D, preload, cap=cap, base=base)
    sub = np.arange(0, 72, 2)  # every other direction: the loop solves LPs here
    assert_same(tuple(x[sub] for x in out), per_direction(g, D[sub], preload, cap, base))


def test_degenerate_box_grasps():
    """Contacts sharing faces: singular and over-determined states that keep their LPs."""
    rng = np.random.default_rng(7)
    for m in (3, 4):
        pts, nrm = box_grasp(rng, m)
        g = Grasp(pts, nrm, 0.5)
        D = rng.choice([-1.0, -0.5, 0.0, 0.5, 1.0], size=(12, 3))
        D[~D.any(axis=1), 0] = 1.0
        assert_same(pl.max_disturbance_map(g, D, 1.0, cap=5.0), per_direction(g, D, 1.0, 5.0))


@pytest.mark.parametrize("preload", [0.0, 1.0])
def test_precheck_only_rules_out_lps_without_solution(preload):
    """Over all (singular state, direction) pairs whose LP pins ``s`` (not only those a
    map reaches): the precheck says "no" only where the LP has no solution, and it
    rules out most of them."""
    p = enumeration.preload_vector(THREE, preload)
    ctx = system.Context.make(THREE, p, np.zeros(3), np.zeros(3))  # the thesis grasp has size 1
    sw = sweep._sweep_states(THREE, ctx, p, 8192)
    D = circle(12)
    solvable, s_ub, pinned = sweep._singular_bounds(ctx, sw, D, 10.0)
    k, j = np.nonzero(solvable & pinned)
    maybe = sweep._precheck(ctx, sw, k, s_ub[k, j], D[j])
    lp_ok = np.array([
        system.lp_state(
            dataclasses.replace(ctx, d=D[jj]), sw.rS[kk], sw.rP[kk], (0.0, s_ub[kk, jj]), 1
        )
        is not None
        for kk, jj in zip(k, j, strict=True)
    ])  # fmt: skip
    assert lp_ok.sum() >= 5  # the implication below is exercised
    assert np.all(maybe[lp_ok])
    assert (~maybe).sum() >= 0.5 * (~lp_ok).sum()


@pytest.mark.parametrize("preload", [0.0, 1.0])
def test_zonotope_bound_is_the_lp_value(preload):
    """For states whose rolling contacts hold the object still, the support-function
    bound equals the LP's optimum wherever the LP is feasible (and is never below it)."""
    rng = np.random.default_rng(11)
    pts = rng.uniform(-1, 1, (4, 2))
    ang = rng.uniform(0, 2 * np.pi, 4)
    g = Grasp(pts, np.c_[np.cos(ang), np.sin(ang)], 0.6)
    p = enumeration.preload_vector(g, preload)
    _, unit = unit_grasp(g)
    ctx = system.Context.make(unit, p, np.zeros(3), np.zeros(3))
    sw = sweep._sweep_states(unit, ctx, p, 8192)
    assert sw.fixed.any()
    # random directions, and directions near the zonotopes' centres -h (rays that hit them)
    aim = -sw.mh[sw.fixed][rng.integers(0, sw.fixed.sum(), 12)]
    D = np.r_[rng.normal(size=(12, 3)), aim + 0.3 * rng.normal(size=(12, 3))]
    feasible, s_hi = sweep._zonotope_bounds(ctx, sw, D, 10.0)
    n_feasible = 0
    for k, (S, P) in enumerate(zip(sw.mS[sw.fixed], sw.mP[sw.fixed], strict=True)):
        for j, d in enumerate(D):
            res = system.lp_state(dataclasses.replace(ctx, d=d), S, P, (0.0, 10.0), sense=1)
            if res is not None:
                n_feasible += 1
                assert feasible[k, j]
                assert s_hi[k, j] == pytest.approx(res[2], rel=1e-9, abs=1e-12)
    assert n_feasible >= 5


def test_resistible_forces_uses_the_batch():
    g = fresh_three()
    rmap = resistible_forces(g, "planar", directions=36, preload=1.0, cap=10.0)
    vals, capped, _ = pl.max_disturbance_map(g, circle(36), 1.0, cap=10.0)
    np.testing.assert_array_equal(rmap.magnitudes, vals)
    np.testing.assert_array_equal(rmap.capped, capped)
    ref_vals, ref_capped, _ = per_direction(THREE, circle(36)[::3], 1.0, 10.0)
    np.testing.assert_allclose(rmap.magnitudes[::3], ref_vals, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(rmap.capped[::3], ref_capped)
    # a second map on the same grasp (cached states) answers the same
    again = resistible_forces(g, "planar", directions=36, preload=1.0, cap=10.0)
    np.testing.assert_array_equal(again.magnitudes, rmap.magnitudes)


def test_units_and_scaling():
    """Points * L with torques * L is the same problem (the unit-grasp scaling)."""
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1, 1, (3, 2))
    ang = rng.uniform(0, 2 * np.pi, 3)
    nrm = np.c_[np.cos(ang), np.sin(ang)]
    D = rng.normal(size=(24, 3))
    ref = pl.max_disturbance_map(Grasp(pts, nrm, 0.6), D, 0.7, cap=5.0)
    L = 1e3
    out = pl.max_disturbance_map(Grasp(pts * L, nrm, 0.6), D * [1, 1, L], 0.7, cap=5.0)
    np.testing.assert_array_equal(out[2], ref[2])
    np.testing.assert_allclose(out[0], ref[0], rtol=1e-9, atol=1e-12)


def test_certified_rows_match_certified():
    """The batched certificate is the scalar one, row by row, on real solutions and on
    perturbed ones."""
    rng = np.random.default_rng(3)
    p = np.full(3, 1.0)
    ctx = system.Context.make(THREE, p, np.zeros(3), np.zeros(3))
    code = {"detach": (0, 0), "roll": (0, 1), "slip+": (1, 1), "slip-": (-1, 1)}
    rows = []
    for d in circle(24):
        sol = solve(THREE, MaxDisturbance(direction=d, preload=p, cap=10.0), method="planar")
        S = np.array([code[n][0] for n in sol.states], dtype=np.int8)
        P = np.array([code[n][1] for n in sol.states], dtype=bool)
        for eps in (0.0, 1e-9, 1e-3):
            r = sol.motion + eps * rng.normal(size=3)
            ct = np.where(S == 0, sol.forces[:, 1], 0.0) + eps * rng.normal(size=3)
            rows.append((S, P, r, ct, sol.value, d))
    S, P, r, ct, s, d = (np.array(x) for x in zip(*rows, strict=True))
    got = sweep._certified_rows(ctx, S, P, r, ct, s, d)
    want = [
        system.certified(system.Context.make(THREE, p, np.zeros(3), dk), Sk, Pk, rk, ck, sk)
        for Sk, Pk, rk, ck, sk, dk in rows
    ]
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < len(got)


def test_bad_input():
    D = circle(8)
    with pytest.raises(GraspError, match=r"directions must be an \(N, 3\) array"):
        pl.max_disturbance_map(THREE, D[:, :2])
    with pytest.raises(GraspError, match=r"directions must be an \(N, 3\) array"):
        pl.max_disturbance_map(THREE, D[0])
    with pytest.raises(GraspError, match=r"directions must be an \(N, 3\) array"):
        pl.max_disturbance_map(THREE, "up")
    with pytest.raises(GraspError, match="finite"):
        pl.max_disturbance_map(THREE, np.r_[D, [[np.nan, 0, 0]]])
    with pytest.raises(GraspError, match=r"non-zero \(rows \[8\]\)"):
        pl.max_disturbance_map(THREE, np.r_[D, [[0, 0, 0]]])
    with pytest.raises(GraspError, match="cap must be finite and > 0"):
        pl.max_disturbance_map(THREE, D, cap=0.0)
    with pytest.raises(GraspError, match="preload must be >= 0"):
        pl.max_disturbance_map(THREE, D, preload=-1.0)
    with pytest.raises(GraspError, match=r"base must have shape \(3,\)"):
        pl.max_disturbance_map(THREE, D, base=[0, 1])
    with pytest.raises(GraspError, match="unknown option"):
        pl.max_disturbance_map(THREE, D, tol=1e-3)
    with pytest.raises(GraspError, match="chunk must be a positive integer"):
        pl.max_disturbance_map(THREE, D, chunk=0)
    with pytest.raises(GraspError, match="expected a stability.Grasp"):
        pl.max_disturbance_map("grasp", D)
    # what solve says: the planar method models a rigid hand, no commands
    with pytest.raises(MethodError, match="rigid hand only"):
        pl.max_disturbance_map(THREE, D, commands=[1.0])
    with pytest.raises(MethodError, match="rigid hand only"):
        solve(THREE, MaxDisturbance(direction=D[0], commands=[1.0]), method="planar")
    with pytest.raises(MethodError, match="rigid hand only"):
        resistible_forces(THREE, "planar", directions=8, commands=[1.0])
    spatial = Grasp(np.eye(3), -np.eye(3), 0.5)
    with pytest.raises(MethodError, match="planar grasp"):
        pl.max_disturbance_map(spatial, np.eye(6)[:2])
    empty = pl.max_disturbance_map(THREE, np.zeros((0, 3)))
    assert [len(x) for x in empty] == [0, 0, 0]


def test_map_chart_radius_fits_the_answers_and_names_the_axes() -> None:
    """A map well below its cap is drawn out to just beyond its largest answer, one that
    reaches the cap out to the cap; 0 and 90 degrees are labelled with the plane's axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stability.maps import ResistibleMap, plot_resistible, radial_top

    angles = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    small = ResistibleMap(angles, np.r_[1.2, 1.9, np.nan, 1.5, 0, 0, 1, 1], np.zeros(8, bool),
                          10.0, "xz", "planar")  # fmt: skip
    assert radial_top(small) == pytest.approx(1.9 * 1.1)
    capped = ResistibleMap(angles, np.full(8, 10.0), np.ones(8, bool), 10.0, "xy", "planar")
    assert radial_top(capped) == pytest.approx(10.5)
    fig, ax = plt.subplots(subplot_kw={"projection": "polar"})
    plot_resistible(ax, small)
    assert ax.get_ylim()[1] == pytest.approx(2.09)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["+x", "+z", "-x", "-z"]
    plt.close(fig)
