"""Negative preloads (gaps) and contacts a MotionLimit keeps open, against closed forms,
across the 3D methods: a pinch with a third contact that closes after a gap."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from stability import (
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    MethodError,
    MotionLimit,
    solve,
)
from stability.model.problem import ball_directions

METHODS = ("modesearch", "refinement", "exact", "no_mdp")
K, K3, P = 1000.0, 4000.0, 2.0  # N/m, N/m, N


def _pinch3() -> Grasp:
    """The pinch of tests/stability/test_motion_limit.py (contacts 60 mm apart along x,
    stiffness K left and 2K right) with a third contact of stiffness K3 at the right one's
    point and normal."""
    return Grasp([[-0.03, 0, 0], [0.03, 0, 0], [0.03, 0, 0]],
                 [[1, 0, 0], [-1, 0, 0], [-1, 0, 0]], mu=0.5,
                 stiffness=[K, 2 * K, K3])  # fmt: skip


def _reach(shift: float) -> tuple[float, float]:
    """How far the inscribed polytope of a ball of ``shift`` reaches along +x: on the ray,
    and with any sideways motion (an LP)."""
    e = np.array([1.0, 0.0, 0.0])
    a, rho = ball_directions(3)
    ray = shift / (rho * float(np.abs(a @ e).max()))
    A = np.r_[a, -a]
    lp = linprog(-e, A_ub=A, b_ub=np.full(len(A), shift / rho), bounds=[(None, None)] * 3)
    return ray, -float(lp.fun)


def _answer(shift: float, gap: float) -> float:
    """Push along +x by ``t``: the left contact gives ``max(0, P - K t)``, the right
    ``P + 2 K t``, the gapped one ``K3 max(0, t - gap)`` (preload ``-K3 gap``). With the left
    contact closed the object moves along x only (``t`` on the polytope's ray), once it opens
    it may turn about the right contacts' point (``t`` up to the polytope's reach)."""
    ray, reach = _reach(shift)
    options = []
    if ray <= P / K:
        options.append(3 * K * ray + K3 * max(0.0, ray - gap))
    if reach >= P / K:
        options.append(P + 2 * K * reach + K3 * max(0.0, reach - gap))
    return max(options)


def _query(shift: float, gap: float, keep_open: bool = False) -> MaxDisturbance:
    limit = MotionLimit(shift=shift, open=np.array([False, False, keep_open]))
    return MaxDisturbance([1, 0, 0, 0, 0, 0], preload=[P, P, -K3 * gap], cap=100.0,
                          motion_limit=limit)  # fmt: skip


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(("shift", "gap"), [(1.5e-3, 0.5e-3), (1.5e-3, 2e-3), (3e-3, 1e-3)])
def test_gap_engages_at_closed_form(method: str, shift: float, gap: float) -> None:
    sol = solve(_pinch3(), _query(shift, gap), method=method)
    assert sol.status == "solved" and sol.stable
    assert sol.value == pytest.approx(_answer(shift, gap), rel=1e-7)
    assert sol.max_residual(enforced=True) <= 1e-7
    closes = sol.forces[2, 0] > 1e-9
    assert closes == (_reach(shift)[1] > gap if shift > 2e-3 else _reach(shift)[0] > gap)


@pytest.mark.parametrize("method", METHODS)
def test_open_mask_stops_at_the_gap(method: str) -> None:
    """Kept open, the gapped contact bounds the push at ``t = gap``: ``s = 3 K gap``."""
    gap = 0.5e-3
    sol = solve(_pinch3(), _query(1.5e-3, gap, keep_open=True), method=method)
    assert sol.status == "solved" and sol.stable
    assert sol.value == pytest.approx(3 * K * gap, rel=1e-7)
    assert sol.forces[2, 0] == 0.0 or abs(sol.forces[2, 0]) <= 1e-9
    res = sol.residuals()
    assert res["motion_limit"] <= 1e-9
    assert sol.max_residual(enforced=True) <= 1e-7


@pytest.mark.parametrize("method", METHODS)
def test_gapped_contact_open_at_rest(method: str) -> None:
    """No load: the gapped contact stays open and carries nothing."""
    sol = solve(_pinch3(), Existence(np.zeros(6), preload=[P, P, -1.0]), method=method)
    assert sol.stable
    assert sol.forces[2, 0] == pytest.approx(0.0, abs=1e-9)
    assert sol.max_residual(enforced=True) <= 1e-7


def test_open_mask_validated() -> None:
    q = MaxDisturbance([1, 0, 0, 0, 0, 0], motion_limit=MotionLimit(open=[1, 0]))
    with pytest.raises(GraspError, match="open must be 3 booleans"):
        solve(_pinch3(), q, method="no_mdp")


def test_planar_still_refuses_a_gap() -> None:
    g = Grasp([[-1, 0], [1, 0]], [[1, 0], [-1, 0]], mu=0.5)
    with pytest.raises(GraspError, match="preload must be >= 0"):
        solve(g, Existence([0, 0, 0], preload=-1.0), method="planar")


def test_iterative_refuses_a_gap() -> None:
    with pytest.raises(MethodError, match="negative preload"):
        solve(_pinch3(), Existence(np.zeros(6), preload=[P, P, -1.0]), method="iterative")
