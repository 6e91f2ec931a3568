"""``ihm/FourFingerRotate-v0`` (envs.four_finger): API checks, the observation against
ihm.grasp_from_mujoco / mj_contactForce, the reward's sign and terms, stable resets, bad
input, the grasp cache, the explicit contact pairs and the solver settings.

The training smoke runs on this env: tests/train/test_rotation_train_smoke.py."""

from __future__ import annotations

import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs  # noqa: F401  (registers the ids)
from envs.four_finger import (
    CONTACT_LINKS,
    DROP_Z,
    FRAME_SKIP,
    N_OBS,
    SOLVER_TOLERANCE,
    TIMESTEP,
    VERIFY_STEPS,
    FourFingerError,
    FourFingerRotate,
    generate_grasps,
    grasp_cache,
    yaw_rate,
)
from ihm.contacts import grasp_from_mujoco
from ihm.hands import four_finger as ff


@pytest.fixture(scope="module")
def env():
    e = FourFingerRotate()
    yield e
    e.close()


def test_registered_with_the_thesis_episode_length() -> None:
    e = gym.make("ihm/FourFingerRotate-v0")
    assert e.spec.max_episode_steps == 64
    assert isinstance(e.unwrapped, FourFingerRotate)
    assert e.unwrapped.dt == pytest.approx(0.05)  # 20 Hz policy
    assert e.observation_space.shape == (N_OBS,) == (56,)
    assert e.action_space.shape == (12,)
    e.close()


def test_gymnasium_and_sb3_check_env_without_warnings(env) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=True)
    assert [str(w.message) for w in caught] == []


def test_same_seed_same_rollout() -> None:
    a, b = FourFingerRotate(), FourFingerRotate()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (30, 12)).astype(np.float32)
    out = []
    for e in (a, b):
        obs, info = e.reset(seed=123)
        traj = [obs]
        for act in actions:
            obs, r, term, trunc, info = e.step(act)
            traj.append(np.append(obs, r))
            if term:
                break
        out.append(np.concatenate(traj))
    assert np.array_equal(out[0], out[1])
    picked = {a.reset(seed=s)[1]["grasp"] for s in range(20)}
    assert len(picked) > 10  # seeds draw different start grasps


def _link_of(model, geom) -> int:
    return CONTACT_LINKS.index(model.body(model.geom_bodyid[geom]).name)


@pytest.fixture(scope="module")
def point_env():
    e = FourFingerRotate(torsional=False)  # condim 3: what grasp_from_mujoco reads
    yield e
    e.close()


