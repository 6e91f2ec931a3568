"""MuJoCo's compliance read in physical units (ihm.compliance): the soft contacts' normal
stiffness against an independent finite-difference probe on every scene and against the
closed form of constant impedance, and the servo, spring and limit helpers."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.compliance import (
    actuator_stiffness,
    contact_rows,
    contact_stiffness,
    impedance,
    limit_gaps,
    passive_stiffness,
    probe_contact_stiffness,
    static_normal_force,
    tendon_limit_gaps,
)
from ihm.contacts import body_subtree, object_contact_ids
from stability import GraspError

LOADED_N = 1e-3  # a contact carrying less normal force than this [N] is not compared


def loaded_contacts(model: mujoco.MjModel, data: mujoco.MjData) -> list[int]:
    """The object's contacts that carry normal force."""
    in_obj = body_subtree(model, model.body("object").id)
    out = []
    for i, _, _ in object_contact_ids(data, in_obj[model.geom_bodyid].tolist()):
        f6 = np.zeros(6)
        mujoco.mj_contactForce(model, data, i, f6)
        if f6[0] > LOADED_N:
            out.append(i)
    return out


@pytest.mark.parametrize("scene", ihm.available_scenes())
def test_contact_stiffness_matches_the_probe_on_every_scene(scene):
    model, data = ihm.load_scene(scene)
    ids = loaded_contacts(model, data)
    assert ids
    qpos = data.qpos.copy()
    k = contact_stiffness(model, data, ids)
    probe = probe_contact_stiffness(model, data, ids)
    assert np.all(k > 0)
    np.testing.assert_allclose(probe, k, rtol=0.05)
    assert np.max(np.abs(probe / k - 1)) < 1e-3  # measured: <= 3e-6 on every scene
    np.testing.assert_array_equal(data.qpos, qpos)  # the probe works on a copy


SPHERE = """
<mujoco>
  <option timestep="0.002" cone="{cone}" impratio="{impratio}" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" condim="{condim}" friction="0.7 0.02 0.001"
          solref="0.02 1" solimp="{solimp}" margin="{margin}"/>
    <body name="object" pos="0 0 {z}">
      <freejoint/>
      <geom type="sphere" size="0.05" mass="{mass}" condim="{condim}"
            friction="0.7 0.02 0.001" solref="0.02 1" solimp="{solimp}"/>
    </body>
  </worldbody>
</mujoco>
"""


def sphere_on_plane(cone="elliptic", condim=3, impratio=1.0, solimp="0.9 0.9 0.001 0.5 2",
                    margin=0.0, z=0.0495, mass=0.4, steps=1500):  # fmt: skip
    """A sphere resting on a plane under gravity (one contact), settled ``steps`` steps."""
    model = mujoco.MjModel.from_xml_string(SPHERE.format(
        cone=cone, condim=condim, impratio=impratio, solimp=solimp, margin=margin, z=z,
        mass=mass))  # fmt: skip
    data = mujoco.MjData(model)
    for _ in range(steps):
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    return model, data


def closed_form(model, data, i):
    """Constant impedance: ``K = k imp^2 / ((1 - imp) A)`` (frictionless, elliptic), times
    ``(condim - 1) impratio / (mu^2 (1 + mu^2))`` for a pyramidal cone; ``k = 1 / (dmax^2
    timeconst^2 dampratio^2)``, ``A`` the sphere's ``body_invweight0`` (the plane is the
    world's)."""
    con = data.contact[i]
    tc, dr = con.solref
    tc = max(tc, 2 * model.opt.timestep)
    imp = con.solimp[1]
    k = 1.0 / (imp**2 * tc**2 * dr**2)
    A = model.body_invweight0[model.body("object").id, 0]
    K = k * imp**2 / ((1 - imp) * A)
    if model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and con.dim > 1:
        mu = con.friction[0]
        K *= (con.dim - 1) * model.opt.impratio / (mu**2 * (1 + mu**2))
    return K


