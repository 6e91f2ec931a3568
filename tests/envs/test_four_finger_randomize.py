"""Randomised physics, held-out start grasps and the net-turn measure of the four-finger
rotation env (issue 29): read back from the MjModel, MjData and the observation."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from envs.four_finger import (
    CONTACT_LINKS,
    FourFingerError,
    FourFingerRotate,
    PhysicsSample,
    Randomization,
    corners,
    grasp_cache,
    yaw_rate,
    z_twist,
)
from envs.four_finger.cache import GRASP_SETS
from ihm.hands import four_finger as ff


def _quat(axis, angle) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q, np.asarray(axis, float), angle)
    return q


def _mul(a, b) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, a, b)
    return q


def _turns(quats, dt=0.05) -> tuple[float, float]:
    """(summed per-step z rotation, unwrapped net z twist) along a quaternion trajectory, as
    the env accumulates them."""
    summed = net = prev = 0.0
    for q0, q1 in zip(quats[:-1], quats[1:], strict=True):
        summed += yaw_rate(q0, q1, dt) * dt
        tw = z_twist(quats[0], q1)
        net += math.remainder(tw - prev, 2 * math.pi)
        prev = tw
    return summed, net


def test_net_turn_equals_summed_rotation_about_z() -> None:
    """A pure rotation about z through several full turns: the net twist (unwrapped) is the
    summed rotation, both the true angle."""
    start = _quat([1, 2, 0.5], 0.7)  # any start orientation
    angles = np.linspace(0.0, 3.3 * 2 * np.pi, 400)
    quats = [_mul(_quat([0, 0, 1], a), start) for a in angles]
    summed, net = _turns(quats)
    assert summed == pytest.approx(angles[-1], rel=1e-9)
    assert net == pytest.approx(angles[-1], rel=1e-9)
    back = [_mul(_quat([0, 0, 1], -a), start) for a in angles]
    assert _turns(back)[1] == pytest.approx(-angles[-1], rel=1e-9)


def test_net_turn_is_smaller_than_summed_rotation_when_tumbling() -> None:
    """A tumbling trajectory: world angular velocity ``(a cos(phi t), a sin(phi t), w)``, a
    steady turn about z plus a horizontal spin whose axis circles, integrated in fine steps.
    The per-step z rotations add up to about ``w T`` (what the reward sums), but the object's
    heading turns less: the tumble's cone costs twist, the overstatement the issue measured
    on the sphere (summed 1.62 against 1.50 rad/s)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    quats = [q]
    a, phi, w, dt, sub = 2.0, 6.0, 1.0, 0.05, 10
    for k in range(400):
        for j in range(sub):
            t = (k * sub + j) * dt / sub
            om = np.array([a * np.cos(phi * t), a * np.sin(phi * t), w])
            q = _mul(_quat(om / np.linalg.norm(om), np.linalg.norm(om) * dt / sub), q)
        quats.append(q)
    summed, net = _turns(quats)
    assert summed == pytest.approx(w * 20.0, rel=0.02)
    assert 0.0 < net < 0.8 * summed


def test_env_reports_net_turn_and_caps_the_rotation_reward() -> None:
    env = FourFingerRotate(rotation_cap=0.2)
    obs, info = env.reset(seed=3)
    assert info["net_turn"] == 0.0
    rng = np.random.default_rng(0)
    for _ in range(20):
        obs, r, term, _, info = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        assert abs(info["rotation"]) <= 0.2 + 1e-12 and r == pytest.approx(info["rotation"])
        if term:
            break
    tw = z_twist(env._quat0, env.physics.object_quat())
    assert math.remainder(info["net_turn"] - tw, 2 * np.pi) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(FourFingerError, match="rotation_cap"):
        FourFingerRotate(rotation_cap=0.0)


