"""shields.qp / shields.GraspShield: the linearised-compliance QP shield.

Residuals of returned actions under the linear model, idempotence on safe actions, agreement
of the two QP backends and of an independent solver (cvxpy/Clarabel), the fallback, force
closure against stability.gws, and the wrapper inside SB3's SubprocVecEnv."""

from __future__ import annotations

import cvxpy as cp
import gymnasium as gym
import mujoco
import numpy as np
import pytest
from stable_baselines3.common.vec_env import SubprocVecEnv

import envs  # noqa: F401  (registers ihm/FourFingerRotate-v0)
from envs.four_finger import FourFingerError, FourFingerRotate
from shields import GraspShield, ShieldError, ShieldLimits
from shields.force_closure import force_closure_wrenches
from shields.qp import STATUSES, GraspQP, tilt_angles
from stability import Grasp, gws

INFO_KEYS = (
    "agent_action",
    "executed_action",
    "shield_intervened",
    "shield_correction",
    "shield_subset",
    "shield_status",
    "shield_solve_time_s",
)


@pytest.fixture(scope="module")
def env() -> FourFingerRotate:
    return FourFingerRotate()


def shield_for(env: FourFingerRotate, **kw: object) -> GraspQP:
    return GraspQP(env.model, max_setpoint_step=env.max_setpoint_step, horizon=env.dt, **kw)


def states(env: FourFingerRotate, n: int = 6, seed: int = 0):
    """Settled cached grasps, then a few random steps: (grasp, action) pairs at each state."""
    rng = np.random.default_rng(seed)
    for g in range(n):
        env.reset(options={"grasp": g})
        for _ in range(int(rng.integers(1, 4))):
            env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
        yield g, rng.uniform(-1, 1, 12)


@pytest.mark.parametrize("backend", ["daqp", "osqp"])
def test_returned_action_satisfies_its_constraints(env: FourFingerRotate, backend: str) -> None:
    qp = shield_for(env, backend=backend)
    seen = set()
    for _, a in states(env, 8):
        res = qp(env.data, a)
        prob = qp.last_problem
        seen.add(res.status)
        assert res.status in STATUSES
        assert np.all(res.action >= -1) and np.all(res.action <= 1)
        ctrl = env.data.ctrl + env.max_setpoint_step * res.action
        rng_ = env.model.actuator_ctrlrange
        assert np.all(ctrl >= rng_[:, 0] - 1e-12) and np.all(ctrl <= rng_[:, 1] + 1e-12)
        if res.status in ("safe", "corrected"):
            mask = sum(1 << prob.links.index(name) for name in res.links)
            assert prob.closure(mask)
            x = np.clip(res.action, prob.x_low, prob.x_high)
            assert prob.violation(mask, x) <= 1e-6
            assert res.violation <= 1e-6
            # servos of unshielded links keep the agent's action
            fixed = prob.fixed(mask)
            np.testing.assert_array_equal(
                res.action[fixed], np.clip(a, prob.x_low, prob.x_high)[fixed]
            )
            # predicted state under the linear model: the constraints, written out
            c, du = prob.lin.predict(env.max_setpoint_step * x)
            for k, link in enumerate(prob.lin.links):
                if link in res.links:
                    assert c[k, 0] >= qp.limits.c_min - 1e-6
                    assert np.hypot(c[k, 1], c[k, 2]) <= prob.lin.mu[k] * c[k, 0] + 1e-6
            p = prob.lin.object_pos + du[:3]
            lo = np.minimum(qp.limits.box_low, prob.lin.object_pos)
            hi = np.maximum(qp.limits.box_high, prob.lin.object_pos)
            assert np.all(p >= lo - 1e-6) and np.all(p <= hi + 1e-6)
    assert "corrected" in seen


def test_safe_action_is_returned_unchanged(env: FourFingerRotate) -> None:
    """A corrected action is safe: shielding it again returns it bit for bit."""
    qp = shield_for(env)
    n = 0
    for _, a in states(env, 8, seed=3):
        first = qp(env.data, a)
        if first.status != "corrected":
            continue
        again = qp(env.data, first.action)
        assert again.status == "safe"
        assert again.correction == 0.0
        np.testing.assert_array_equal(again.action, first.action)
        n += 1
    assert n >= 2


def test_backends_agree(env: FourFingerRotate) -> None:
    daqp_, osqp_ = shield_for(env, backend="daqp"), shield_for(env, backend="osqp")
    for _, a in states(env, 8, seed=5):
        r1, r2 = daqp_(env.data, a), osqp_(env.data, a)
        assert r1.status == r2.status
        assert r1.correction == pytest.approx(r2.correction, abs=1e-4)
        if r1.status == "corrected":
            np.testing.assert_allclose(r1.action, r2.action, atol=1e-3)


