"""Scene barrett_cube: thesis ch. 6 fig. cube (three inner-link contacts, equal moment
arms, mu 0.45, no gravity)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.contacts import grasp_from_mujoco

MU = 0.45
TAU12 = 0.1  # N m on the proximal joints of fingers 1 and 2 (thesis)
ARM = 0.05  # m: every contact is 0.050 m up its inner link (scene header)
SEAT = [0.0, 0.02, 0.02, 0.005]  # light closing commands of the nonbackdrivable protocol


def _settle(preload=None, **kw):
    model, data = ihm.load_scene("barrett_cube", preload=preload, **kw)
    g = grasp_from_mujoco(model, data)
    names = [model.body(b).name for b in g.hand_bodies]
    return model, data, g, names


@pytest.fixture(scope="module")
def cube_scene():
    return ihm.load_scene("barrett_cube")


@pytest.fixture(scope="module")
def cube(cube_scene):
    model, data = cube_scene
    g = grasp_from_mujoco(model, data)
    return model, data, g, [model.body(b).name for b in g.hand_bodies]


def _contact(names, link):
    return names.index(link)


def test_settles_fast_and_at_rest(cube, cube_scene):
    model, data, g, _ = cube
    info = cube_scene.settle_info
    assert info.time_s < 8.0 and info.max_vel < 1e-4
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit), "a joint limit is active"
    assert np.all(model.opt.gravity == 0.0)  # the thesis' example has no gravity


def test_one_inner_link_contact_per_finger(cube):
    """Exactly three contacts, one on each inner link: no palm, no outer link."""
    _, _, g, names = cube
    assert sorted(names) == ["f1_prox", "f2_prox", "f3_prox"]
    assert np.all(g.forces[:, 0] > 0.1)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["object"] <= 1e-4 * load and res["hand"] <= 1e-4 * load, res


def test_contact_geometry_is_the_thesis_frame(cube):
    """Contacts 1, 2 oppose along the object x-axis and lie on it; contact 3 pushes along
    +z from 0.0385-0.0395 m down the -z axis (the lever against torques about x); all three
    lie in the object xz-plane (object frame = body frame = thesis axes)."""
    _, _, g, names = cube
    c1, c2, c3 = (_contact(names, f"f{k}_prox") for k in (1, 2, 3))
    cos2deg = np.cos(np.radians(2.0))
    assert g.normals[c1] @ [1.0, 0.0, 0.0] > cos2deg  # finger 1 pushes +x
    assert g.normals[c2] @ [-1.0, 0.0, 0.0] > cos2deg  # finger 2 pushes -x
    # the thumb pushes +z, its normal tilted toward the palm by its flexion (~2 deg)
    assert g.normals[c3] @ [0.0, 0.0, 1.0] > np.cos(np.radians(3.0))
    assert np.abs(g.points[:, 1]).max() < 1e-3  # in the xz-plane
    assert np.abs(g.points[[c1, c2], 2]).max() < 2e-3  # 1 and 2 on the x-axis
    assert g.points[c1, 0] < -0.06 and g.points[c2, 0] > 0.06
    assert abs(g.points[c3, 0]) < 2e-3 and -0.0400 < g.points[c3, 2] < -0.0380


def test_equal_moment_arms(cube):
    """Thesis: the moment arms from joint to contact are the same for all three fingers,
    so the normal forces are the proximal joint torques over 0.050 m."""
    model, _, g, names = cube
    tau = dict(zip(("f1", "f2", "f3"), ihm.scenes.default_preload(model)[1:], strict=True))
    arms = np.array([tau[f] / g.forces[_contact(names, f"{f}_prox"), 0] for f in tau])
    assert arms == pytest.approx(ARM, rel=0.02)


def test_friction_budget_of_contacts_1_and_2():
    """Nonbackdrivable fingers (seat, ratchet, preload): contacts 1, 2 carry the thumb's
    push by friction, f3 <= 2 mu f_n12, i.e. tau3 <= 2 mu tau12 = 0.09 N m (thesis). At
    0.06 N m the friction use is f3 / (2 f_n12); at 0.1 N m the object slides out."""
    model, _, g, names = _settle([0.0, TAU12, TAU12, 0.06], nonbackdrivable=True, seat=SEAT)
    c12 = [_contact(names, "f1_prox"), _contact(names, "f2_prox")]
    c3 = _contact(names, "f3_prox")
    ratio = np.linalg.norm(g.forces[c12, 1:], axis=1) / g.forces[c12, 0]
    predicted = g.forces[c3, 0] / (2.0 * g.forces[c12, 0])
    assert ratio == pytest.approx(predicted, rel=0.05)
    assert np.all(ratio < MU)
    assert g.forces[c3, 0] == pytest.approx(0.06 / ARM, rel=0.05)  # + the seat's residual
    model, data = ihm.load_scene("barrett_cube", preload=[0.0, TAU12, TAU12, 0.1],
                                 nonbackdrivable=True, seat=SEAT)  # fmt: skip
    # pushed out along +z (palm +x) until it comes to rest on the palm
    assert data.body("object").xpos[0] > 0.01
    palm = model.body("palm").id
    assert any(palm in model.geom_bodyid[[c.geom1, c.geom2]] for c in data.contact[: data.ncon])


def test_unloaded_thumb_is_a_passive_support():
    """tau3 = 0 with the ratchet: the thumb keeps its seated contact (a small passive force)
    and the object stays in place, held by contacts 1 and 2."""
    model, data, g, names = _settle([0.0, TAU12, TAU12, 0.0], nonbackdrivable=True, seat=SEAT)
    assert sorted(names) == ["f1_prox", "f2_prox", "f3_prox"]
    c3 = _contact(names, "f3_prox")
    assert 0.0 < g.forces[c3, 0] < 0.2 and data.actuator_force[model.actuator("f3").id] == 0