def test_heldout_grasps_are_not_training_grasps() -> None:
    """The test set comes from a disjoint generator seed: no test grasp is within 1e-6 of any
    training grasp (256 training, 100 test), and both are valid held grasps."""
    assert GRASP_SETS["train"] != GRASP_SETS["test"]
    train = grasp_cache("sphere", True, 256, seed=GRASP_SETS["train"])
    test = grasp_cache("sphere", True, 100, seed=GRASP_SETS["test"])
    d = np.linalg.norm(train.qpos[:, None, :] - test.qpos[None, :, :], axis=2)
    assert d.min() > 1e-3
    env = FourFingerRotate(grasps="test", n_grasps=100)
    np.testing.assert_array_equal(env.grasps.qpos, test.qpos)
    with pytest.raises(FourFingerError, match="grasps"):
        FourFingerRotate(grasps="validation")


def test_fixed_physics_is_read_back_from_mujoco() -> None:
    """A corner's scales land in the MjModel (pair friction, mass, inertia, servo gain), and the
    contacts MuJoCo makes carry the scaled friction."""
    nominal = FourFingerRotate()
    s = PhysicsSample(friction=0.5, torsional=1.5, mass=2.0, gain=0.8)
    env = FourFingerRotate(physics=s)
    m0, m = nominal.model, env.model
    b = env.physics.obj_body
    assert m.body_mass[b] == pytest.approx(2.0 * m0.body_mass[b])
    np.testing.assert_allclose(m.body_inertia[b], 2.0 * m0.body_inertia[b])
    assert m.body_subtreemass[b] == pytest.approx(2.0 * m0.body_subtreemass[b])
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], 0.8 * m0.actuator_gainprm[:, 0])
    np.testing.assert_allclose(m.actuator_biasprm[:, 1], 0.8 * m0.actuator_biasprm[:, 1])
    env.reset(seed=0)
    env.step(np.zeros(12, np.float32))
    d = env.data
    obj = [
        i
        for i in range(d.ncon)
        if b in (m.geom_bodyid[d.contact.geom1[i]], m.geom_bodyid[d.contact.geom2[i]])
        and m.geom_bodyid[d.contact.geom1[i]] != 0
    ]
    assert obj, "the start grasp touches the object"
    for i in obj:
        fr = d.contact.friction[i]
        assert fr[0] == pytest.approx(0.5 * 1.0) and fr[2] == pytest.approx(1.5 * 0.005)
    # the servo force follows the scaled gain: kp * (ctrl - q)
    mujoco.mj_forward(m, d)
    q = d.qpos[: ff.NQ]
    np.testing.assert_allclose(d.actuator_force, np.clip(0.8 * (d.ctrl - q), -0.5, 0.5), atol=1e-9)


def test_physics_given_at_reset_is_read_back_and_kept() -> None:
    """``reset(options={"physics": s})`` writes ``s`` into the MjModel of an env built without
    randomised physics, keeps it for the next resets, and overrides a ``randomize`` draw; a
    value that is not a PhysicsSample is refused."""
    env = FourFingerRotate()
    b = env.physics.obj_body
    m0 = env.model.body_mass[b]
    kp0 = env.model.actuator_gainprm[:, 0].copy()
    mu0 = env.model.pair_friction[:, 0].copy()
    s = PhysicsSample(friction=0.7, mass=1.1, gain=tuple(np.linspace(0.8, 1.2, 12)))
    env.reset(seed=0, options={"grasp": 3, "physics": s})
    assert env.scaler is not None and env.scaler.current == s
    assert env.model.body_mass[b] == pytest.approx(1.1 * m0)
    np.testing.assert_allclose(env.model.actuator_gainprm[:, 0], np.linspace(0.8, 1.2, 12) * kp0)
    pairs = env.scaler.obj_pairs
    np.testing.assert_allclose(env.model.pair_friction[pairs, 0], 0.7 * mu0[pairs])
    env.reset(options={"grasp": 4})
    assert env.scaler.current == s
    r = FourFingerRotate(randomize=Randomization())
    r.reset(seed=0, options={"physics": s})
    assert r.scaler is not None and r.scaler.current == s
    with pytest.raises(FourFingerError, match="PhysicsSample"):
        env.reset(options={"physics": 0.5})


