"""Barrett BH8-280 model (assets/barrett/bh280.xml) and its grasp scenes."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.contacts import grasp_from_mujoco, hand_coordinates
from ihm.hands import barrett


@pytest.fixture(scope="module")
def hand():
    model = mujoco.MjModel.from_xml_path(str(barrett.XML))
    return model, mujoco.MjData(model)


def test_counts_and_names(hand):
    model, _ = hand
    assert (model.nq, model.nv, model.nu, model.ntendon, model.ngeom) == (
        barrett.NQ,
        barrett.NV,
        barrett.NU,
        barrett.NTENDON,
        barrett.NGEOM,
    )
    assert tuple(model.joint(j).name for j in range(model.njnt)) == barrett.JOINT_NAMES
    assert tuple(model.actuator(a).name for a in range(model.nu)) == barrett.ACTUATOR_NAMES
    for b in barrett.BODY_NAMES:
        assert model.body(b).id >= 0
    for g in barrett.COLLISION_GEOM_NAMES:
        assert model.geom(g).conaffinity == 1 and model.geom(g).contype == 0
    assert np.all(model.body_gravcomp[1:] == 1.0)
    assert np.all(model.dof_frictionloss == 0.0)


def test_couplings_give_four_coordinates_and_identity_R(hand):
    """Spread mirror and distal = proximal / 3: l = 4 coordinates, R = I (4 x 4)."""
    model, data = ihm.load_scene("barrett_box", settle_grasp=False)
    dofs, T, names = hand_coordinates(model, data)
    assert tuple(names) == barrett.INDEPENDENT_JOINT_NAMES
    col = {n: k for k, n in enumerate(names)}
    expect = np.zeros((barrett.NV, barrett.N_INDEPENDENT))
    for r, j in enumerate(barrett.JOINT_NAMES):
        if j in col:
            expect[r, col[j]] = 1.0
    expect[barrett.JOINT_NAMES.index("f2_spread"), 0] = barrett.SPREAD_MIRROR
    for f in ("f1", "f2", "f3"):
        expect[barrett.JOINT_NAMES.index(f"{f}_dist"), col[f"{f}_prox"]] = barrett.COUPLING
    assert np.allclose(T, expect)


def test_coupling_holds_in_motion(hand):
    """Driving the motors moves the coupled joints as the equalities say (MuJoCo's
    equalities are soft: a few mrad of lag while the fingers accelerate)."""
    model, _ = hand
    data = mujoco.MjData(model)
    data.ctrl[:] = [0.05, 0.05, 0.05, 0.05]
    for _ in range(300):
        mujoco.mj_step(model, data)
    q = dict(zip(barrett.JOINT_NAMES, data.qpos, strict=True))
    assert q["f1_prox"] > 0.05 and q["f1_spread"] > 0.01
    assert q["f2_spread"] == pytest.approx(q["f1_spread"], abs=3e-3)
    for f in ("f1", "f2", "f3"):
        assert q[f"{f}_dist"] == pytest.approx(barrett.COUPLING * q[f"{f}_prox"], abs=3e-3)


def _settled(name: str, preload=None):
    model, data = ihm.load_scene(name, preload=preload)
    g = grasp_from_mujoco(model, data)
    links = sorted(model.body(b).name for b in g.hand_bodies)
    return model, data, g, links


def _check_rest(model, data, g) -> None:
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit), "a joint limit is active"
    assert np.all(g.forces[:, 0] >= -1e-9)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["object"] <= 1e-3 * load and res["hand"] <= 1e-3 * load, res
    assert np.allclose(g.R, np.eye(4))


def test_box_scene():
    """Grasp example 1: four contacts, inner and outer link of fingers 1 and 2, loaded."""
    model, data, g, links = _settled("barrett_box")
    _check_rest(model, data, g)
    assert links == ["f1_dist", "f1_prox", "f2_dist", "f2_prox"]
    assert np.all(g.forces[:, 0] > 0.1)
    # planar: contacts in the object xy-plane, normals in it too
    assert np.abs(g.points[:, 2]).max() < 1e-3
    assert np.abs(g.normals[:, 2]).max() < 1e-3
    # inner-link normals point into the box and toward the palm (+y): a -y pull is
    # resisted passively by the inner links
    prox = [k for k in range(g.m) if model.body(g.hand_bodies[k]).name.endswith("prox")]
    assert np.all(g.normals[prox, 1] > 0.05)
    # symmetric: the two opposing fingers carry the same load, link by link
    fn = {model.body(g.hand_bodies[k]).name: g.forces[k, 0] for k in range(g.m)}
    for link in ("prox", "dist"):
        assert fn[f"f1_{link}"] == pytest.approx(fn[f"f2_{link}"], rel=0.05)
    # honest geometry: no contact exclusion, and the box is clear of the palm face (z = 0)
    # and of the open thumb, whose bent outer link reaches x = -0.009
    assert model.nexclude == 0
    box = model.geom("object")
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    world = data.geom_xpos[box.id] + (corners * box.size) @ data.geom_xmat[box.id].reshape(3, 3).T
    assert world[:, 2].min() > 0.0005 and np.abs(world[:, 0]).max() < 0.008


def test_spread_is_a_stiff_servo():
    """The spread holds its angle (nonbackdrivable in the thesis): a position servo with
    kp = SPREAD_KP; the finger motors are torque motors (gain 1, no bias)."""
    model = mujoco.MjModel.from_xml_path(str(barrett.XML))
    a = model.actuator("spread").id
    assert model.actuator_gainprm[a, 0] == barrett.SPREAD_KP
    assert model.actuator_biasprm[a, 1] == -barrett.SPREAD_KP
    for name in ("f1", "f2", "f3"):
        i = model.actuator(name).id
        assert model.actuator_gainprm[i, 0] == 1.0
        assert not np.any(model.actuator_biasprm[i, :3])