@pytest.mark.parametrize("cone", ["elliptic", "pyramidal"])
@pytest.mark.parametrize("condim", [1, 3, 4, 6])
def test_constant_impedance_closed_form(cone, condim):
    impratio = 3.0 if cone == "pyramidal" else 1.0
    model, data = sphere_on_plane(cone=cone, condim=condim, impratio=impratio)
    assert data.ncon == 1 and len(contact_rows(data, 0)) == (
        1 if condim == 1 else 2 * (condim - 1) if cone == "pyramidal" else condim)  # fmt: skip
    A = model.body_invweight0[model.body("object").id, 0]
    assert A == pytest.approx(1 / 0.4, rel=1e-9)  # a free sphere: 1 / mass
    K = contact_stiffness(model, data, [0])[0]
    assert K == pytest.approx(closed_form(model, data, 0), rel=1e-9)
    assert probe_contact_stiffness(model, data, [0])[0] == pytest.approx(K, rel=1e-4)
    # settled under its weight on a linear spring: depth = m g / K
    depth = -(data.contact[0].dist - data.contact[0].includemargin)
    assert depth == pytest.approx(0.4 * 9.81 / K, rel=1e-3)
    assert static_normal_force(model, data, [0])[0] == pytest.approx(0.4 * 9.81, rel=1e-3)


def mujoco_impedance(solimp, r):
    """MuJoCo's impedance ``d(r)`` (``getimpedance``), written out for the check."""
    d0, d1, width, mid, power = solimp
    x = min(abs(r) / width, 1.0)
    if x <= mid:
        y = x**power / mid ** (power - 1)
    else:
        y = 1 - (1 - x) ** power / (1 - mid) ** (power - 1)
    return d0 + y * (d1 - d0)


def test_position_dependent_impedance_and_margin():
    """``solimp`` with a width: the stiffness holds ``imp'``; a margin shifts ``r``."""
    solimp = (0.5, 0.95, 0.004, 0.3, 3.0)
    model, data = sphere_on_plane(solimp=" ".join(map(str, solimp)), margin=0.002)
    con = data.contact[0]
    r = con.dist - con.includemargin
    assert -solimp[2] < r < 0  # on the sigmoid
    K = contact_stiffness(model, data, [0])[0]
    assert probe_contact_stiffness(model, data, [0])[0] == pytest.approx(K, rel=1e-4)
    # the static law f(r) = -k imp(r) r / ((1 - imp(r)) A / imp(r)), differenced here
    k = 1.0 / (solimp[1] ** 2 * 0.02**2)
    A = model.body_invweight0[model.body("object").id, 0]

    def f(x):
        imp = mujoco_impedance(solimp, x)
        return -k * imp**2 * x / ((1 - imp) * A)

    h = 1e-8
    assert K == pytest.approx(-(f(r + h) - f(r - h)) / (2 * h), rel=1e-5)
    assert f(r) == pytest.approx(0.4 * 9.81, rel=1e-3)


def test_impedance_and_static_law_are_mujocos():
    """``impedance`` against the impedance MuJoCo reports on a rising sigmoid, and the law
    ``k imp^2 r / ((1 - imp) A)`` written out against MuJoCo's static normal force."""
    solimp = (0.5, 0.95, 0.004, 0.3, 3.0)
    model, data = sphere_on_plane(solimp=" ".join(map(str, solimp)), margin=0.002)
    con = data.contact[0]
    r = con.dist - con.includemargin
    rows = [j for j in contact_rows(data, 0) if data.efc_KBIP[j, 0] > 0]
    assert impedance(np.array(solimp), np.array([r]))[0] == pytest.approx(
        data.efc_KBIP[rows[0], 2], rel=1e-12
    )
    k = 1.0 / (solimp[1] ** 2 * 0.02**2)
    A = model.body_invweight0[model.body("object").id, 0]
    imp = mujoco_impedance(solimp, r)
    law = -k * imp**2 * r / ((1 - imp) * A)
    assert static_normal_force(model, data, [0])[0] == pytest.approx(law, rel=1e-9)


