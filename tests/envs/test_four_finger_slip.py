"""The contact-slip penalty of the four-finger rotation env (issue 29): the sliding speed it
reads from MuJoCo's constraint velocities equals the relative velocity of the two bodies at
each contact point, from the bodies' Jacobians, in the contact's tangent plane."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from envs.four_finger import FourFingerError, FourFingerRotate


def _slip_from_jacobians(env: FourFingerRotate) -> list[float]:
    m, d, ph = env.model, env.data, env.physics
    jac1, jac2 = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    out = []
    for i in range(d.ncon):
        c = d.contact[i]
        g1, g2 = int(c.geom[0]), int(c.geom[1])
        link = g1 if ph.is_obj[g2] else g2 if ph.is_obj[g1] else -1
        if link < 0 or ph.slot[link] < 0 or c.exclude:
            continue
        mujoco.mj_jac(m, d, jac1, None, c.pos, m.geom_bodyid[g1])
        mujoco.mj_jac(m, d, jac2, None, c.pos, m.geom_bodyid[g2])
        rel = (jac2 - jac1) @ d.qvel
        t1, t2 = c.frame[3:6], c.frame[6:9]
        out.append(math.hypot(rel @ t1, rel @ t2))
    return out


def test_slip_is_the_tangential_relative_velocity_at_the_contacts() -> None:
    env = FourFingerRotate(slip_weight=2.0)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(6):
        _, _, term, _, info = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        assert not term
    assert info["slip"] == pytest.approx(-2.0 * env.physics.object_slip())
    mujoco.mj_forward(env.model, env.data)  # efc_vel of the current state
    ref = _slip_from_jacobians(env)
    assert len(ref) >= 2
    assert env.physics.object_slip() == pytest.approx(float(np.mean(ref)), rel=1e-6)
    assert env.physics.object_slip() > 1e-3  # random setpoint steps make the contacts slide


def test_still_hand_barely_slips_and_the_weight_is_checked() -> None:
    """A held start grasp with zero actions creeps at well under 1 mm/s (MuJoCo's soft
    friction); the default weight adds nothing to the reward."""
    env = FourFingerRotate(slip_weight=1.0, grasps="test", n_grasps=4)
    env.reset(seed=0, options={"grasp": 0})
    zero = np.zeros(12, dtype=np.float32)
    slips = [-env.step(zero)[4]["slip"] for _ in range(20)]
    assert max(slips[5:]) < 1e-3
    plain = FourFingerRotate(grasps="test", n_grasps=4)
    plain.reset(seed=0, options={"grasp": 0})
    assert plain.step(zero)[4]["slip"] == 0.0
    with pytest.raises(FourFingerError, match="slip_weight"):
        FourFingerRotate(slip_weight=-1.0)