def test_optimal_against_clarabel(env: FourFingerRotate) -> None:
    """The returned correction is the smallest over all candidates: each candidate's QP
    solved again with cvxpy/Clarabel."""
    qp = shield_for(env)
    checked = 0
    for _, a in states(env, 8, seed=7):
        res = qp(env.data, a)
        if res.status != "corrected":
            continue
        prob = qp.last_problem
        a_eff = np.clip(a, prob.x_low, prob.x_high)
        best = np.inf
        for mask in prob.candidates:
            A, low, high = prob.rows(mask)
            fixed = prob.fixed(mask)
            x = cp.Variable(12)
            cons = [A @ x >= low, x >= prob.x_low, x <= prob.x_high, x[fixed] == a_eff[fixed]]
            fin = np.isfinite(high)
            cons.append(A[fin] @ x <= high[fin])
            pr = cp.Problem(cp.Minimize(cp.sum_squares(x - a)), cons)
            pr.solve(solver=cp.CLARABEL)
            if pr.status == cp.OPTIMAL:
                best = min(best, float(np.sum((x.value - a) ** 2)))
        assert res.correction**2 == pytest.approx(best, rel=1e-4, abs=1e-7)
        checked += 1
    assert checked >= 2


def test_infeasible_takes_the_fallback(env: FourFingerRotate) -> None:
    qp = shield_for(env, limits=ShieldLimits(c_min=50.0))  # no grasp squeezes 50 N
    env.reset(options={"grasp": 1})
    a = np.full(12, 0.5)
    res = qp(env.data, a)
    assert res.status == "fallback"
    np.testing.assert_array_equal(res.action, np.zeros(12))
    assert res.qps >= 1 and res.correction == pytest.approx(np.linalg.norm(a))
    # through the wrapper: no exception, the zero step executed, the status in info
    wrapped = GraspShield(gym.make("ihm/FourFingerRotate-v0"), limits=ShieldLimits(c_min=50.0))
    wrapped.reset(seed=0, options={"grasp": 1})
    ctrl = wrapped.unwrapped.data.ctrl.copy()
    _, _, _, _, info = wrapped.step(a.astype(np.float32))
    assert info["shield_status"] == "fallback" and info["shield_intervened"]
    np.testing.assert_array_equal(wrapped.unwrapped.data.ctrl, ctrl)


def test_no_grasp_passes_the_action(env: FourFingerRotate) -> None:
    qp = shield_for(env)
    env.reset(options={"grasp": 0})
    env.data.qpos[14] += 0.5  # the object above the hand: no contact
    mujoco.mj_forward(env.model, env.data)
    a = np.linspace(-1, 1, 12)
    res = qp(env.data, a)
    assert res.status == "no_closure" and res.links == ()
    np.testing.assert_array_equal(res.action, a)


def test_two_soft_fingertips_can_be_a_candidate(env: FourFingerRotate) -> None:
    """With ``soft_closure`` and torsional friction (condim 4) two fingertip contacts can be
    in force closure, so a three-finger grasp has two-finger candidates; with point-contact
    closure (the default) no pair of single contacts is."""
    found = 0
    soft_qp, point_qp = shield_for(env, limits=ShieldLimits(soft_closure=True)), shield_for(env)
    for g in range(12):
        env.reset(options={"grasp": g})
        env.step(np.zeros(12, dtype=np.float32))
        soft, point = soft_qp.problem(env.data), point_qp.problem(env.data)
        if len(soft.groups) != 3 or any(len(m) != 1 for m in soft.groups):
            continue
        assert not [mk for mk in point.candidates if bin(mk).count("1") == 2]
        found += bool([mk for mk in soft.candidates if bin(mk).count("1") == 2])
        # a superset of a candidate is one, so the full set is one in both
        assert point.closure(7) == soft.closure(7) or soft.closure(7)
    assert found >= 1