def test_randomization_draws_within_ranges_and_changes_each_episode() -> None:
    r = Randomization()
    env = FourFingerRotate(randomize=r)
    b = env.physics.obj_body
    m0 = FourFingerRotate().model
    masses, lat = [], []
    for k in range(40):
        env.reset(seed=k) if k == 0 else env.reset()
        s = env.scaler.current
        m = env.model
        assert r.friction[0] <= s.friction <= r.friction[1]
        assert r.mass[0] <= s.mass <= r.mass[1]
        assert m.body_mass[b] == pytest.approx(s.mass * m0.body_mass[b])
        p = env.scaler.obj_pairs
        np.testing.assert_allclose(m.pair_friction[p, 0], s.friction * m0.pair_friction[p, 0])
        np.testing.assert_allclose(m.pair_friction[p, 2], s.torsional * m0.pair_friction[p, 2])
        g = m.actuator_gainprm[:, 0] / m0.actuator_gainprm[:, 0]
        assert np.all((g >= r.gain[0] - 1e-12) & (g <= r.gain[1] + 1e-12))
        masses.append(s.mass)
        lat.append(s.latency)
    assert min(masses) < 0.8 and max(masses) > 1.3 and 0 < np.mean(lat) < 1
    # pairs of finger links with each other keep their friction
    other = np.setdiff1d(np.arange(env.model.npair), env.scaler.obj_pairs)
    assert len(other) and np.allclose(env.model.pair_friction[other], m0.pair_friction[other])


def test_latency_applies_the_previous_action() -> None:
    """With one step of latency the first action moves no setpoint and the second step applies
    the first action."""
    a1 = np.full(12, 0.5, np.float32)
    a2 = np.full(12, -0.3, np.float32)
    env = FourFingerRotate(physics=PhysicsSample(latency=1))
    env.reset(seed=1)
    c0 = env.data.ctrl.copy()
    env.step(a1)
    np.testing.assert_allclose(env.data.ctrl, c0)
    env.step(a2)
    lo, hi = env.physics.ctrl_lo, env.physics.ctrl_hi
    np.testing.assert_allclose(env.data.ctrl, np.clip(c0 + 0.5 * 0.05, lo, hi))


def test_latency_observes_the_commanded_setpoint() -> None:
    """Under latency the setpoint slots show the action in flight: after step(a1) they hold
    the setpoints that the next step applies, while the servos still run on the old ones;
    without latency they are ``data.ctrl``."""
    a1 = np.full(12, 0.5, np.float32)
    env = FourFingerRotate(physics=PhysicsSample(latency=1))
    env.reset(seed=3)
    c0 = env.data.ctrl.copy()
    obs, *_ = env.step(a1)
    np.testing.assert_allclose(env.data.ctrl, c0)  # not applied yet
    shown = obs[ff.NQ : 2 * ff.NU].astype(float)
    assert np.abs(shown - c0).max() > 0.01
    env.step(np.zeros(12, np.float32))
    np.testing.assert_allclose(shown, env.data.ctrl, atol=1e-6)
    nominal = FourFingerRotate()
    nominal.reset(seed=3)
    obs, *_ = nominal.step(a1)
    np.testing.assert_allclose(obs[ff.NQ : 2 * ff.NU], nominal.data.ctrl, atol=1e-6)


def test_sensor_noise_has_the_stated_spread() -> None:
    """Observation minus the noise-free observation: joint noise of std 0.005 rad, contact
    force noise 0.05 N on touching links, none on setpoints or on links without contact."""
    noise = (0.005, 0.001, 0.05)
    env = FourFingerRotate(physics=PhysicsSample(noise=noise))
    env.reset(seed=2)
    dq, dctrl, dfn, dfree = [], [], [], []
    for _ in range(300):
        clean = env.observe()
        noisy = env._sensed()
        diff = noisy.astype(float) - clean
        dq.append(diff[: ff.NQ])
        dctrl.append(diff[ff.NQ : 2 * ff.NU])
        c = diff[2 * ff.NU :].reshape(len(CONTACT_LINKS), 4)
        touching = clean[2 * ff.NU + 3 :: 4] > 0
        dfn.append(c[touching, 3])
        dfree.append(c[~touching].ravel())
    assert np.std(np.concatenate(dq)) == pytest.approx(0.005, rel=0.1)
    assert np.concatenate(dfn).size > 100
    assert np.std(np.concatenate(dfn)) == pytest.approx(0.05, rel=0.15)
    assert not np.any(np.concatenate(dctrl)) and not np.any(np.concatenate(dfree))


