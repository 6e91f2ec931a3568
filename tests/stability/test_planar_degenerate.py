"""Degenerate planar grasps against the naive 6^m checker.

Structured grasps make the arrangements non-generic: contacts on one flat face
share their tangential plane, opposing contacts without preload share their
normal plane, several planes meet in one line. The enumeration then relies on
its non-simple-vertex and deduplication paths, so these cases get their own
cross-check against the exhaustive enumeration of ``naive_planar``.
"""

from __future__ import annotations

import numpy as np
import pytest
from naive_planar import naive_stable

from stability import Existence, Grasp, MaxDisturbance, solve

# unit-square object, contacts on its faces with axis-aligned normals into it
FACES = {
    "bottom": (np.array([0.0, -1.0]), np.array([0.0, 1.0]), 0),
    "top": (np.array([0.0, 1.0]), np.array([0.0, -1.0]), 0),
    "left": (np.array([-1.0, 0.0]), np.array([1.0, 0.0]), 1),
    "right": (np.array([1.0, 0.0]), np.array([-1.0, 0.0]), 1),
}


def box_grasp(rng: np.random.Generator, m: int):
    pts, nrm = [], []
    for _ in range(m):
        centre, n, axis = FACES[rng.choice(list(FACES))]
        p = centre.copy()
        # offsets on a coarse grid so that contacts coincide or align often
        p[axis] = rng.choice([-0.5, 0.0, 0.5])
        pts.append(p)
        nrm.append(n)
    return np.array(pts), np.array(nrm)


def cases():
    rng = np.random.default_rng(2024)
    out = []
    for k in range(120):
        m = 2 + k % 3  # 2, 3, 4 contacts
        pts, nrm = box_grasp(rng, m)
        mu = rng.choice([0.0, 0.3, 0.5, 1.0])
        preload = rng.choice([0.0, 1.0])
        # wrenches on a coarse grid (axis-aligned, pure torques, mixes) hit degenerate faces
        w = rng.choice([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0], size=3)
        out.append((pts, nrm, mu, w, preload))
    return out


@pytest.mark.slow  # brute force on 120 box grasps; test_planar_naive keeps random ones
def test_planar_agrees_with_naive_on_box_grasps():
    bad = []
    n_stable = 0
    for k, (pts, nrm, mu, w, preload) in enumerate(cases()):
        g = Grasp(pts, nrm, mu)
        sol = solve(g, Existence(wrench=w, preload=preload), method="planar")
        ref, _ = naive_stable(pts, nrm, mu, w, preload)
        n_stable += ref
        if sol.stable != ref:
            bad.append((k, pts.tolist(), nrm.tolist(), mu, w.tolist(), preload, sol.stable, ref))
        elif sol.stable:
            assert sol.max_residual() <= 1e-7, (k, sol.residuals())
    assert not bad, (
        "planar vs naive disagree (k, pts, nrm, mu, w, P, planar, naive):\n"
        + "\n".join(map(str, bad))
    )
    assert 20 <= n_stable <= 100  # both answers occur


@pytest.mark.parametrize("preload", [0.0, 1.0])
def test_pinch_without_and_with_preload(preload):
    """Two opposing fingers, collinear: both normal planes coincide (degenerate)."""
    g = Grasp([[-1, 0], [1, 0]], [[1, 0], [-1, 0]], 0.5)
    # gravity-like load across the pinch axis: friction must carry it
    down = solve(g, MaxDisturbance(direction=(0, -1, 0), preload=preload, cap=10.0))
    # unloaded springs give no friction; with preload P each finger holds mu * P
    assert down.value == pytest.approx(2 * 0.5 * preload, abs=1e-9)
    ok, _ = naive_stable(
        [[-1, 0], [1, 0]], [[1, 0], [-1, 0]], 0.5, (0, -0.9 * down.value, 0), preload
    )
    assert ok
    # along the pinch axis a finger is compressed without bound: capped
    side = solve(g, MaxDisturbance(direction=(1, 0, 0), preload=preload, cap=10.0))
    assert side.stats["capped"] and side.max_residual() <= 1e-9


def test_max_disturbance_boundary_on_box_grasps():
    """Near MaxDisturbance.value, planar Existence agrees with the naive checker."""
    bad = []
    checked = 0
    for k, (pts, nrm, mu, w, preload) in enumerate(cases()[:60]):
        if not np.any(w):
            continue
        g = Grasp(pts, nrm, mu)
        sol = solve(g, MaxDisturbance(direction=w, preload=preload, cap=20.0))
        if not sol.stable or sol.stats["capped"]:
            continue
        assert sol.max_residual() <= 1e-7 * max(1.0, sol.value)
        for s in (sol.value * (1 - 1e-3), sol.value * (1 + 1e-3) + 1e-6):
            mine = solve(g, Existence(wrench=s * w, preload=preload)).stable
            ref, _ = naive_stable(pts, nrm, mu, s * w, preload)
            if mine != ref:
                bad.append((k, s, mine, ref))
        checked += 1
    assert not bad, bad
    assert checked >= 10
