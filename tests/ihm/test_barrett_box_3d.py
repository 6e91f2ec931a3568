"""Scene barrett_box_3d (thesis grasp example 2, fig. 3dgrasp): a box held by the inner links
of the spread fingers 1 and 2 and the opposing thumb, one contact per finger, with finger 1's
contact closer to its flexion axis than finger 2's (the asymmetry behind the thesis'
finger-1-versus-finger-2 preload experiment)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.contacts import grasp_from_mujoco

LINKS = ("f1_prox", "f2_prox", "f3_prox")


@pytest.fixture(scope="module")
def settled():
    scene = ihm.load_scene("barrett_box_3d")
    model, data, info = scene.model, scene.data, scene.settle_info
    g = grasp_from_mujoco(model, data)
    links = [model.body(b).name for b in g.hand_bodies]
    contact = {name: links.index(name) for name in LINKS if name in links}
    return model, data, info, g, links, contact


def test_settles_at_rest_without_joint_limits(settled):
    model, data, info, g, _, _ = settled
    assert info.time_s < 5.0
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit), "a joint limit is active"
    # well inside the ranges, not just off the stops: proximal 0..2.44 rad
    for f in ("f1", "f2", "f3"):
        assert 0.1 < data.qpos[model.jnt_qposadr[model.joint(f"{f}_prox").id]] < 2.3
    # spread between 0 and 90 deg: fingers 1 and 2 face neither each other nor the thumb
    spread = data.qpos[model.jnt_qposadr[model.joint("f1_spread").id]]
    assert np.radians(20) < spread < np.radians(70)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["object"] <= 1e-3 * load and res["hand"] <= 1e-3 * load, res


def test_one_contact_per_finger_on_the_inner_links(settled):
    _, _, _, g, links, _ = settled
    assert sorted(links) == sorted(LINKS)  # no palm, no outer-link contact
    assert np.all(g.forces[:, 0] > 0.5)  # every finger pushes [N]
    assert all(len(ids) == 1 for ids in g.contact_ids)


def test_fingers_oppose_the_thumb_along_x(settled):
    """Normals (into the object) of fingers 1 and 2 point along -x, the thumb's along +x:
    their horizontal parts lie within 5 deg of the object x-axis, all tilted toward the
    palm (-z), which carries the weight (gravity +z, away from the palm)."""
    _, _, _, g, _, contact = settled
    for name, sign in (("f1_prox", -1.0), ("f2_prox", -1.0), ("f3_prox", 1.0)):
        n = g.normals[contact[name]]
        assert sign * n[0] > 0.8
        assert abs(n[1]) < np.tan(np.radians(5)) * abs(n[0])
        assert n[2] < 0.0
    # the contacts sit on the far edges of the box (object z = +half height 0.012 m)
    assert np.allclose(g.points[:, 2], 0.012, atol=1e-3)


def test_finger_1_has_the_smaller_flexion_moment_arm(settled):
    """J (normal row of contact k, column fK_prox) is the moment arm of contact k's normal
    force about finger k's flexion axis: finger 1 meets the yawed box edge obliquely and
    near its joint, so its arm is clearly smaller than finger 2's, and its normal has the
    larger arm about the (passive) spread axis, which then carries a reaction torque."""
    _, data, _, g, _, contact = settled
    col = {name: k for k, name in enumerate(g.joint_names)}
    arm1 = g.J[3 * contact["f1_prox"], col["f1_prox"]]
    arm2 = g.J[3 * contact["f2_prox"], col["f2_prox"]]
    assert 0.0 < arm1 < 0.8 * arm2
    spread1 = abs(g.J[3 * contact["f1_prox"], col["f1_spread"]])
    spread2 = abs(g.J[3 * contact["f2_prox"], col["f1_spread"]])
    assert spread1 > 1.5 * spread2
    assert abs(data.actuator_force[0]) > 0.02  # spread commanded 0: passive reaction [N m]