@pytest.mark.parametrize("torsional", [False, True])
@pytest.mark.parametrize("steps", [0, 5, 15])
def test_observation_matches_grasp_from_mujoco(env, point_env, steps, torsional) -> None:
    """Per finger link: the mean contact position and summed normal force equal those of
    ihm.grasp_from_mujoco's contacts on that link (point contacts, condim 3; it refuses
    condim 4), and mj_contactForce's normal component (both)."""
    env = env if torsional else point_env
    obs, _ = env.reset(seed=7)
    rng = np.random.default_rng(steps)
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
    m, d = env.model, env.data
    pos = np.zeros((8, 3))
    fn = np.zeros(8)
    n = np.zeros(8)
    if torsional:  # grasp_from_mujoco refuses condim 4: contact positions from mj_data
        for c in d.contact[: d.ncon]:
            geoms = (c.geom1, c.geom2)
            names = [m.body(m.geom_bodyid[g]).name for g in geoms]
            if "object" in names and any(x in CONTACT_LINKS for x in names):
                i = CONTACT_LINKS.index(names[0] if names[1] == "object" else names[1])
                pos[i] += c.pos
                n[i] += 1
    else:
        g = grasp_from_mujoco(m, d)
        for k, geom in enumerate(g.hand_geoms):
            i = _link_of(m, geom)
            pos[i] += g.points_world()[k]
            fn[i] += g.forces[k, 0]
            n[i] += 1
    pos[n > 0] /= n[n > 0, None]
    # mj_contactForce directly: the first component is the normal force
    fn_direct = np.zeros(8)
    f6 = np.zeros(6)
    for c in range(d.ncon):
        con = d.contact[c]
        b1, b2 = m.geom_bodyid[con.geom1], m.geom_bodyid[con.geom2]
        obj = m.body("object").id
        if obj not in (b1, b2) or con.efc_address < 0:
            continue
        other = con.geom2 if b1 == obj else con.geom1
        if m.body(m.geom_bodyid[other]).name not in CONTACT_LINKS:
            continue
        mujoco.mj_contactForce(m, d, c, f6)
        fn_direct[_link_of(m, other)] += f6[0]
    feats = obs[24:].reshape(8, 4)
    assert n.sum() >= 2  # a grasp, not an empty hand
    np.testing.assert_allclose(feats[:, :3], pos, atol=1e-6)  # float32 observation
    if not torsional:
        np.testing.assert_allclose(feats[:, 3], fn, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(feats[:, 3], fn_direct, rtol=1e-5, atol=1e-6)
    assert np.all(feats[n == 0] == 0.0)
    assert np.all(feats[n > 0, 3] >= 0.0)
    np.testing.assert_allclose(obs[:12], d.qpos[:12], atol=1e-6)
    np.testing.assert_allclose(obs[12:24], d.ctrl, atol=1e-6)


def test_contacts_simulate_the_documented_torsional_friction(env, point_env) -> None:
    """Read back from mj_data.contact: condim 4 with the skin's torsional coefficient
    (TORSIONAL_FRICTION) in the default env, plain point contacts with torsional=False."""
    from envs.four_finger import TORSIONAL_FRICTION

    for e, dim in ((env, 4), (point_env, 3)):
        e.reset(seed=3)
        cons = e.data.contact[: e.data.ncon]
        assert len(cons) >= 2
        assert all(c.dim == dim for c in cons)
        assert all(c.friction[0] == pytest.approx(1.0) for c in cons)
        if dim == 4:
            assert all(c.friction[2] == pytest.approx(TORSIONAL_FRICTION) for c in cons)


def test_torsional_friction_stops_a_free_spin(env, point_env) -> None:
    """The exploit PPO found with point contacts: a sphere held between two fingertips spins
    about the line through the contacts without resistance. Fingers 2 and 4 let go, the
    sphere rests pinched between fingers 1 and 3; spun at 6 rad/s about the line through
    those contacts it keeps most of its spin for 1 s with condim 3 and loses > 90 % with
    condim 4."""
    left = {}
    for e, name in ((point_env, "point"), (env, "torsional")):
        e.reset(options={"grasp": 0})
        d = e.data
        d.ctrl[[4, 5, 10, 11]] -= 0.5  # f2, f4 flexion setpoints open
        for _ in range(20):
            e.step(np.zeros(12, dtype=np.float32))
        assert d.ncon == 2
        tips = [c.pos.copy() for c in d.contact[: d.ncon]]
        centre = d.qpos[ff.NQ : ff.NQ + 3]
        pairs = [(a, b) for i, a in enumerate(tips) for b in tips[i + 1 :]]
        a, b = max(pairs, key=lambda p: -np.dot(p[0] - centre, p[1] - centre))  # most opposed
        axis = (a - b) / np.linalg.norm(a - b)
        w_world = 6.0 * axis
        rot = d.xmat[e.model.body("object").id].reshape(3, 3)
        d.qvel[ff.NV + 3 : ff.NV + 6] = rot.T @ w_world  # free joint: local angular velocity
        for _ in range(20):
            e.step(np.zeros(12, dtype=np.float32))
        w = e.data.xmat[e.model.body("object").id].reshape(3, 3) @ d.qvel[ff.NV + 3 : ff.NV + 6]
        left[name] = abs(w @ axis) / 6.0
    assert left["point"] > 0.5 and left["torsional"] < 0.1


def test_no_contact_gives_zeros(env) -> None:
    env.reset(seed=1)
    m, d = env.model, env.data
    d.qpos[ff.NQ : ff.NQ + 3] = [0.0, 0.0, 0.5]  # object lifted clear of the hand
    mujoco.mj_forward(m, d)
    obs = env.observe()
    assert d.ncon == 0 or all(
        m.body("object").id not in (m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2])
        for c in d.contact[: d.ncon]
    )
    assert np.all(obs[24:] == 0.0)


