"""Barrett flask scene (thesis ch. 6 fig. flasks): four non-coplanar contacts."""

from __future__ import annotations

from collections import Counter

import mujoco
import numpy as np
import pytest

import ihm
from ihm.contacts import grasp_from_mujoco


@pytest.fixture(scope="module")
def flask():
    scene = ihm.load_scene("barrett_flask")
    model, data, info = scene.model, scene.data, scene.settle_info
    g = grasp_from_mujoco(model, data)
    links = [model.body(b).name for b in g.hand_bodies]
    return model, data, g, links, info


def test_settles_at_rest_without_limits(flask):
    model, data, _, _, info = flask
    assert info.time_s < 5.0
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit), "a joint limit is active"
    # spread command 0: the servo carries at most a small reaction torque
    assert abs(data.actuator_force[model.actuator("spread").id]) < 2e-3


def test_contacts_on_expected_links(flask):
    _, _, g, links, _ = flask
    assert Counter(links) == Counter(["f1_dist", "f2_dist", "f3_dist", "f3_prox"])
    assert np.all(g.forces[:, 0] > 0.05)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["object"] <= 1e-3 * load and res["hand"] <= 1e-3 * load, res


def test_contacts_not_coplanar(flask):
    """The thesis' point: the four contacts do not lie in one plane (a 3-D grasp)."""
    _, _, g, _, _ = flask
    p = g.points - g.points.mean(axis=0)
    # smallest singular value ~ distance of the points from their best-fit plane [m]
    assert np.linalg.svd(p, compute_uv=False)[-1] > 5e-3


def test_geometry_of_the_cylinder_grasp(flask):
    """Contacts on the flask body: normals perpendicular to the flask axis (object y); the
    fingertips of fingers 1 and 2 sit at either side of the thumb's plane and push toward
    the thumb (+z), the thumb's inner link pushes back (-z); gravity lies in the object
    xy-plane (up to the roll of the cylinder about its axis)."""
    _, _, g, links, _ = flask
    k = {name: i for i, name in enumerate(links)}
    assert np.abs(g.normals[:, 1]).max() < 0.02
    assert g.normals[k["f1_dist"], 2] > 0.3 and g.normals[k["f2_dist"], 2] > 0.3
    assert g.normals[k["f3_prox"], 2] < -0.9
    assert g.points[k["f1_dist"], 1] < -0.015 < 0.015 < g.points[k["f2_dist"], 1]
    f = g.gravity_wrench[:3]
    assert abs(f[2]) < 0.05 * np.linalg.norm(f)
    # near-mirror images: fingers 1 and 2 carry about the same normal force
    f1, f2 = g.forces[k["f1_dist"], 0], g.forces[k["f2_dist"], 0]
    assert abs(f1 - f2) < 0.1 * max(f1, f2)
