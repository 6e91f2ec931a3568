"""Four-finger hand (thesis ch. 7, fig. ffh): model against its constants module, joint
sign conventions, and the three fingertip grasps (sphere, cylinder, cube) after settling."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm.scenes
from ihm.contacts import grasp_from_mujoco, hand_coordinates, transmission
from ihm.hands import four_finger as ff

SCENES = ("four_finger_sphere", "four_finger_cylinder", "four_finger_cube")


@pytest.fixture(scope="module")
def hand():
    model = mujoco.MjModel.from_xml_path(str(ff.XML))
    return model, mujoco.MjData(model)


_CACHE: dict[str, tuple] = {}


@pytest.fixture(scope="module", params=SCENES)
def scene(request):
    name = request.param
    if name not in _CACHE:
        scene = ihm.scenes.load_scene(name)
        model, data, info = scene.model, scene.data, scene.settle_info
        _CACHE[name] = (name, model, data, grasp_from_mujoco(model, data), info)
    return _CACHE[name]


# -- the model ---------------------------------------------------------------------------
def test_counts_and_names(hand):
    model, _ = hand
    assert (model.nq, model.nv, model.nu, model.ntendon) == (ff.NQ, ff.NV, ff.NU, ff.NTENDON)
    assert model.ngeom == ff.NGEOM
    assert [model.joint(j).name for j in range(model.njnt)] == list(ff.JOINT_NAMES)
    assert [model.actuator(a).name for a in range(model.nu)] == list(ff.ACTUATOR_NAMES)
    assert len(ff.TENDON_NAMES) == model.ntendon
    for a, j in zip(ff.ACTUATOR_NAMES, ff.JOINT_NAMES, strict=True):
        assert model.actuator_trnid[model.actuator(a).id, 0] == model.joint(j).id


def test_servos_and_ranges(hand):
    model, _ = hand
    assert np.all(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
    assert np.allclose(model.jnt_range, ff.JOINT_RANGES)
    assert np.all(model.jnt_limited)
    # position servos: force = KP (ctrl - q), ctrl limited to the joint range
    assert np.allclose(model.actuator_gainprm[:, 0], ff.KP)
    assert np.allclose(model.actuator_biasprm[:, :3], [0.0, -ff.KP, 0.0])
    gain, bias = ihm.scenes._affine(model)  # settle's reading: force = g ctrl + b0 + b1 L
    assert np.allclose(gain[:, 0], ff.KP) and np.allclose(-bias[:, 1], ff.KP)
    assert np.allclose(model.actuator_ctrlrange, ff.JOINT_RANGES)
    assert np.allclose(model.actuator_forcerange, [-ff.FORCE_LIMIT, ff.FORCE_LIMIT])
    assert np.allclose(model.dof_damping, ff.DAMPING)
    assert np.all(model.dof_frictionloss == 0.0)
    lo, hi = ff.JOINT_RANGES.T
    assert np.all((ff.DEFAULT_POSE > lo) & (ff.DEFAULT_POSE < hi))


def test_bodies_and_collision_geoms(hand):
    model, _ = hand
    assert np.all(model.body_gravcomp[1:] == 1.0)
    assert model.body(f"{ff.FINGERS[0]}_base").parentid[0] != 0  # fixed to the palm, no free joint
    coll = [g for g in range(model.ngeom) if model.geom_conaffinity[g] or model.geom_contype[g]]
    finger = [g for g in coll if model.body(model.geom_bodyid[g]).name in ff.BODY_NAMES]
    fixed = [g for g in coll if g not in finger]
    assert {model.body(model.geom_bodyid[g]).name for g in finger} == set(ff.BODY_NAMES)
    assert {model.geom(g).name for g in fixed} == {"palm", "floor"}
    # fingers collide with objects (contype 1) and each other; palm and floor with objects only
    assert np.all(model.geom_contype[finger] == 2) and np.all(model.geom_conaffinity[finger] == 3)
    assert np.all(model.geom_contype[fixed] == 0) and np.all(model.geom_conaffinity[fixed] == 1)
    types = {int(model.geom_type[g]) for g in range(model.ngeom)}
    assert types <= {
        int(t)
        for t in (
            mujoco.mjtGeom.mjGEOM_PLANE,
            mujoco.mjtGeom.mjGEOM_CAPSULE,
            mujoco.mjtGeom.mjGEOM_SPHERE,
            mujoco.mjtGeom.mjGEOM_CYLINDER,
            mujoco.mjtGeom.mjGEOM_BOX,
        )
    }


def test_fingers_collide_with_each_other(hand):
    """Curled fingers swung sideways (abduction 0.4 rad commanded on f1 and f2) touch their
    neighbours instead of passing through: MuJoCo reports contacts between different fingers
    only, and they stop the abduction short of the setpoint (without finger-finger collision
    the joints reach it: 0.4 rad)."""
    model, _ = hand
    data = mujoco.MjData(model)
    q = np.tile([0.0, 1.2, 1.4], 4)  # curled in, tips near the palm centre
    data.qpos[:] = q
    data.ctrl[:] = q
    data.ctrl[0], data.ctrl[3] = 0.4, -0.4  # f1 toward f2, f2 toward f1
    for _ in range(1000):
        mujoco.mj_step(model, data)
    pairs = {
        tuple(sorted(model.body(model.geom_bodyid[g]).name[:2] for g in (c.geom1, c.geom2)))
        for c in data.contact[: data.ncon]
    }
    assert data.ncon > 0 and all(a != b for a, b in pairs)  # contacts between different fingers
    assert abs(data.qpos[0]) < 0.3 and abs(data.qpos[3]) < 0.3  # blocked
    assert min(c.dist for c in data.contact[: data.ncon]) > -ff.LINK_RADIUS  # soft skin only


def test_dropped_object_lands_on_palm():
    """Without the fingers' grip the sphere falls onto the palm disc and rests there."""
    model, data = ihm.scenes.load_scene("four_finger_sphere", settle_grasp=False)
    data.qpos[: ff.NQ] = np.tile([0.0, -0.5, 0.0], 4)  # fingers open wide
    data.ctrl[:] = data.qpos[: ff.NQ]
    for _ in range(2000):
        mujoco.mj_step(model, data)
    z = data.body("object").xpos[2]
    assert z == pytest.approx(0.035, abs=1e-3)  # sphere radius above the palm top at z = 0
    assert np.abs(data.qvel[ff.NV :]).max() < 1e-2