def test_corners_cover_the_ranges() -> None:
    c = corners()
    assert len(c) == 16
    assert {s.friction for s in c} == {0.5, 1.5} and {s.mass for s in c} == {0.5, 2.0}
    assert all(s.latency == 1 and s.noise == (0.005, 0.001, 0.05) for s in c)
    with pytest.raises(FourFingerError, match="mass"):
        Randomization(mass=(2.0, 0.5))
    with pytest.raises(FourFingerError, match="not both"):
        FourFingerRotate(randomize=Randomization(), physics=PhysicsSample())


def test_corner_prob_draws_corners_at_the_stated_rate() -> None:
    """Boundary sampling: ``corner_prob`` 1 draws only corners, all 16 of them; 0.5 about half
    (binomial, 400 draws, 4.5 sigma); 0 leaves the uniform stream as it was; out of [0, 1]
    is refused. In the env, a corner episode's friction is read back from the model."""
    cs = set(corners())
    rng = np.random.default_rng(0)
    draws = [Randomization(corner_prob=1.0).sample(rng, ff.NU) for _ in range(200)]
    assert set(draws) <= cs and len(set(draws)) == 16
    rng = np.random.default_rng(1)
    half = [Randomization(corner_prob=0.5).sample(rng, ff.NU) in cs for _ in range(400)]
    assert abs(sum(half) - 200) < 4.5 * math.sqrt(100)
    a = [Randomization().sample(np.random.default_rng(2), ff.NU) for _ in range(3)]
    b = [Randomization(corner_prob=0.0).sample(np.random.default_rng(2), ff.NU) for _ in range(3)]
    assert a == b and not set(a) & cs
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(FourFingerError, match="corner_prob"):
            Randomization(corner_prob=bad)
    env = FourFingerRotate(randomize=Randomization(corner_prob=1.0))
    m0 = FourFingerRotate().model
    p = env.scaler.obj_pairs
    for k in range(4):
        env.reset(seed=k)
        s = env.scaler.current
        assert s in cs
        np.testing.assert_allclose(
            env.model.pair_friction[p, 0], s.friction * m0.pair_friction[p, 0]
        )


