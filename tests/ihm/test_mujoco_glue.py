"""ihm glue against MuJoCo itself: kinematics (G, J) by finite differences through
MuJoCo's forward kinematics, statics (G c + w_g = 0, J^T c = R f) with the forces
MuJoCo computes, frame conventions, and bad input.

The finite differences never use our G or J: they move the object (or one
independent hand coordinate) in ``qpos``, let ``mj_kinematics`` place the
bodies, and measure how the material contact points moved.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from conftest import THESIS_SCENES

import ihm
from ihm.contacts import SceneGrasp, grasp_from_mujoco, hand_coordinates
from ihm.scenes import SceneError, SettleOptions, load_scene, settle
from stability import GraspError

SCENES = ihm.available_scenes()
EPS = 1e-6  # finite-difference step [m, rad]

# Two fingers squeeze a box under gravity: a slide finger (capsule) and a finger
# of two hinges coupled 1:2 by a joint equality (capsule + sphere tip). Capsules
# and the box meet with the object as MuJoCo's geom2, the sphere tip with the
# object as geom1 in the sphere variant, which exercises the frame flip.
TOY = """
<mujoco model="toy">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" jacobian="dense" cone="elliptic" integrator="implicitfast"
          noslip_iterations="20"/>
  <default>
    <geom contype="0" conaffinity="1" mass="0.05"/>
  </default>
  <worldbody>
    <body name="left" pos="-0.05 0 0" gravcomp="1">
      <joint name="lslide" type="slide" axis="1 0 0" damping="1"/>
      <geom name="lpad" type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01"/>
    </body>
    <body name="rbase" pos="0.05 0 -0.06" gravcomp="1">
      <joint name="r1" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.004" contype="0" conaffinity="0"/>
      <body name="rtip" pos="0 0 0.03" gravcomp="1">
        <joint name="r2" type="hinge" axis="0 1 0" damping="0.1"/>
        <geom name="rpad" type="capsule" fromto="0 0 0.02 0 0 0.07" size="0.01"/>
      </body>
    </body>
    <body name="object" pos="0 0 0">
      <freejoint name="object"/>
      OBJECT
    </body>
  </worldbody>
  <equality>
    <joint joint1="r2" joint2="r1" polycoef="0 0.5 0 0 0"/>
  </equality>
  <actuator>
    <motor name="lm" joint="lslide"/>
    <motor name="rm" joint="r1"/>
  </actuator>