def test_contact_not_engaged_gets_the_engaging_slope():
    """A contact row with ``r = dist - includemargin >= 0`` (inside ``margin`` but not
    engaged: MuJoCo 3's ``gap``) carries no force; its stiffness is the slope at which it
    engages, ``k imp(0)^2 / ((1 - imp(0)) A)``. MuJoCo 4 makes ``includemargin`` the whole
    margin, so the row is shifted here by hand (the formulas read ``efc_pos``)."""
    model, data = sphere_on_plane(solimp="0.8 0.95 0.001 0.5 2")
    row = data.contact[0].efc_address
    data.efc_pos[row] = data.efc_margin[row] + 1e-3
    k = 1.0 / (0.95**2 * 0.02**2)
    A = model.body_invweight0[model.body("object").id, 0]
    want = k * 0.8**2 / ((1 - 0.8) * A)
    assert contact_stiffness(model, data, [0])[0] == pytest.approx(want, rel=1e-9)
    assert static_normal_force(model, data, [0])[0] == 0.0


HAND = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body>
      <joint name="a" type="hinge" axis="0 0 1" stiffness="0.3" range="-1 1" margin="0.01"/>
      <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/>
      <body pos="0.1 0 0">
        <joint name="b" type="slide" axis="1 0 0" stiffness="2"/>
        <geom type="box" size="0.01 0.01 0.01"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="t" stiffness="5" range="-0.5 0.5" limited="true">
      <joint joint="a" coef="1"/>
      <joint joint="b" coef="2"/>
    </fixed>
  </tendon>
  <actuator>
    <position name="servo" joint="a" kp="50"/>
    <general name="rescaled" joint="b" gainprm="7" biastype="affine" biasprm="0 -40 -2"/>
    <motor name="motor" joint="a"/>
    <position name="saturated" joint="b" kp="100" forcerange="-0.1 0.1"/>
  </actuator>
</mujoco>
"""


def test_actuator_passive_and_limit_helpers():
    model = mujoco.MjModel.from_xml_string(HAND)
    data = mujoco.MjData(model)
    data.qpos[:] = [0.2, 0.03]
    data.ctrl[:] = [0.25, 0.0, 0.1, 0.5]
    mujoco.mj_forward(model, data)
    # servo: kp; rescaled general: -biasprm[1] (not the gain); motor: 0; saturated: 0
    np.testing.assert_allclose(actuator_stiffness(model, data), [50.0, 40.0, 0.0, 0.0])
    # joint springs on the diagonal, the tendon's 5 J^T J coupling the two dofs
    J = np.array([1.0, 2.0])
    K = passive_stiffness(model, data, [0, 1])
    np.testing.assert_allclose(K, np.diag([0.3, 2.0]) + 5 * np.outer(J, J), rtol=1e-6)
    np.testing.assert_allclose(limit_gaps(model, data, [0, 1]),
                               [[0.2 + 1 - 0.01, 1 - 0.2 - 0.01], [np.inf, np.inf]])  # fmt: skip
    L = 0.2 + 2 * 0.03
    np.testing.assert_allclose(tendon_limit_gaps(model, data, [0]), [[L + 0.5, 0.5 - L]])


# --- the grasp read with compliance="mujoco" -------------------------------------------


@pytest.mark.parametrize(
    "scene", ["barrett_box", "four_finger_sphere", "four_finger_cylinder", "four_finger_cube"]
)
def test_grasp_stiffness_in_physical_units(scene):
    """Each grasp contact's stiffness is the probe's over the MuJoCo contacts it stands for;
    the servos are backdrivable springs of stiffness kp, the motors rigid; compliance="unit"
    is the thesis' model."""
    model, data = ihm.load_scene(scene)
    g = ihm.grasp_from_mujoco(model, data, compliance="mujoco")
    assert g.compliant and np.all(g.stiffness > 0)
    for k, ids in enumerate(g.contact_ids):
        probe = probe_contact_stiffness(model, data, ids)
        assert g.stiffness[k] == pytest.approx(probe.sum(), rel=1e-3)
    for a, name in enumerate(g.actuator_names):
        act = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        kp = -model.actuator_biasprm[act, 1] if act >= 0 else 0.0
        assert g.actuator_stiffness[a] == pytest.approx(kp, rel=1e-12)
        assert g.backdrivable[a] == (kp > 0) and g.stop_gap[a] == 0.0
    unit = ihm.grasp_from_mujoco(model, data, compliance="unit")
    default = ihm.grasp_from_mujoco(model, data)
    assert not unit.compliant
    np.testing.assert_array_equal(unit.stiffness, np.ones(len(unit.points)))
    for f in ("points", "normals", "tangents", "J", "R", "forces", "commands"):
        np.testing.assert_array_equal(getattr(unit, f), getattr(default, f))