def test_reward_sign_and_terms() -> None:
    """All four abduction setpoints stepped positive (a[j0] = +1) swing the fingertips
    counter-clockwise about +z and turn the held sphere with them: positive reward; the
    scripted reverse turns it back: negative. The reward equals the sum of the info terms."""
    e = FourFingerRotate(drop_weight=2.0, action_weight=0.1)
    obs, info = e.reset(seed=0, options={"grasp": 0})
    quat0 = e.data.qpos[ff.NQ + 3 : ff.NQ + 7].copy()
    act = np.zeros(12, dtype=np.float32)
    act[0::3] = 1.0
    fwd = []
    for _ in range(4):
        obs, r, term, trunc, info = e.step(act)
        assert not term
        assert r == pytest.approx(info["rotation"] + info["drop"] + info["action"], abs=1e-12)
        assert info["action"] == pytest.approx(-0.1 * 4 / 12)
        fwd.append(info["rotation"])
    assert sum(fwd) > 0.0 and min(fwd) > -0.05
    # the accumulated angle is the object's yaw change about world z (up to the small tilts
    # that make per-step z components differ from the yaw of the total rotation)
    quat = e.data.qpos[ff.NQ + 3 : ff.NQ + 7]
    rel = np.zeros(4)
    mujoco.mju_mulQuat(rel, quat, np.array([quat0[0], *(-quat0[1:])]))
    yaw = 2 * np.arctan2(rel[3], rel[0])
    assert yaw > 0.1 and info["rotation_angle"] == pytest.approx(yaw, rel=0.1)
    assert info["rotation_angle"] == pytest.approx(sum(fwd) * e.dt, rel=1e-9)
    back = [e.step(-act)[4]["rotation"] for _ in range(4)]
    assert sum(back) < 0.0


def test_yaw_rate_equals_mujocos_quaternion_velocity() -> None:
    """The float-arithmetic reward equals ``mju_quat2Vel(q1 * conj(q0), dt)[2]`` for small
    steps, large turns (past pi: the short way round) and no turn at all."""
    rng = np.random.default_rng(0)
    for i in range(500):
        q0 = rng.normal(size=4)
        q0 /= np.linalg.norm(q0)
        q1 = rng.normal(size=4) if i % 2 else q0 + 0.05 * rng.normal(size=4)
        q1 = q0 if i == 0 else q1 / np.linalg.norm(q1)
        inv, rel, vel = np.zeros(4), np.zeros(4), np.zeros(3)
        mujoco.mju_negQuat(inv, q0)
        mujoco.mju_mulQuat(rel, q1, inv)
        mujoco.mju_quat2Vel(vel, rel, 0.05)
        assert yaw_rate(q0, q1, 0.05) == pytest.approx(vel[2], rel=1e-9, abs=1e-12)


def test_mujoco_runs_the_documented_solver_settings(env) -> None:
    """What the docstring and README state is what MuJoCo simulates: PGS, tolerance 1e-4,
    2 ms x 25 substeps (a 0.05 s policy step), elliptic cone with impratio 100, no noslip."""
    opt = env.unwrapped.model.opt
    assert opt.solver == mujoco.mjtSolver.mjSOL_PGS
    assert opt.tolerance == SOLVER_TOLERANCE == 1e-4
    assert opt.timestep == TIMESTEP == 0.002 and env.unwrapped.frame_skip == FRAME_SKIP == 25
    assert env.unwrapped.dt == pytest.approx(0.05)
    assert opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and opt.impratio == 100.0
    assert opt.noslip_iterations == 0


def test_solver_tolerance_changes_nothing_the_policy_sees() -> None:
    """PGS stops at ``SOLVER_TOLERANCE`` instead of MuJoCo's 1e-8 (module doc, "Physics").
    One policy step from 48 states of random-action rollouts: the object's yaw rate (the
    reward) and position differ from the 1e-8 step by under 1 % of what halving the timestep
    changes (median and largest); 8 cached grasps held 10 s with zero actions end within
    0.01 rad (1e-3 rad/s of creep, 0.2 % of the rotation target) and 0.2 mm of the 1e-8
    hold. (1e-2 fails both, 1e-3 the first.)"""
    from envs.four_finger import policy_step_outcomes, save_state

    e = FourFingerRotate()
    m, d, ph = e.model, e.data, e.physics
    rng = np.random.default_rng(3)
    states = []
    for ep in range(4):
        e.reset(seed=ep)
        for _ in range(12):
            e.step(rng.uniform(-1, 1, 12).astype(np.float32))
            d.ctrl[:] = np.clip(d.ctrl + rng.uniform(-0.05, 0.05, 12), ph.ctrl_lo, ph.ctrl_hi)
            states.append(save_state(e))

    def policy_step(timestep: float, tol: float) -> np.ndarray:
        return policy_step_outcomes(e, states, timestep, round(e.dt / timestep), "pgs", tol)

    shipped, exact = policy_step(TIMESTEP, SOLVER_TOLERANCE), policy_step(TIMESTEP, 1e-8)
    fine = policy_step(TIMESTEP / 2, 1e-8)
    for cols in (slice(0, 1), slice(1, 4)):  # yaw rate [rad/s], position [mm]
        by_tol = np.linalg.norm(shipped[:, cols] - exact[:, cols], axis=1)
        by_dt = np.linalg.norm(fine[:, cols] - exact[:, cols], axis=1)
        assert np.median(by_tol) < 0.01 * np.median(by_dt), (np.median(by_tol), np.median(by_dt))
        assert by_tol.max() < 0.01 * by_dt.max(), (by_tol.max(), by_dt.max())

    m.opt.timestep = TIMESTEP

    def hold(tol: float) -> np.ndarray:
        m.opt.tolerance = tol
        out = []
        for i in range(8):
            e.reset(options={"grasp": i})
            for _ in range(200):
                info = e.step(np.zeros(12, dtype=np.float32))[4]
            out.append([info["rotation_angle"], *ph.object_pos()])
        return np.array(out)

    diff = np.abs(hold(SOLVER_TOLERANCE) - hold(1e-8))
    assert diff[:, 0].max() < 0.01, diff[:, 0]
    assert np.linalg.norm(diff[:, 1:], axis=1).max() < 2e-4, diff[:, 1:]
    e.close()