def test_hard_prob_draws_the_hard_region_at_the_stated_rate() -> None:
    """``hard_prob`` 1 draws friction at its lower bound and the mass log-uniformly between
    nominal and the heaviest (about half of them above sqrt(2), 4.5 sigma), torsional friction
    and gains still spread over their ranges; with ``corner_prob`` 0.3 and ``hard_prob`` 0.4
    the three kinds come at 0.3 / 0.4 / 0.3 (4.5 sigma); a sum above 1 is refused; 0 leaves
    the uniform stream as it was; ``hard_gain`` bounds the gains there. In the env the
    friction and mass are read back from the model."""
    cs = set(corners())
    rng = np.random.default_rng(0)
    draws = [Randomization(hard_prob=1.0).sample(rng, ff.NU) for _ in range(400)]
    assert {d.friction for d in draws} == {0.5}
    masses = np.array([d.mass for d in draws])
    assert masses.min() >= 1.0 and masses.max() <= 2.0
    assert abs((masses > math.sqrt(2)).sum() - 200) < 4.5 * math.sqrt(100)
    tors = np.array([d.torsional for d in draws])
    gains = np.array([d.gain for d in draws])
    assert tors.min() < 0.6 and tors.max() > 1.4 and gains.min() < 0.81 and gains.max() > 1.19
    rng = np.random.default_rng(1)
    r = Randomization(corner_prob=0.3, hard_prob=0.4)
    kinds = np.zeros(3)
    for _ in range(1000):
        d = r.sample(rng, ff.NU)
        kinds[0 if d in cs else 1 if d.friction == 0.5 and d.mass >= 1.0 else 2] += 1
    for k, p in zip(kinds, (0.3, 0.4, 0.3), strict=True):
        assert abs(k - 1000 * p) < 4.5 * math.sqrt(1000 * p * (1 - p))
    with pytest.raises(FourFingerError, match="corner_prob \\+ hard_prob"):
        Randomization(corner_prob=0.6, hard_prob=0.5)
    with pytest.raises(FourFingerError, match="hard_prob"):
        Randomization(hard_prob=-0.1)
    weak = Randomization(hard_prob=1.0, hard_gain=1.0).sample(np.random.default_rng(3), ff.NU)
    assert 0.8 <= min(weak.gain) < max(weak.gain) <= 1.0  # ``hard_gain``: the weak half
    with pytest.raises(FourFingerError, match="hard_gain"):
        Randomization(hard_gain=0.7)
    a = [Randomization().sample(np.random.default_rng(2), ff.NU) for _ in range(3)]
    b = [Randomization(hard_prob=0.0).sample(np.random.default_rng(2), ff.NU) for _ in range(3)]
    assert a == b
    env = FourFingerRotate(randomize=Randomization(hard_prob=1.0))
    m0 = FourFingerRotate().model
    p, body = env.scaler.obj_pairs, env.scaler.obj_body
    for k in range(4):
        env.reset(seed=k)
        np.testing.assert_allclose(env.model.pair_friction[p, 0], 0.5 * m0.pair_friction[p, 0])
        ratio = env.model.body_mass[body] / m0.body_mass[body]
        assert 1.0 <= ratio <= 2.0
        assert ratio == pytest.approx(env.scaler.current.mass)


def test_scaled_ranges_shrink_towards_nominal_and_are_read_back() -> None:
    """``Randomization.scaled(s)``: friction, torsional friction and gain bounds move to
    ``1 + s (b - 1)``, mass bounds to ``b**s`` (log-range scaled); latency, noise and the
    sampling probabilities stay; ``s = 1`` is the same ranges; ``s`` outside (0, 1] is refused.
    The corners are the scaled bounds, and in the env every draw's friction, mass and gains
    read back from the model lie inside the scaled ranges, not only inside the full ones."""
    r = Randomization(hard_prob=0.5, hard_gain=1.0).scaled(0.5)
    assert r.friction == (0.75, 1.25) and r.torsional == (0.75, 1.25) and r.gain == (0.9, 1.1)
    assert r.mass == pytest.approx((1 / math.sqrt(2), math.sqrt(2)))
    assert (r.latency_prob, r.hard_prob, r.hard_gain) == (0.5, 0.5, 1.0)
    assert (r.noise_joint, r.noise_pos, r.noise_force) == (0.005, 0.001, 0.05)
    assert Randomization().scaled(1.0) == Randomization()
    assert Randomization().scaled(0.25).gain == (0.95, 1.05)
    for bad in (0.0, -0.5, 1.5, float("nan")):
        with pytest.raises(FourFingerError, match="range scale"):
            Randomization().scaled(bad)
    half = Randomization().scaled(0.5)
    c = corners(half)
    assert {s.friction for s in c} == {0.75, 1.25} and {s.gain for s in c} == {0.9, 1.1}
    assert all(s.latency == 1 for s in c)
    env = FourFingerRotate(randomize=half)
    m0 = FourFingerRotate().model
    p, body = env.scaler.obj_pairs, env.scaler.obj_body
    for k in range(12):
        env.reset(seed=k) if k == 0 else env.reset()
        f = env.model.pair_friction[p, 0] / m0.pair_friction[p, 0]
        assert np.all((f >= 0.75 - 1e-12) & (f <= 1.25 + 1e-12))
        mass = env.model.body_mass[body] / m0.body_mass[body]
        assert 2**-0.5 - 1e-12 <= mass <= 2**0.5 + 1e-12
        g = env.model.actuator_gainprm[:, 0] / m0.actuator_gainprm[:, 0]
        assert np.all((g >= 0.9 - 1e-12) & (g <= 1.1 + 1e-12))