def _tips(model, data, q):
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    tip = np.array([0.0, 0.0, ff.DISTAL_LENGTH])
    return np.array(
        [
            data.xpos[model.body(b).id] + data.xmat[model.body(b).id].reshape(3, 3) @ tip
            for b in ff.DISTAL_BODY_NAMES
        ]
    )


def test_dimensions_and_symmetry(hand):
    model, data = hand
    tips = _tips(model, data, ff.DEFAULT_POSE)
    r = np.hypot(tips[:, 0], tips[:, 1])
    assert np.allclose(r, r[0]) and np.allclose(tips[:, 2], tips[0, 2])
    # planar 2-link kinematics of one finger in its radial plane
    q1, q2 = ff.DEFAULT_FINGER_POSE[1:]
    r_expect = (
        ff.FINGER_BASE_RADIUS - ff.PROXIMAL_LENGTH * np.sin(q1) - ff.DISTAL_LENGTH * np.sin(q1 + q2)
    )
    z_expect = ff.PROXIMAL_LENGTH * np.cos(q1) + ff.DISTAL_LENGTH * np.cos(q1 + q2)
    assert np.allclose(r, r_expect) and np.allclose(tips[:, 2], z_expect)
    azimuth = np.arctan2(tips[:, 1], tips[:, 0]) % (2 * np.pi)
    assert np.allclose(azimuth, ff.FINGER_AZIMUTHS, atol=1e-9)


@pytest.mark.parametrize("joint", [0, 1, 2])
def test_sign_convention(hand, joint):
    """Positive flexion closes (tips toward the palm axis); positive abduction turns every
    tip counter-clockwise about +z."""
    model, data = hand
    tips0 = _tips(model, data, ff.DEFAULT_POSE)
    dq = np.zeros(12)
    dq[joint::3] = 1e-3
    tips1 = _tips(model, data, ff.DEFAULT_POSE + dq)
    d = tips1 - tips0
    radial = tips0[:, :2] / np.linalg.norm(tips0[:, :2], axis=1, keepdims=True)
    tangential = np.stack([-radial[:, 1], radial[:, 0]], axis=1)
    d_rad = np.einsum("mj,mj->m", d[:, :2], radial)
    d_tan = np.einsum("mj,mj->m", d[:, :2], tangential)
    if joint == 0:
        assert np.all(d_tan > 0.5e-3 * ff.PROXIMAL_LENGTH)
        assert np.allclose(d_rad, 0.0, atol=1e-7)
    else:
        assert np.all(d_rad < -0.5e-3 * ff.DISTAL_LENGTH)
        assert np.allclose(d_tan, 0.0, atol=1e-12)