def test_relaxed_contacts_accept_holding_still(env: FourFingerRotate) -> None:
    """``relax_contacts``: a contact row the state already violates only must not get worse,
    so keeping every setpoint (the zero action, which changes nothing under the linear
    model) is safe wherever the links are in force closure; the thesis' strict rows
    correct it where a contact is already outside its cone."""
    strict, relaxed = shield_for(env), shield_for(env, limits=ShieldLimits(relax_contacts=True))
    corrected = 0
    for g in range(16):
        env.reset(options={"grasp": g})
        env.step(np.zeros(12, dtype=np.float32))
        r = relaxed(env.data, np.zeros(12))
        assert r.status in ("safe", "no_closure")
        if strict(env.data, np.zeros(12)).status == "corrected":
            assert r.status == "safe"
            assert (strict.last_problem.low_contact > 1e-6).any()  # a violated row
            corrected += 1
    assert corrected >= 1


def test_broken_state_takes_the_fallback(env: FourFingerRotate) -> None:
    """NaN in MuJoCo's data (a diverged simulation) gives the fallback, not an exception."""
    qp = shield_for(env)
    env.reset(options={"grasp": 2})
    env.data.qvel[:] = np.nan
    mujoco.mj_forward(env.model, env.data)
    res = qp(env.data, np.full(12, 0.3))
    assert res.status in ("fallback", "no_closure")
    assert np.all(np.isfinite(res.action))
    env.reset(options={"grasp": 2})


def test_force_closure_agrees_with_gws() -> None:
    """The shield's fast test (one QP) against stability.gws.force_closure (convex hull)."""
    rng = np.random.default_rng(11)
    agree = {True: 0, False: 0}
    for trial in range(60):
        m = int(rng.integers(2, 5))
        pts = rng.normal(size=(m, 3))
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
        if trial % 3 == 0:  # contacts in one hemisphere: often not in closure
            pts[:, 2] = np.abs(pts[:, 2])
        g = Grasp(points=0.035 * pts, normals=-pts, mu=float(rng.uniform(0.2, 1.0)))
        W = gws.primitive_wrenches(g, 8).copy()
        W[:, 3:] /= 0.035
        ref = gws.force_closure(g, 8)
        assert force_closure_wrenches(W) == ref, trial
        agree[ref] += 1
    assert agree[True] >= 5 and agree[False] >= 5


def test_tilt_gradient_matches_finite_differences() -> None:
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, q)
        R = R.reshape(3, 3)
        r, dr = tilt_angles(R)
        z = R[:, 2]
        assert r[0] == pytest.approx(np.arctan2(z[1], z[2]))
        for i in range(3):
            w = np.zeros(3)
            w[i] = 1e-6
            Rw = np.zeros(9)
            dq = np.zeros(4)
            mujoco.mju_axisAngle2Quat(dq, w / 1e-6, 1e-6)
            mujoco.mju_quat2Mat(Rw, dq)
            r2, _ = tilt_angles(Rw.reshape(3, 3) @ R)
            np.testing.assert_allclose((r2 - r) / 1e-6, dr[:, i], atol=1e-4)


def test_wrapper_in_subproc_vec_env() -> None:
    def make() -> gym.Env:
        return GraspShield(gym.make("ihm/FourFingerRotate-v0"), backend="daqp")

    vec = SubprocVecEnv([make, make], start_method="fork")
    try:
        vec.seed(0)
        vec.reset()
        statuses = []
        for _ in range(4):
            _, _, _, infos = vec.step(np.random.default_rng(0).uniform(-1, 1, (2, 12)))
            for info in infos:
                assert all(k in info for k in INFO_KEYS), sorted(info)
                assert info["shield_status"] in STATUSES
                assert info["shield_correction"] == pytest.approx(
                    np.linalg.norm(info["executed_action"] - np.clip(info["agent_action"], -1, 1))
                )
                statuses.append(info["shield_status"])
    finally:
        vec.close()
    assert statuses


def test_bad_options(env: FourFingerRotate) -> None:
    with pytest.raises(ShieldError, match="backend"):
        shield_for(env, backend="quadprog")
    with pytest.raises(ShieldError, match="edges"):
        ShieldLimits(edges=2)
    with pytest.raises(ShieldError, match="box_low"):
        ShieldLimits(box_low=(0.1, 0.0, 0.0))
    with pytest.raises(ShieldError, match="c_min"):
        ShieldLimits(c_min=float("nan"))
    qp = shield_for(env)
    env.reset(options={"grasp": 0})
    with pytest.raises(ShieldError, match="shape"):
        qp(env.data, np.zeros(11))
    with pytest.raises(ShieldError, match="NaN"):
        qp(env.data, np.full(12, np.nan))
    wrapped = GraspShield(gym.make("ihm/FourFingerRotate-v0"))
    wrapped.reset(seed=0)
    with pytest.raises(FourFingerError, match="NaN"):
        wrapped.step(np.full(12, np.nan, dtype=np.float32))
