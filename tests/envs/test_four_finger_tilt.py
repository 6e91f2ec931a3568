"""The tilt penalty of the four-finger rotation env (issue 29): ``z_tilt`` is the swing of
the swing-twist decomposition, checked against rotations built from axis and angle and
against the object's z axis read from MuJoCo's ``xmat``."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from envs.four_finger import FourFingerError, FourFingerRotate, z_tilt, z_twist


def _quat(axis, angle) -> np.ndarray:
    q, a = np.zeros(4), np.asarray(axis, float)
    mujoco.mju_axisAngle2Quat(q, a / np.linalg.norm(a), angle)
    return q


def _mul(a, b) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, a, b)
    return q


@pytest.mark.parametrize("theta", [0.0, 0.3, 1.2, 2.5, math.pi])
@pytest.mark.parametrize("axis", [[1, 0, 0], [0, 1, 0], [1, -2, 0]])
def test_tilt_is_the_angle_of_a_rotation_about_a_horizontal_axis(axis, theta) -> None:
    """From any start orientation, a rotation by ``theta`` about a horizontal axis tilts by
    ``theta``; one about z then adds nothing to the tilt and everything to the twist."""
    start = _quat([0.3, -1, 2], 0.9)
    tipped = _mul(_quat(axis, theta), start)
    assert z_tilt(start, tipped) == pytest.approx(theta, abs=1e-7)
    spun = _mul(_quat([0, 0, 1], 0.8), start)
    assert z_tilt(start, spun) == pytest.approx(0.0, abs=1e-7)
    assert z_twist(start, spun) == pytest.approx(0.8, abs=1e-9)
    both = _mul(_quat([0, 0, 1], -1.1), tipped)
    assert z_tilt(start, both) == pytest.approx(theta, abs=1e-7)


def test_tilt_equals_the_angle_between_the_vertical_and_its_image() -> None:
    """Random rotations: ``cos(tilt)`` is the z component of ``R_rel e_z``."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        q0, q1 = rng.normal(size=4), rng.normal(size=4)
        q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
        rel, conj = np.zeros(4), np.zeros(4)
        mujoco.mju_negQuat(conj, q0)
        mujoco.mju_mulQuat(rel, q1, conj)
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, rel)
        assert math.cos(z_tilt(q0, q1)) == pytest.approx(r[8], abs=1e-9)


def test_env_tilt_term_reads_the_object_orientation_from_mujoco() -> None:
    """Random setpoint steps rock the cylinder; the term is ``-w`` times the angle by which
    the object's rotation since the start, ``R_1 R_0^T`` from ``data.xmat``, turns the
    vertical; off by default."""
    env = FourFingerRotate("cylinder", tilt_weight=2.0, grasps="test", n_grasps=4)
    env.reset(seed=0, options={"grasp": 1})
    body = env.model.body("object").id
    r0 = env.data.xmat[body].reshape(3, 3).copy()
    rng = np.random.default_rng(1)
    for _ in range(8):
        _, _, term, _, info = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        assert not term
    mujoco.mj_forward(env.model, env.data)  # xmat of this qpos (mj_step leaves it a substep old)
    r1 = env.data.xmat[body].reshape(3, 3)
    vertical = r1 @ r0.T @ np.array([0.0, 0.0, 1.0])  # the vertical, turned as the object was
    angle = math.acos(float(np.clip(vertical[2], -1, 1)))
    assert angle > 1e-3
    assert info["tilt"] == pytest.approx(-2.0 * angle, rel=1e-6, abs=1e-9)
    plain = FourFingerRotate("cylinder", grasps="test", n_grasps=4)
    plain.reset(seed=0, options={"grasp": 1})
    assert plain.step(rng.uniform(-1, 1, 12).astype(np.float32))[4]["tilt"] == 0.0
    with pytest.raises(FourFingerError, match="tilt_weight"):
        FourFingerRotate(tilt_weight=-0.5)
