"""Scene barrett_cube: thesis ch. 6 fig. cube (three fingertip contacts, mu 0.45)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.contacts import grasp_from_mujoco
from ihm.scenes import SceneError

MU = 0.45
TAU12 = 0.1  # N m on the proximal joints of fingers 1 and 2 (thesis)


def _settle(preload=None):
    model, data = ihm.load_scene("barrett_cube", preload=preload)
    g = grasp_from_mujoco(model, data)
    names = [model.body(b).name for b in g.hand_bodies]
    return model, data, g, names


@pytest.fixture(scope="module")
def cube():
    return _settle()


def _contact(g, names, link):
    return names.index(link)


def test_settles_fast_and_at_rest(cube):
    model, data, g, _ = cube
    info = ihm.scenes.last_settle
    assert info.time_s < 8.0 and info.max_vel < 1e-4
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit), "a joint limit is active"
    for f in ("f1", "f2", "f3"):
        assert 0.0 < data.joint(f"{f}_prox").qpos[0] < 2.44
        assert 0.0 < data.joint(f"{f}_dist").qpos[0] < 0.838


def test_one_fingertip_contact_per_finger(cube):
    """Exactly three contacts, one on each outer link: no palm, no inner link."""
    _, _, g, names = cube
    assert sorted(names) == ["f1_dist", "f2_dist", "f3_dist"]
    assert np.all(g.forces[:, 0] > 0.05)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["object"] <= 1e-4 * load and res["hand"] <= 1e-4 * load, res


def test_contact_geometry_is_the_thesis_frame(cube):
    """Contacts 1, 2 oppose along the object x-axis and lie on it; contact 3 pushes along
    +z; all three lie in the object xz-plane (object frame = body frame = thesis axes)."""
    _, _, g, names = cube
    c1, c2, c3 = (_contact(g, names, f"f{k}_dist") for k in (1, 2, 3))
    cos2deg = np.cos(np.radians(2.0))
    assert g.normals[c1] @ [1.0, 0.0, 0.0] > cos2deg  # finger 1 pushes +x
    assert g.normals[c2] @ [-1.0, 0.0, 0.0] > cos2deg  # finger 2 pushes -x
    assert g.normals[c3] @ [0.0, 0.0, 1.0] > cos2deg  # the thumb pushes +z
    assert np.abs(g.points[:, 1]).max() < 2e-3  # in the xz-plane
    assert np.abs(g.points[[c1, c2], 2]).max() < 2e-3  # 1 and 2 on the x-axis
    assert g.points[c1, 0] < -0.02 and g.points[c2, 0] > 0.02
    assert abs(g.points[c3, 0]) < 2e-3 and g.points[c3, 2] < 0.0  # 3 on the -z axis


def test_equal_moment_arms(cube):
    """Thesis: the moment arms from joint to contact are (about) the same for all three
    fingers, so the normal forces are proportional to the proximal joint torques."""
    model, _, g, names = cube
    tau = dict(zip(("f1", "f2", "f3"), ihm.scenes.default_preload(model)[1:], strict=True))
    arms = [tau[f] / g.forces[_contact(g, names, f"{f}_dist"), 0] for f in tau]
    assert max(arms) - min(arms) < 0.03 * np.mean(arms)


def test_friction_budget_of_contacts_1_and_2():
    """Contacts 1, 2 carry the thumb's push plus the weight (gravity along +z) by friction:
    f3 + m g <= 2 mu f_n12, i.e. tau3 <= 2 mu tau12 - a m g (~ 0.06 N m here). Below that
    the grasp holds with the predicted friction use; above it the cube slides out."""
    model, _, g, names = _settle([0.0, TAU12, TAU12, 0.05])
    c12 = [_contact(g, names, "f1_dist"), _contact(g, names, "f2_dist")]
    c3 = _contact(g, names, "f3_dist")
    weight = float(model.body("object").mass[0] * np.linalg.norm(model.opt.gravity))
    assert model.opt.gravity @ [1.0, 0.0, 0.0] > 9.8  # palm +x = object +z
    ratio = np.linalg.norm(g.forces[c12, 1:], axis=1) / g.forces[c12, 0]
    predicted = (g.forces[c3, 0] + weight) / (2.0 * g.forces[c12, 0])
    assert ratio == pytest.approx(predicted, rel=0.03)
    assert np.all(ratio < MU)
    arm = 0.05 / g.forces[c3, 0]
    tau3_max = 2.0 * MU * TAU12 - arm * weight
    assert 0.055 < tau3_max < 0.07
    with pytest.raises(SceneError):
        ihm.load_scene("barrett_cube", preload=[0.0, TAU12, TAU12, tau3_max + 0.008])