# the cylinder's run builds its own 256-grasp start cache on a cold cache: the slow tier
@pytest.mark.parametrize("obj", ["sphere", pytest.param("cylinder", marks=pytest.mark.slow)])
def test_explicit_pairs_simulate_the_scene_unchanged(obj) -> None:
    """The env's speed-up (module doc, "Physics"): the scene's contacts as explicit pairs give
    the same contacts in the same order, with the same parameters, and the same motion bit
    for bit as the scene's own broadphase (600 policy steps). From the same state
    each policy step, with random setpoints large enough to reach finger-finger, palm and
    catch-plane contacts."""
    from envs.four_finger import Physics

    new = Physics(obj, True, TIMESTEP)
    old = Physics(obj, True, TIMESTEP, explicit_pairs=False)
    assert new.model.npair == 34 and old.model.npair == 0  # 10 with the object, 24 cross-finger
    assert new.model.opt.integrator == old.model.opt.integrator
    assert not new.model.geom_contype.any() and not new.model.geom_conaffinity.any()
    assert new.slot == old.slot
    cache = grasp_cache(obj, True)
    rng = np.random.default_rng(1)
    kinds, err = set(), []
    names = [old.model.geom(g).name for g in range(old.model.ngeom)]
    for ep in range(10):
        i = int(rng.integers(len(cache)))
        mujoco.mj_resetData(old.model, old.data)
        old.data.qpos[:], old.data.ctrl[:] = cache.qpos[i], cache.ctrl[i]
        for _ in range(60):
            step = rng.uniform(-1, 1, 12) * (0.15 if ep % 2 else 0.05)
            old.data.ctrl[:] = np.clip(old.data.ctrl + step, old.ctrl_lo, old.ctrl_hi)
            for f in ("qpos", "qvel", "qacc_warmstart", "ctrl"):
                getattr(new.data, f)[:] = getattr(old.data, f)
            mujoco.mj_step(new.model, new.data, nstep=FRAME_SKIP)
            mujoco.mj_step(old.model, old.data, nstep=FRAME_SKIP)
            err.append(np.abs(new.data.qpos - old.data.qpos).max())
            cn, co = new.data.contact, old.data.contact
            assert new.data.ncon == old.data.ncon
            np.testing.assert_array_equal(cn.geom, co.geom)  # the same order: the same PGS sweep
            for field in ("dim", "friction", "solref", "solreffriction", "solimp", "includemargin"):
                np.testing.assert_array_equal(getattr(cn, field), getattr(co, field), err_msg=field)
            kinds |= {tuple(sorted(names[g][:2] for g in pair)) for pair in co.geom.tolist()}
    assert max(err) == 0.0
    # what was covered: object-link, link-link (other finger), object-palm or catch plane
    links = {"f1", "f2", "f3", "f4"}
    assert any(a in links and b == "ob" for a, b in kinds)
    assert any(a in links and b in links and a != b for a, b in kinds)
    assert any("pa" in k or "fl" in k for k in kinds)


