"""shields.qp with the study's drop criteria (ShieldLimits(contacts=False, friction=False,
tilt=False)) and the drift model (GraspQP(drift_steps=H)): which rows exist, that the
drift is the object's velocity read back from MuJoCo, that a returned action keeps the
rows it was solved for; GuardedShield: the thesis' QP exactly where its guard rejects."""

from __future__ import annotations

import copy

import cvxpy as cp
import gymnasium as gym
import mujoco
import numpy as np

import envs  # noqa: F401  (registers ihm/FourFingerRotate-v0)
from envs.four_finger import FourFingerRotate
from shields import GuardedShield, ShieldLimits, drop_limits
from shields.qp import GraspQP, tilt_angles

_BIG = 1e29  # the QP's "no bound" is +-1e30


def qp_for(env: FourFingerRotate, **kw: object) -> GraspQP:
    return GraspQP(env.model, max_setpoint_step=env.max_setpoint_step, horizon=env.dt, **kw)


def moving_states(env: FourFingerRotate, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for g in range(n):
        env.reset(options={"grasp": g})
        for _ in range(int(rng.integers(1, 12))):
            _, _, term, _, _ = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
            if term:
                break
        yield rng.uniform(-1, 1, 12)


def test_friction_and_tilt_rows_can_be_dropped() -> None:
    env = FourFingerRotate()
    env.reset(options={"grasp": 0})
    full = qp_for(env).problem(env.data)
    part = qp_for(env, limits=ShieldLimits(friction=False, tilt=False)).problem(env.data)
    np.testing.assert_array_equal(part.low_contact[:, 0], full.low_contact[:, 0])  # normal
    assert np.all(part.low_contact[:, 1:] <= -_BIG)  # no friction rows
    assert np.all(full.low_contact[:, 1:] > -_BIG)
    np.testing.assert_array_equal(part.low_global[:3], full.low_global[:3])  # the box stays
    assert np.all(part.low_global[3:] <= -_BIG) and np.all(part.high_global[3:] >= _BIG)


def test_drift_is_the_objects_velocity() -> None:
    env = FourFingerRotate()
    h = 3.0
    for _ in moving_states(env, 4, seed=1):
        d = env.data
        p0 = qp_for(env, limits=ShieldLimits(contacts=False)).problem(d)
        ph = qp_for(env, limits=ShieldLimits(contacts=False), drift_steps=h).problem(d)
        vel = np.empty(6)  # [angular, linear], world frame, at the body's origin
        body = env.model.body("object").id
        fresh = copy.copy(d)  # cvel of the current state (d's is one substep old)
        mujoco.mj_forward(env.model, fresh)
        mujoco.mj_objectVelocity(env.model, fresh, mujoco.mjtObj.mjOBJ_BODY, body, vel, 0)
        shift = -(ph.low_global - p0.low_global)
        np.testing.assert_allclose(shift[:3], h * env.dt * vel[3:], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(ph.high_global[:3] - p0.high_global[:3], -shift[:3])
        # the tilt rows: dr (the tilt gradient at the problem's orientation) times the world
        # angular velocity; MuJoCo's is at the current orientation, d.xmat one substep older
        _, dr = tilt_angles(d.xmat[body].reshape(3, 3))
        np.testing.assert_allclose(shift[3:], h * env.dt * dr @ vel[:3], rtol=2e-2, atol=1e-9)


def test_box_only_action_keeps_its_rows() -> None:
    env = FourFingerRotate()
    qp = qp_for(env, limits=drop_limits(env), drift_steps=4.0)
    seen = set()
    for a in moving_states(env, 14, seed=2):
        res = qp(env.data, a)
        seen.add(res.status)
        prob = qp.last_problem
        if res.status == "safe":
            assert np.array_equal(res.action, a)
        if res.status in ("safe", "corrected"):
            y = prob.A_global @ np.clip(res.action, prob.x_low, prob.x_high)
            assert np.all(y >= prob.low_global - 1e-6) and np.all(y <= prob.high_global + 1e-6)
        if res.status == "corrected":  # the nearest such action, by an independent solver
            x = cp.Variable(12)
            fin = np.abs(prob.low_global) < _BIG
            cons = [x >= prob.x_low, x <= prob.x_high,
                    prob.A_global[fin] @ x >= prob.low_global[fin],
                    prob.A_global[fin] @ x <= prob.high_global[fin]]  # fmt: skip
            cp.Problem(cp.Minimize(cp.sum_squares(x - a)), cons).solve(solver=cp.CLARABEL)
            assert res.correction <= np.linalg.norm(x.value - a) + 1e-5
    assert "safe" in seen and len(seen) >= 2, seen


def test_guarded_shield_is_the_thesis_qp_where_the_guard_rejects() -> None:
    env = GuardedShield(gym.make("ihm/FourFingerRotate-v0"))
    base = env.unwrapped
    thesis = qp_for(base)
    rng = np.random.default_rng(5)
    seen = set()
    for ep in range(6):
        env.reset(seed=ep)
        for _ in range(15):
            a = rng.uniform(-1, 1, 12)
            guard = env.guard(base.data, a)
            want = thesis(base.data, a)
            x, intervened = env.shield(a)
            if guard.status == "safe":
                assert np.array_equal(x, a) and not intervened
            else:
                np.testing.assert_array_equal(x, want.action)
                assert intervened == (want.status in ("corrected", "fallback"))
            seen.add(guard.status == "safe")
            _, _, term, _, info = env.step(a)
            assert "shield_guard" in info
            if term:
                break
    assert seen == {True, False}