def test_height_term_penalises_sag_toward_the_drop_threshold() -> None:
    """``height = -w * max(0, HOLD_Z - z) / (HOLD_Z - DROP_Z)`` of the object's centre after the
    step: 0 for a grasp held high, -w/2 halfway down, and part of the reward."""
    from envs.four_finger import DROP_Z
    from envs.four_finger.env import HOLD_Z

    env = FourFingerRotate(height_weight=2.0)
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.zeros(12, np.float32))
    z = env.physics.object_pos()[2]
    assert z > HOLD_Z and info["height"] == 0.0
    env.data.qpos[env.physics.obj_qpos + 2] = 0.5 * (HOLD_Z + DROP_Z)
    assert env._sag() == pytest.approx(0.5)
    _, r, _, _, info = env.step(np.zeros(12, np.float32))
    z = env.physics.object_pos()[2]
    assert info["height"] == pytest.approx(-2.0 * max(0.0, HOLD_Z - z) / (HOLD_Z - DROP_Z))
    assert info["height"] < -0.5
    assert r == pytest.approx(info["rotation"] + info["drop"] + info["action"] + info["height"])


def test_height_from_start_counts_every_millimetre_of_sag() -> None:
    """``height_from="start"``: the reference is the object's height at the reset, ``z_0``:
    ``height = -w * max(0, z_0 - z) / (z_0 - DROP_Z)``. A 3 mm sag, free with ``HOLD_Z`` (7 mm
    below a held object), costs about ``w * 3 / 27`` from the start height; bad names are
    refused."""
    from envs.four_finger import DROP_Z
    from envs.four_finger.env import HOLD_Z

    hold = FourFingerRotate(height_weight=2.0)
    start = FourFingerRotate(height_weight=2.0, height_from="start")
    for env in (hold, start):
        env.reset(seed=0, options={"grasp": 3})
    z0 = start.physics.object_pos()[2]
    assert z0 - 0.003 > HOLD_Z and start._z_ref == z0 and hold._z_ref == HOLD_Z
    for env in (hold, start):
        env.data.qpos[env.physics.obj_qpos + 2] = z0 - 0.003
    _, _, _, _, h = hold.step(np.zeros(12, np.float32))
    _, r, _, _, s = start.step(np.zeros(12, np.float32))
    z = start.physics.object_pos()[2]
    assert h["height"] == 0.0
    assert s["height"] == pytest.approx(-2.0 * (z0 - z) / (z0 - DROP_Z))
    assert -2.0 * 0.2 < s["height"] < -2.0 * 0.05
    assert r == pytest.approx(sum(s[k] for k in ("rotation", "drop", "action", "height", "slip")))
    with pytest.raises(FourFingerError, match="height_from"):
        FourFingerRotate(height_from="palm")


def test_history_stacks_the_last_frames_oldest_first() -> None:
    """``history=3``: the observation is three sensed frames, oldest first; at a reset all
    three are the first frame, each step shifts them by one, and the newest frame is what
    the single-frame env observes from the same start and actions."""
    one, three = FourFingerRotate(), FourFingerRotate(history=3)
    n = one.observation_space.shape[0]
    assert three.observation_space.shape == (3 * n,)
    np.testing.assert_array_equal(three.observation_space.low[2 * n :], one.observation_space.low)
    o1, _ = one.reset(seed=5)
    o3, _ = three.reset(seed=5)
    np.testing.assert_array_equal(o3.reshape(3, n), np.tile(o1, (3, 1)))
    rng = np.random.default_rng(0)
    frames = [o1]
    for _ in range(4):
        a = rng.uniform(-1, 1, 12).astype(np.float32)
        o1 = one.step(a)[0]
        new3 = three.step(a)[0]
        np.testing.assert_array_equal(new3[: 2 * n], o3[n:])  # shifted by one frame
        np.testing.assert_array_equal(new3[2 * n :], o1)
        frames.append(o1)
        o3 = new3
    np.testing.assert_array_equal(o3.reshape(3, n), np.stack(frames[-3:]))
    with pytest.raises(FourFingerError, match="history"):
        FourFingerRotate(history=0)