@pytest.mark.parametrize("filterparent", [True, False])
def test_dynamic_pairs_are_the_pairs_mujoco_collides(filterparent) -> None:
    """envs.four_finger.dynamic_pairs against MuJoCo's own broadphase on a model where every
    geom overlaps every other: a jointed chain (parent-child), a body welded to its parent,
    a free body, an <exclude>, contype/conaffinity that rule pairs out, with and without
    the filterparent rule. Scenes with mocap bodies are refused."""
    from envs.four_finger import dynamic_pairs

    flag = "" if filterparent else '<option><flag filterparent="disable"/></option>'
    xml = f"""<mujoco>{flag}<worldbody>
      <geom name="w" size="0.3"/>
      <body name="a"><joint type="hinge"/><geom size="0.3"/>
        <body name="b"><joint type="hinge"/><geom size="0.3"/>
          <body name="c"><geom size="0.3"/><geom size="0.3" contype="2" conaffinity="2"/></body>
        </body>
      </body>
      <body name="d"><freejoint/><geom size="0.3"/><geom size="0.3" contype="4" conaffinity="0"/>
      </body>
      <body name="e"><freejoint/><geom size="0.3"/></body>
    </worldbody><contact><exclude body1="d" body2="e"/></contact></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    got = {tuple(sorted(p)) for p in d.contact.geom.tolist()}
    assert got == set(dynamic_pairs(m))
    assert len(got) >= 5
    mocap = xml.replace('<body name="e"><freejoint/>', '<body name="e" mocap="true">')
    with pytest.raises(FourFingerError, match="mocap"):
        dynamic_pairs(mujoco.MjModel.from_xml_string(mocap))


def test_mixed_contact_parameters_are_mujocos() -> None:
    """envs.four_finger.mixed_contact against what MuJoCo puts on a dynamic contact, for
    geoms of equal and of different priority, solmix weights and both solref formats."""
    from envs.four_finger import mixed_contact

    cases = [
        ('priority="1" friction="0.7 0.01 0.001" condim="3"', 'friction="1.2 0.02 0" condim="6"'),
        ('solmix="3" solref="0.02 0.8" solimp="0.8 0.95 0.002 0.5 2" condim="4"',
         'solmix="1" solref="0.01 1.2" solimp="0.9 0.99 0.001 0.4 3" friction="0.3 0.2 0.1"'),
        ('solref="-1000 -20"', 'solref="-500 -40"'),
        ('solmix="0"', 'solmix="2" solref="0.05 1"'),
    ]  # fmt: skip
    for a, b in cases:
        xml = f"""<mujoco><worldbody>
          <body><freejoint/><geom name="a" size="0.05" {a}/></body>
          <body pos="0 0 0.09"><freejoint/><geom name="b" size="0.05" {b}/></body>
        </worldbody></mujoco>"""
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        assert d.ncon == 1
        c, want = d.contact[0], mixed_contact(m, 0, 1)
        assert c.dim == want["condim"]
        np.testing.assert_allclose(c.friction, want["friction"], rtol=1e-12)
        np.testing.assert_allclose(c.solref, want["solref"], rtol=1e-12)
        np.testing.assert_allclose(c.solimp, want["solimp"], rtol=1e-12)
    # margins and gaps: mixed differently by MuJoCo versions, refused
    m = mujoco.MjModel.from_xml_string(xml.replace('size="0.05"', 'size="0.05" margin="0.01"'))
    with pytest.raises(FourFingerError, match="margin or gap"):
        mixed_contact(m, 0, 1)


def test_drop_terminates_with_the_penalty() -> None:
    e = FourFingerRotate(drop_weight=3.0)
    e.reset(seed=0)
    e.data.qpos[ff.NQ + 2] = DROP_Z - 0.01  # object below the drop height
    mujoco.mj_forward(e.model, e.data)
    act = np.zeros(12, dtype=np.float32)
    act[1::3] = -1.0  # open
    _, r, term, trunc, info = e.step(act)
    assert term and not trunc and info["dropped"]
    assert info["drop"] == -3.0
    assert r == pytest.approx(info["rotation"] - 3.0)


def test_resets_hold_with_zero_actions() -> None:
    """With gravity on, the object stays in the hand for 40 steps from >= 95% of resets."""
    e = FourFingerRotate()
    held = 0
    n = 60
    zero = np.zeros(12, dtype=np.float32)
    for i in range(n):
        e.reset(seed=1000 + i)
        p0 = e.data.qpos[ff.NQ : ff.NQ + 3].copy()
        ok = True
        for _ in range(40):
            _, _, term, _, _ = e.step(zero)
            if term:
                ok = False
                break
        held += ok and np.linalg.norm(e.data.qpos[ff.NQ : ff.NQ + 3] - p0) < 5e-3
    assert held / n >= 0.95


def test_grasp_cache_is_varied_and_reloads(tmp_path, monkeypatch) -> None:
    """The generator's grasps differ (yaw, abduction, squeeze, 3- and 4-finger), the disk
    cache returns the same arrays, and each cached grasp holds (checked on a sample)."""
    monkeypatch.setenv("IHM_CACHE", str(tmp_path))
    c = generate_grasps("cube", True, 12, seed=5)
    assert len(c) == 12 and c.candidates >= 12
    assert np.ptp(c.qpos[:, 0:12:3]) > 0.2  # abduction varies
    assert np.ptp(c.ctrl[:, 1::3] - c.qpos[:, 1:12:3]) > 0.02  # flexion squeeze varies
    grasps = grasp_cache("cylinder", False, 6)
    assert (tmp_path / "grasps").is_dir() and len(list((tmp_path / "grasps").glob("*.npz"))) == 1
    from envs.four_finger import cache

    cache._MEMORY.clear()  # white-box: force the disk read
    again = grasp_cache("cylinder", False, 6)
    np.testing.assert_array_equal(grasps.qpos, again.qpos)
    e = FourFingerRotate(object="cylinder", gravity=False, n_grasps=6)
    assert np.all(e.model.opt.gravity == 0.0)
    for i in range(len(e.grasps)):
        e.reset(options={"grasp": i})
        for _ in range(VERIFY_STEPS):
            assert not e.step(np.zeros(12, dtype=np.float32))[2]


def test_start_grasps_hold_the_object_clear_of_the_drop_line(tmp_path, monkeypatch) -> None:
    """Every kept grasp starts with the object's centre at least ``START_CLEARANCE`` (10 mm)
    above ``DROP_Z``. Before that condition the cube's 51st nominal test grasp (generator
    seed ``GRASP_SETS["test"]``) started 1.6 mm above it, the cube low and tilted: any
    motion counted as a drop. The object's height is read back from MuJoCo after a reset."""
    from envs.four_finger import DROP_Z
    from envs.four_finger.cache import GRASP_SETS, START_CLEARANCE

    monkeypatch.setenv("IHM_CACHE", str(tmp_path))
    c = generate_grasps("cube", True, 52, seed=GRASP_SETS["test"])
    e = FourFingerRotate(object="cube", n_grasps=52)
    e.grasps = c
    e.reset(seed=0)
    z = []
    for i in range(len(c)):
        e.reset(options={"grasp": i})
        z.append(float(e.physics.object_pos()[2]))
    assert min(z) >= DROP_Z + START_CLEARANCE
    assert np.median(z) > 0.075  # held high, as the sphere's are (about 0.077 m)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"object": "teapot"}, "unknown object 'teapot'"),
        ({"gravity": "yes"}, "gravity must be True or False"),
        ({"max_setpoint_step": -0.1}, "max_setpoint_step"),
        ({"frame_skip": 0}, "frame_skip"),
        ({"render_mode": "human"}, "render_mode"),
        ({"solver": "magic"}, "unknown solver"),
    ],
)
def test_bad_options(kwargs, message) -> None:
    with pytest.raises(FourFingerError, match=message):
        FourFingerRotate(**kwargs)