@pytest.mark.parametrize("reduce", ["line", "extremes"])
def test_reduced_patches_keep_their_total_stiffness(reduce):
    """``linkage_box``: each pad's MuJoCo contacts (16, merged pairwise to 12) reduced to
    two or three points carry the same total stiffness, split over points that all have
    some."""
    model, data = ihm.load_scene("linkage_box")
    full = ihm.grasp_from_mujoco(model, data, compliance="mujoco")
    red = ihm.grasp_from_mujoco(model, data, reduce=reduce, compliance="mujoco")
    assert len(red.points) < len(full.points) and np.all(red.stiffness > 0)
    for body in set(full.hand_bodies.tolist()):
        assert red.stiffness[red.hand_bodies == body].sum() == pytest.approx(
            full.stiffness[full.hand_bodies == body].sum(), rel=1e-12)  # fmt: skip


SLIDERS = """
<mujoco>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" jacobian="dense" cone="elliptic" gravity="0 0 0"/>
  <worldbody>
    <body name="left" pos="-0.05 0 0" gravcomp="1">
      <joint name="lslide" type="slide" axis="1 0 0" damping="1" range="-0.05 LIM"
             margin="0.001"/>
      <geom type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01" mass="0.05"/>
    </body>
    <body name="right" pos="0.05 0 0" gravcomp="1">
      <joint name="rslide" type="slide" axis="-1 0 0" damping="1" stiffness="100"
             springref="0.05"/>
      <geom type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01" mass="0.05"/>
    </body>
    <body name="object">
      <freejoint name="object"/>
      <geom type="box" size="0.03 0.03 0.03" mass="0.1" friction="1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="lm" joint="lslide"/>
  </actuator>
</mujoco>
"""


def test_springs_and_near_limits_with_mujoco_compliance():
    """A finger held by its spring alone (refused by the unit model) is a backdrivable
    column of the spring's stiffness; a limit 2 mm from engaging (past the joint's 1 mm
    margin) is a stop with that gap."""
    model = mujoco.MjModel.from_xml_string(SLIDERS.replace("LIM", "0.05"))
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [3.0])
    q = float(data.qpos[model.joint("lslide").qposadr[0]])
    model = mujoco.MjModel.from_xml_string(SLIDERS.replace("LIM", f"{q + 0.003:.6f}"))
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [3.0])
    q = float(data.qpos[model.joint("lslide").qposadr[0]])
    with pytest.raises(ihm.contacts.HandModelError, match="held by the spring"):
        ihm.grasp_from_mujoco(model, data)
    g = ihm.grasp_from_mujoco(model, data, compliance="mujoco")
    names = g.actuator_names
    k = names.index("spring:rslide")
    assert g.backdrivable[k] and g.actuator_stiffness[k] == pytest.approx(100.0, rel=1e-6)
    assert g.commands[k] == pytest.approx(abs(data.qfrc_spring[model.joint("rslide").dofadr[0]]))
    s = names.index("limit:lslide")
    hi = model.jnt_range[model.joint("lslide").id, 1]
    assert not g.backdrivable[s] and g.stop_gap[s] == pytest.approx(hi - q - 0.001, rel=1e-9)
    assert g.stop_gap[s] == pytest.approx(0.002, abs=2e-4)
    assert g.actuator_stiffness[names.index("lm")] == 0.0
    with pytest.raises(GraspError, match="compliance must be"):
        ihm.grasp_from_mujoco(model, data, compliance="soft")
