"""MaxDisturbance / Existence with a MotionLimit: the largest load held with the object's
motion within a bound, against closed forms, across methods, in physical units."""

from __future__ import annotations

import math

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
K, P = 1000.0, 2.0  # N/m, N


def _pinch() -> Grasp:
    """Two opposed contacts 60 mm apart along x, stiffness K (left) and 2K (right)."""
    return Grasp([[-0.03, 0, 0], [0.03, 0, 0]], [[1, 0, 0], [-1, 0, 0]], mu=0.5,
                 stiffness=[K, 2 * K])  # fmt: skip


def _support(e: np.ndarray, radius: float) -> tuple[float, float]:
    """Along unit ``e``: how far the inscribed polytope of a ball of ``radius`` reaches on
    the ray ``t e`` (closed form) and at most with any sideways motion (an LP)."""
    a, rho = ball_directions(len(e))
    ray = radius / (rho * float(np.abs(a @ e).max()))
    A = np.r_[a, -a]
    lp = linprog(-e, A_ub=A, b_ub=np.full(len(A), radius / rho), bounds=[(None, None)] * len(e))
    return ray, -float(lp.fun)


def _pinch_answer(shift: float) -> float:
    """The pinch pushed along +x within ``shift``: with both contacts closed the object moves
    along x only (a sideways slide at both contacts has unbalanced friction), ``s = 3 K t``
    while ``t <= P / K``; once the left contact opens, ``s = P + 2 K h`` at the polytope's
    reach ``h >= P / K``."""
    ray, reach = _support(np.array([1.0, 0.0, 0.0]), shift)
    options = [3 * K * ray] if ray <= P / K else []
    if reach >= P / K:
        options.append(P + 2 * K * reach)
    return max(options)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shift", [0.5e-3, 1.5e-3, 3e-3, 10e-3])
def test_pinch_against_closed_form(method: str, shift: float) -> None:
    q = MaxDisturbance([1, 0, 0, 0, 0, 0], preload=P, cap=100.0,
                       motion_limit=MotionLimit(shift=shift))  # fmt: skip
    sol = solve(_pinch(), q, method=method)
    assert sol.status == "solved" and sol.stable
    assert sol.value == pytest.approx(_pinch_answer(shift), rel=1e-7)
    res = sol.residuals()
    assert res["motion_limit"] <= 1e-12
    assert np.linalg.norm(sol.motion[:3]) <= shift * (1 + 1e-9)
    assert sol.max_residual(enforced=True) <= 1e-7


def test_polytope_sits_between_its_balls() -> None:
    """Every vertex of the inscribed polytope is within the ball and every direction
    reaches at least 1 / rho of it (sampled directions, LP reach)."""
    rng = np.random.default_rng(0)
    for dim in (2, 3):
        _, rho = ball_directions(dim)
        for e in rng.normal(size=(20, dim)):
            e /= np.linalg.norm(e)
            ray, reach = _support(e, 1.0)
            assert 1.0 / rho - 1e-12 <= ray <= reach <= 1.0 + 1e-9


def test_limit_grows_to_the_free_answer() -> None:
    """A larger limit never gives less, and a limit beyond the free answer's motion gives
    the free answer (a pinch under its weight, pushed sideways: friction-limited)."""
    g = Grasp([[-0.03, 0, 0], [0.03, 0, 0]], [[1, 0, 0], [-1, 0, 0]], mu=0.5,
              stiffness=[K, K])  # fmt: skip
    base = [0, 0, -0.5, 0, 0, 0]
    free = solve(g, MaxDisturbance([0, 1, 0, 0, 0, 0], preload=P, cap=100.0, base=base))
    assert free.status == "solved" and not free.stats["capped"]
    values = []
    for shift in (1e-4, 1e-3, 1e-2, 1.0):
        q = MaxDisturbance([0, 1, 0, 0, 0, 0], preload=P, cap=100.0, base=base,
                           motion_limit=MotionLimit(shift, 1.0))  # fmt: skip
        values.append(solve(g, q).value)
    assert all(b >= a - 1e-9 for a, b in zip(values, values[1:], strict=False))
    assert values[-1] == pytest.approx(free.value, rel=1e-7)


def test_turn_limit_on_a_torque() -> None:
    """A torque about z on the pinch turns it against the contacts' friction: with a small
    turn limit the answer is at most the free one and the rotation stays within it."""
    g = _pinch()
    free = solve(g, MaxDisturbance([0, 0, 0, 0, 0, 1], preload=P, cap=10.0))
    lim = MotionLimit(turn=1e-3, point=[0.01, 0.0, 0.0])
    sol = solve(g, MaxDisturbance([0, 0, 0, 0, 0, 1], preload=P, cap=10.0, motion_limit=lim))
    assert sol.status == "solved" and sol.value <= free.value + 1e-9
    assert np.linalg.norm(sol.motion[3:]) <= 1e-3 * (1 + 1e-9)
    assert sol.residuals()["motion_limit"] <= 1e-12


def test_existence_within_a_limit() -> None:
    """A load held only after the object moves 1.5 mm (the left contact pushed to P + ...):
    stable with a 2 mm limit, unstable with a 1 mm one."""
    g = _pinch()
    w = [-3.5, 0, 0, 0, 0, 0]  # needs t = 3.5 / 3K = 1.17 mm with both contacts closed
    for shift, stable in ((2e-3, True), (1e-3, False)):
        for method in ("modesearch", "exact"):
            sol = solve(g, Existence(w, preload=P, motion_limit=MotionLimit(shift)), method=method)
            assert sol.status == "solved" and sol.stable is stable, (method, shift)


def test_planar_pinch() -> None:
    """A planar grasp: the 16-gon and ``|theta| <= turn`` (no_mdp, the MIP that takes
    planar grasps), against the closed form of the spatial pinch's x push."""
    g = Grasp([[-0.03, 0], [0.03, 0]], [[1, 0], [-1, 0]], mu=0.5, stiffness=[K, 2 * K])
    shift = 0.5e-3
    ray, _ = _support(np.array([1.0, 0.0]), shift)
    q = MaxDisturbance([1, 0, 0], preload=P, cap=100.0, motion_limit=MotionLimit(shift))
    sol = solve(g, q, method="no_mdp")
    assert sol.value == pytest.approx(3 * K * ray, rel=1e-7)
    assert sol.residuals()["motion_limit"] <= 1e-12


@pytest.mark.parametrize("method", ["gws", "iterative"])
def test_methods_without_a_limit_refuse(method: str) -> None:
    q = MaxDisturbance([1, 0, 0, 0, 0, 0], preload=P, motion_limit=MotionLimit(1e-3))
    with pytest.raises(MethodError, match="motion_limit"):
        solve(_pinch(), q, method=method)


@pytest.mark.parametrize(
    "limit, match",
    [
        (MotionLimit(shift=0.0), "> 0"),
        (MotionLimit(turn=-1.0), "> 0"),
        (MotionLimit(shift=math.nan), "> 0"),
        (MotionLimit(point=[0.0, 1.0]), "3 finite numbers"),
        ((1e-3, 0.05), "stability.MotionLimit"),
    ],
)
def test_bad_limits_are_named(limit, match: str) -> None:
    q = MaxDisturbance([1, 0, 0, 0, 0, 0], preload=P, motion_limit=limit)
    with pytest.raises(GraspError, match=match):
        solve(_pinch(), q)