def test_bad_actions(env) -> None:
    env.reset(seed=0)
    with pytest.raises(FourFingerError, match=r"shape \(12,\)"):
        env.step(np.zeros(11))
    bad = np.zeros(12)
    bad[3] = np.nan
    with pytest.raises(FourFingerError, match="NaN"):
        env.step(bad)
    with pytest.raises(FourFingerError, match="grasp"):
        env.reset(options={"grasp": 10_000})


def test_setpoint_step_is_clipped(env) -> None:
    env.reset(seed=2)
    before = env.data.ctrl.copy()
    act = np.full(12, 5.0, dtype=np.float32)  # clipped to 1: +0.05 rad, within ctrlrange
    env.step(act)
    hi = env.model.actuator_ctrlrange[:, 1]
    np.testing.assert_allclose(env.data.ctrl, np.minimum(before + 0.05, hi), atol=1e-12)


def test_rgb_array_render() -> None:
    from ihm.render import RenderError

    e = FourFingerRotate(render_mode="rgb_array", width=96, height=64)
    e.reset(seed=0)
    try:
        img = e.render()
    except RenderError as exc:
        pytest.skip(f"no offscreen OpenGL here: {exc}")
    assert img.shape == (64, 96, 3) and img.dtype == np.uint8
    assert img.std() > 5  # not blank
    e.close()
