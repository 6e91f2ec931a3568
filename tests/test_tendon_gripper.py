"""Tendon-driven underactuated gripper (thesis ch. 5, grasp example 3): the model against
its constants module, the exact moment arms R of the thesis, sign conventions, and the
box grasp ``tendon_box`` with contacts on all four links."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm.scenes
from ihm.contacts import grasp_from_mujoco, hand_coordinates, transmission
from ihm.hands import tendon_gripper as tg

SCENE = "tendon_box"
# Per finger, rows (proximal, distal joint), columns (proximal, distal tendon) [m]:
# written out from the thesis' text, not from the constants module.
R_THESIS = np.array([[0.005, 0.0016], [0.0, 0.005]] * 2)


@pytest.fixture(scope="module")
def hand():
    model = mujoco.MjModel.from_xml_path(str(tg.XML))
    return model, mujoco.MjData(model)


_CACHE: dict[tuple, tuple] = {}


def _scene(preload=None):
    key = None if preload is None else tuple(preload)
    if key not in _CACHE:
        model, data = ihm.scenes.load_scene(SCENE, preload)
        _CACHE[key] = (model, data, grasp_from_mujoco(model, data), ihm.scenes.last_settle)
    return _CACHE[key]


def _link_normal_forces(model, g) -> dict[str, float]:
    """Total normal force [N] per hand link (0 for links without contact)."""
    out = dict.fromkeys(tg.BODY_NAMES, 0.0)
    for b, fn in zip(g.hand_bodies, g.forces[:, 0], strict=True):
        out[model.body(b).name] += float(fn)
    return out


# -- the model ---------------------------------------------------------------------------
def test_counts_and_names(hand):
    model, _ = hand
    assert (model.nq, model.nv, model.nu, model.ntendon) == (tg.NQ, tg.NV, tg.NU, tg.NTENDON)
    assert model.ngeom == tg.NGEOM
    assert tuple(model.joint(j).name for j in range(model.njnt)) == tg.JOINT_NAMES
    assert tuple(model.actuator(a).name for a in range(model.nu)) == tg.ACTUATOR_NAMES
    assert tuple(model.tendon(t).name for t in range(model.ntendon)) == tg.TENDON_NAMES
    colliding = {model.body(model.geom_bodyid[i]).name for i in range(model.ngeom)
                 if model.geom_conaffinity[i] or model.geom_contype[i]}  # fmt: skip
    assert colliding == set(tg.BODY_NAMES)


def test_model_conventions(hand):
    model, _ = hand
    assert np.all(model.body_gravcomp[1:] == 1.0)
    assert np.all(model.dof_frictionloss == 0.0)
    hand_geoms = model.geom_conaffinity > 0
    assert np.all(model.geom_contype[hand_geoms] == 0)  # hand geoms never collide with each other
    assert model.opt.jacobian == mujoco.mjtJacobian.mjJAC_DENSE
    assert all(model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON for a in range(model.nu))
    assert np.all(model.actuator_gear[:, 0] == 1.0)


def test_tendons_are_the_moment_arms(hand):
    """Fixed tendon coefficients: the tendon length is R^T q, the actuator displacement."""
    model, data = hand
    rng = np.random.default_rng(0)
    for _ in range(3):
        data.qpos[:] = rng.uniform(-0.5, 1.5, model.nq)
        mujoco.mj_forward(model, data)
        assert np.allclose(data.ten_length, R_THESIS.T @ data.qpos, rtol=0, atol=1e-15)
        assert np.allclose(data.actuator_length, R_THESIS.T @ data.qpos, rtol=0, atol=1e-15)


def test_positive_force_closes(hand):
    """tau = R f, and positive joint motion moves each fingertip toward the other finger."""
    model, data = hand
    for f in ([1.0, 0.0], [0.0, 1.0], [30.0, 12.0]):
        data.qpos[:] = 0.3
        data.qvel[:] = 0.0
        data.ctrl[:] = f
        mujoco.mj_forward(model, data)
        assert np.allclose(data.qfrc_actuator, R_THESIS @ f, rtol=0, atol=1e-15)
    tips = {}
    for q in (0.0, 0.1):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        tips[q] = {s: data.xpos[model.body(f"{s}_distal").id].copy() for s in ("left", "right")}
    assert tips[0.1]["left"][0] > tips[0.0]["left"][0]  # left finger closes toward +x
    assert tips[0.1]["right"][0] < tips[0.0]["right"][0]  # right finger closes toward -x


def test_R_exact_from_glue():
    """The issue's check: R from ihm.contacts equals the thesis' moment arms exactly."""
    model, data = ihm.scenes.load_scene(SCENE, settle_grasp=False)
    dofs, T, names = hand_coordinates(model, data)
    assert tuple(names) == tg.JOINT_NAMES
    assert np.array_equal(T, np.eye(4))  # no joint couplings: four independent joints
    R = T.T @ transmission(model, data)[:, dofs].T
    assert np.array_equal(R, R_THESIS)
    assert np.array_equal(R, np.array(tg.R))
    _, _, g, _ = _scene()
    assert np.array_equal(g.R, R_THESIS)
    assert g.actuator_names == list(tg.ACTUATOR_NAMES)


# -- the box grasp -----------------------------------------------------------------------
def test_scene_about():
    about = ihm.scenes.scene_about(SCENE)
    assert "Grasp example 3" in about and "four links" in about


def test_settles_fast():
    model, data, _, info = _scene()
    assert info.time_s < 3.0  # simulated seconds
    assert np.abs(data.qvel).max() < 1e-4
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit)  # no joint limit near at rest
    assert np.allclose(data.actuator_force, ihm.scenes.default_preload(model))


def test_contacts_on_all_four_links():
    model, _, g, _ = _scene()
    names = [model.body(b).name for b in g.hand_bodies]
    assert sorted(names) == sorted(tg.BODY_NAMES)  # exactly one contact per link
    assert np.all(g.forces[:, 0] > 0.1 * g.forces[:, 0].max())
    # friction inside the cone with margin: the grasp does not rely on sliding
    tang = np.linalg.norm(g.forces[:, 1:], axis=1)
    assert np.all(tang < 0.8 * np.asarray(g.mu) * g.forces[:, 0])


def test_contact_geometry():
    """Proximal contacts below the box centre support it against the palm-ward gravity;
    distal contacts above it press it toward the palm; the grasp is mirror symmetric."""
    model, _, g, _ = _scene()
    names = [model.body(b).name for b in g.hand_bodies]
    for name, p, n in zip(names, g.points, g.normals, strict=True):
        side = -1.0 if name.startswith("left") else 1.0
        assert np.sign(p[0]) == side and -side * n[0] > 0  # pushes inward, across the box
        if name.endswith("proximal"):
            assert p[1] < 0 and n[1] > 0
        else:
            assert p[1] > 0 and n[1] < 0
        assert abs(p[2]) < 1e-6 and abs(n[2]) < 1e-6  # in the grasp plane
    by = dict(zip(names, range(g.m), strict=True))
    for link in ("proximal", "distal"):
        left, right = by[f"left_{link}"], by[f"right_{link}"]
        assert np.allclose(g.points[left] * [-1, 1, 1], g.points[right], atol=1e-4)
        assert np.isclose(g.forces[left, 0], g.forces[right, 0], rtol=1e-3)


def test_equilibrium_residuals():
    _, _, g, _ = _scene()
    res = g.equilibrium_residuals()
    scale = g.forces[:, 0].max()
    assert res["object"] < 1e-6 * scale, res
    assert res["hand"] < 1e-6 * scale, res


@pytest.mark.parametrize("force", [20.0, 40.0])
def test_distal_tendon_only_loads_all_four_links(force):
    """Thesis (fig. tendon_loads b): actively loading only the distal tendon gives contact
    forces on all four links. Here this holds without passive tendon loads: the folded
    distal links (distal joint > 90 deg) turn part of the distal tendon's torque into a
    closing moment at the proximal joint."""
    model, data, g, _ = _scene((0.0, force))
    loads = _link_normal_forces(model, g)
    assert all(v > 0.05 * force for v in loads.values()), loads
    assert np.all(data.qpos[[1, 3]] > np.pi / 2)


def test_proximal_tendon_only_leaves_distal_links_unloaded():
    """With plain tendon motors f = [F, 0] puts zero torque on the distal joints, so the
    free distal links cannot press: only the proximal links carry the box. (The thesis
    finds the reverse, proximal contacts breaking, because its nonbackdrivable actuator
    loads the distal tendon passively; the ratcheting transmission is a later issue.)"""
    model, _, g, _ = _scene((20.0, 0.0))
    loads = _link_normal_forces(model, g)
    assert loads["left_distal"] == loads["right_distal"] == 0.0, loads
    assert loads["left_proximal"] > 1.0 and loads["right_proximal"] > 1.0, loads