</mujoco>
"""
BOX = (
    '<geom name="obox" type="box" size="0.03 0.03 0.03" mass="0.1" contype="1" '
    'conaffinity="0" friction="1"/>'
)
SPHERE = (
    '<geom name="osph" type="sphere" size="0.035" mass="0.1" contype="1" '
    'conaffinity="0" friction="1"/>'
)


def toy(obj: str = BOX) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(TOY.replace("OBJECT", obj))
    data = mujoco.MjData(model)
    settle(model, data, [4.0, -0.3])
    return model, data


_CACHE: dict[str, tuple] = {}
TOYS = {"toy-box": BOX, "toy-sphere": SPHERE}


def _settled(name: str) -> tuple:
    """(model, data, grasp) of a toy variant or a thesis scene, settled once per session."""
    if name not in _CACHE:
        model, data = toy(TOYS[name]) if name in TOYS else load_scene(name)
        _CACHE[name] = (model, data, grasp_from_mujoco(model, data))
    return _CACHE[name]


@pytest.fixture(scope="module", params=list(TOYS))
def toy_grasp(request):
    return _settled(request.param)


@pytest.fixture(scope="module", params=[*TOYS, *SCENES])
def case(request):
    """The toy hand (a case small enough to reason about) and every thesis scene."""
    return _settled(request.param)


# -- finite differences through MuJoCo --------------------------------------------------
def _material_points(model, data, body_ids, points_world, qpos):
    """World positions, at configuration ``qpos``, of the points ``points_world``
    (taken at ``data``'s configuration) carried along with bodies ``body_ids``."""
    local = [
        data.xmat[b].reshape(3, 3).T @ (p - data.xpos[b])
        for b, p in zip(body_ids, points_world, strict=True)
    ]
    d2 = mujoco.MjData(model)
    d2.qpos[:] = qpos
    mujoco.mj_kinematics(model, d2)
    return np.array(
        [d2.xpos[b] + d2.xmat[b].reshape(3, 3) @ q for b, q in zip(body_ids, local, strict=True)]
    )


def _object_fd(model, data, g: SceneGrasp, r: np.ndarray) -> np.ndarray:
    """Contact-point motion (stacked, contact frames) for object motion r = (v, w),
    both in the object frame, by central differences of MuJoCo's kinematics."""
    obj = model.body("object").id
    jnt = model.body_jntadr[obj]
    dof = model.jnt_dofadr[jnt]
    qvel = np.zeros(model.nv)
    qvel[dof : dof + 3] = g.object_mat @ r[:3]  # free joint: linear part in world
    qvel[dof + 3 : dof + 6] = r[3:]  # angular part in the body frame
    pts = g.points_world()
    ids = [obj] * g.m
    moved = []
    for s in (+1.0, -1.0):
        q = data.qpos.copy()
        mujoco.mj_integratePos(model, q, qvel, s * EPS)
        moved.append(_material_points(model, data, ids, pts, q))
    disp = (moved[0] - moved[1]) / (2 * EPS)
    return np.einsum("mkj,mj->mk", g.frames_world(), disp).reshape(-1)


def _hand_fd(model, data, g: SceneGrasp, k: int) -> np.ndarray:
    """Hand contact-point motion (stacked, contact frames) for unit speed of
    independent hand coordinate k, by central differences of MuJoCo's kinematics."""
    qvel = np.zeros(model.nv)
    qvel[g.hand_dofs] = g.T[:, k]
    pts = g.points_world()
    moved = []
    for s in (+1.0, -1.0):
        q = data.qpos.copy()
        mujoco.mj_integratePos(model, q, qvel, s * EPS)
        moved.append(_material_points(model, data, list(g.hand_bodies), pts, q))
    disp = (moved[0] - moved[1]) / (2 * EPS)
    return np.einsum("mkj,mj->mk", g.frames_world(), disp).reshape(-1)


def _check_kinematics(model, data, g: SceneGrasp, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(4):
        r = rng.normal(size=6)
        pred = g.G.T @ r
        fd = _object_fd(model, data, g, r)
        assert np.linalg.norm(fd - pred) <= 1e-4 * np.linalg.norm(pred), (fd, pred)
    for k in range(g.J.shape[1]):
        pred = g.J[:, k]
        fd = _hand_fd(model, data, g, k)
        scale = max(np.linalg.norm(pred), np.linalg.norm(fd))
        if scale == 0.0:
            continue  # a joint that moves no contact (e.g. an unloaded finger)
        assert np.linalg.norm(fd - pred) <= 1e-4 * scale, (k, g.joint_names[k], fd, pred)


def _check_statics(g: SceneGrasp) -> None:
    c = g.forces.reshape(-1)
    load = np.abs(g.forces).max() + np.abs(g.gravity_wrench[:3]).max()
    res = g.equilibrium_residuals()
    # MuJoCo's soft constraints at rest leave residual accelerations of order
    # vtol / timestep on the light bodies; 1e-3 of the load is far above that
    # and far below any sign or frame error (which would be O(load)).
    assert res["object"] <= 1e-3 * load, res
    assert res["hand"] <= 1e-3 * load, res
    # the same, written out: G c + w_g = 0 and J^T c = R f
    assert np.allclose(g.G @ c, -g.gravity_wrench, atol=1e-3 * load)
    assert np.allclose(g.J.T @ c, g.R @ g.actuator_forces, atol=1e-3 * load)


def _check_frames(model, data, g: SceneGrasp) -> None:
    F = g.frames
    assert np.allclose(F @ F.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.all(np.linalg.det(F) > 0)
    # convex object geoms: the inward normal points from the contact toward the geom centre
    centre = data.geom_xpos[g.object_geoms]
    n_world = g.frames_world()[:, 0]
    inward = np.einsum("mj,mj->m", n_world, centre - g.points_world())
    assert np.all(inward > 0), inward
    # the hand pushes, never pulls
    assert np.all(g.forces[:, 0] >= -1e-9), g.forces[:, 0]
    # Coulomb: MuJoCo's forces lie in the (elliptic) friction cone
    tang = np.linalg.norm(g.forces[:, 1:], axis=1)
    assert np.all(tang <= g.mu * g.forces[:, 0] * (1 + 1e-6) + 1e-9)


# -- conventions, on the toy hand and every scene ----------------------------------------
def test_kinematics(case):
    model, data, g = case
    _check_kinematics(model, data, g)


def test_statics(case):
    _, _, g = case
    _check_statics(g)


def test_frames(case):
    model, data, g = case
    _check_frames(model, data, g)


def test_toy_squeezed(toy_grasp):
    _, _, g = toy_grasp
    assert g.forces[:, 0].sum() > 1.0  # the 4 N slide motor loads the box


def test_toy_coupled_joints():
    """r2 = 0.5 r1: two independent coordinates, T = [[1,0],[0,1],[0,0.5]], R = I."""
    model, data = toy()
    dofs, T, names = hand_coordinates(model, data)
    assert names == ["lslide", "r1"]
    assert np.array_equal(T, [[1, 0], [0, 1], [0, 0.5]])
    g = grasp_from_mujoco(model, data)
    assert np.array_equal(g.R, np.eye(2))
    assert np.allclose(g.commands, [4.0, -0.3])


def test_toy_object_geom_order():
    """The sphere object is MuJoCo's geom1 against capsule pads (type order), the box
    its geom2: both must give inward normals and pushing forces."""
    for obj, first in ((SPHERE, True), (BOX, False)):
        model, data = toy(obj)
        g = grasp_from_mujoco(model, data)
        for ids, geom in zip(g.contact_ids, g.object_geoms, strict=True):
            assert bool(data.contact[ids[0]].geom1 == geom) is first
        assert np.all(g.forces[:, 0] > 0)


def test_nonlinear_coupling_linearized():
    """r2 = 0.5 r1 + 0.1 r1^2 enters through its derivative at the state: T[r2, r1] =
    0.5 + 0.2 r1 (a small-motion model, as for a four-bar's connect equality)."""
    xml = TOY.replace("OBJECT", BOX).replace('polycoef="0 0.5 0 0 0"', 'polycoef="0 0.5 0.1 0 0"')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    r1 = model.joint("r1").qposadr[0]
    data.qpos[r1] = 0.3
    mujoco.mj_forward(model, data)
    _, T, names = hand_coordinates(model, data)
    assert names == ["lslide", "r1"]
    assert T[2, 1] == pytest.approx(0.5 + 0.2 * 0.3, rel=1e-9)


# -- the thesis scenes ------------------------------------------------------------------
def test_scenes_exist():
    assert set(THESIS_SCENES) <= set(SCENES)


@pytest.mark.parametrize("name", SCENES)
def test_scene_at_rest_limits_are_stops(name):
    """At rest; in the thesis' scenes no joint limit takes load; where one does (the
    linkage gripper's couplers) it is a stop column of R carrying MuJoCo's limit force,
    so that J^T c = R f holds."""
    model, data, g = _settled(name)
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    rows = np.flatnonzero(data.efc_type[: data.nefc] == limit)
    loaded = rows[data.efc_force[rows] > 1e-9]
    if name in THESIS_SCENES:
        assert loaded.size == 0
    col = dict(zip(g.actuator_names, g.actuator_forces, strict=True))
    for r in loaded:
        assert col[f"limit:{model.joint(data.efc_id[r]).name}"] == pytest.approx(
            data.efc_force[r], rel=1e-12
        )


# -- bad input --------------------------------------------------------------------------
def test_unknown_scene_lists_known():
    with pytest.raises(SceneError, match="unknown scene 'no_such_scene'") as exc:
        load_scene("no_such_scene")
    for name in SCENES:
        assert name in str(exc.value)


def test_missing_object_body():
    model, data = toy()
    with pytest.raises(GraspError, match="no body named 'cup'.*object"):
        grasp_from_mujoco(model, data, object_body="cup")


def test_no_contacts():
    model, data = toy()
    jnt = model.joint("object").qposadr[0]
    data.qpos[jnt + 2] += 1.0  # lift the box 1 m out of the hand
    mujoco.mj_forward(model, data)
    with pytest.raises(GraspError, match="no active contact"):
        grasp_from_mujoco(model, data)


def test_bad_preload():
    name = SCENES[0] if SCENES else pytest.skip("no scenes yet")
    model, _ = load_scene(name, settle_grasp=False)
    with pytest.raises(SceneError, match=f"needs {model.nu} actuator forces"):
        load_scene(name, preload=np.ones(model.nu + 1))
    with pytest.raises(SceneError, match="NaN"):
        load_scene(name, preload=np.full(model.nu, np.nan))


def test_bad_settle_arguments():
    model = mujoco.MjModel.from_xml_string(TOY.replace("OBJECT", BOX))
    data = mujoco.MjData(model)
    with pytest.raises(SceneError, match="rounds"):
        settle(model, data, [4.0, -0.3], options=SettleOptions(rounds=0))
    with pytest.raises(SceneError, match="vtol"):
        settle(model, data, [4.0, -0.3], options=SettleOptions(vtol="x"))
    with pytest.raises(SceneError, match="actuator forces must be 2 numbers"):
        settle(model, data, ["a", "b"])
    name = SCENES[0]
    with pytest.raises(SceneError, match="actuator forces must be"):
        load_scene(name, preload="abc")
    with pytest.raises(SceneError, match="actuator forces must be"):
        load_scene(name, preload={"x": 1})


def test_condim():
    """condim 1 is frictionless (mu = 0 whatever the geoms' friction); torsional or
    rolling friction (condim 4, 6) is not in the point-contact model and is refused."""
    model, data = toy()
    g3 = grasp_from_mujoco(model, data)
    assert np.all(g3.mu == 1.0)
    for dim in range(data.ncon):
        data.contact.dim[dim] = 1
    g1 = grasp_from_mujoco(model, data)
    assert np.all(g1.mu == 0.0) and g1.m == g3.m
    data.contact.dim[0] = 4
    with pytest.raises(GraspError, match="condim 4"):
        grasp_from_mujoco(model, data)