def test_fully_actuated_transmission():
    model, data = ihm.scenes.load_scene(SCENES[0], settle_grasp=False)
    dofs, T, names = hand_coordinates(model, data)
    assert names == list(ff.JOINT_NAMES) and np.array_equal(T, np.eye(12))
    assert np.allclose(transmission(model, data)[:, dofs], np.eye(12))  # R = identity


# -- the scenes --------------------------------------------------------------------------
@pytest.mark.parametrize("name", SCENES)
def test_scene_file(name):
    model, data = ihm.scenes.load_scene(name, settle_grasp=False)
    assert model.nu == ff.NU and model.ngeom == ff.NGEOM + 1
    assert np.allclose(data.qpos[: ff.NQ], ff.DEFAULT_POSE)  # the keyframe's hand pose
    assert data.ncon == 0  # hand slightly open: tips off the object
    assert np.allclose(model.body("object").mass, 0.1)
    assert np.allclose(model.opt.gravity, [0.0, 0.0, -9.81])
    pre = ihm.scenes.default_preload(model).reshape(4, 3)
    assert np.all(pre[:, 0] == 0.0) and np.all(pre[:, 1:] > 0.0)  # squeeze: closing torques
    assert np.allclose(pre, pre[0])  # the same on every finger
    assert ihm.scenes.scene_about(name)


def test_scene_settles_fast(scene):
    """Within 3 s of simulated time (the wall time is a benchmark's, not a test's: it
    doubled on a shared machine)."""
    _, model, data, _, info = scene
    assert info.time_s < 3.0 and info.steps < 3000
    assert np.abs(data.qvel).max() < 1e-3
    lo, hi = ff.JOINT_RANGES.T
    q = data.qpos[: ff.NQ]
    assert np.all((q > lo + 0.05) & (q < hi - 0.05))  # no joint limit near, let alone active
    # the commanded squeeze, plus the object's weight carried by the series-elastic springs:
    # at most mg / 4 at a lever of one finger length per joint
    mg = 9.81 * 0.1
    assert np.abs(data.actuator_force - info.commands).max() < mg / 4 * 0.1


def test_scene_contacts(scene):
    """One fingertip contact per finger, on the distal links, pushing inward."""
    _, model, data, g, _ = scene
    assert g.m == 4
    assert sorted(model.body(b).name for b in g.hand_bodies) == sorted(ff.DISTAL_BODY_NAMES)
    assert np.all(g.forces[:, 0] > 0.5)  # the 1 N squeeze of ihm_preload
    assert np.allclose(g.forces[:, 0], g.forces[0, 0], rtol=1e-2)  # symmetric grasp
    n_world = g.frames_world()[:, 0]
    assert np.all(np.abs(n_world[:, 2]) < 0.1)  # near-horizontal normals (sides / equator)
    pts = g.points_world() - g.object_pos
    assert np.all(np.einsum("mj,mj->m", n_world[:, :2], pts[:, :2]) < 0)  # inward
    # friction carries the weight, inside the cone
    tang = np.linalg.norm(g.forces[:, 1:], axis=1)
    assert np.all(tang <= g.mu * g.forces[:, 0])
    assert np.isclose(g.forces_world()[:, 2].sum(), 9.81 * 0.1, rtol=1e-3)


def test_scene_statics(scene):
    _, _, _, g, _ = scene
    res = g.equilibrium_residuals()
    load = np.abs(g.forces).max()
    assert res["object"] < 1e-4 * load and res["hand"] < 1e-4 * load, res


def test_scene_object_frame_and_skin(scene):
    name, model, data, g, _ = scene
    # the object stays upright: its z axis is the vertical axis of the rotation task
    assert g.object_mat[2, 2] > 1 - 1e-6
    # skin: a few hundred to a few thousand N/m at the ~1 N grasp
    for i in range(data.ncon):
        f = np.zeros(6)
        mujoco.mj_contactForce(model, data, i, f)
        k = f[0] / -data.contact[i].dist
        assert 300.0 < k < 3000.0, (name, k)
