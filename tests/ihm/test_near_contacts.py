"""Near contacts (ihm.near, grasp_from_mujoco(near=)): a sphere on a plane beside a wall
0.5 mm away; the wall's contact read with its gap, MuJoCo's engaging stiffness and pair
friction, its preload and stay-open mask in scene_disturbance, and near=0 unchanged."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.sim_maps import scene_disturbance
from stability import GraspError

GAP = 0.5e-3  # [m]
R = 0.05  # [m] sphere radius

SCENE = """
<mujoco>
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" friction="0.7 0.02 0.001"
          solref="0.02 1" solimp="0.9 0.9 0.001 0.5 2"/>
    {wall}
    <body name="object" pos="0 0 0.0495">
      <freejoint/>
      <geom type="sphere" size="{r}" mass="0.4" friction="0.7 0.02 0.001" solref="0.02 1"
            solimp="0.9 0.9 0.001 0.5 2" margin="{margin}"/>
    </body>
  </worldbody>
</mujoco>
"""
WALL = """<geom name="wall" type="box" size="0.01 0.1 0.1" pos="{x} 0 0.05"
          friction="{mu} 0.02 0.001" solref="0.02 1" solimp="0.9 0.9 0.001 0.5 2"/>"""


def _scene(own_body: bool, mu: float = 0.9, margin: float = 0.0):
    """Settled sphere; the wall 0.5 mm from its settled surface (+x), a world geom (the
    floor's body) or its own static body; ``margin`` on the sphere (its contacts engage
    that far out)."""
    base = mujoco.MjModel.from_xml_string(SCENE.format(wall="", r=R, margin=margin))
    data = mujoco.MjData(base)
    for _ in range(1000):
        mujoco.mj_step(base, data)
    x = float(data.xpos[base.body("object").id][0]) + R + GAP + 0.01
    wall = WALL.format(x=f"{x:.9f}", mu=mu)
    if own_body:
        wall = f'<body name="wall_body">{wall}</body>'
    model = mujoco.MjModel.from_xml_string(SCENE.format(wall=wall, r=R, margin=margin))
    d2 = mujoco.MjData(model)
    d2.qpos[:] = data.qpos
    mujoco.mj_forward(model, d2)
    return model, d2


def test_near_contact_read_off() -> None:
    model, data = _scene(own_body=False)
    g0 = ihm.grasp_from_mujoco(model, data, compliance="mujoco")
    g = ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=1e-3)
    assert g0.m == 1 and g.m == 2
    np.testing.assert_array_equal(g.gaps, [0.0, g.gaps[1]])
    assert g.gaps[1] == pytest.approx(GAP, abs=1e-6)
    assert g.forces[1] == pytest.approx(np.zeros(3))
    np.testing.assert_allclose(g.frames_world()[1, 0], [-1, 0, 0], atol=1e-9)  # into it
    assert g.mu[1] == pytest.approx(0.9)  # the larger of the pair's friction
    # the floor's solref/solimp and bodies at constant impedance: the floor's stiffness but
    # for the pyramidal cone's R, which scales with mu^2 (1 + mu^2) (ihm.compliance)
    scale = (0.7**2 * (1 + 0.7**2)) / (0.9**2 * (1 + 0.9**2))
    assert g.stiffness[1] == pytest.approx(g.stiffness[0] * scale, rel=1e-6)
    assert g.contact_ids[1] == [] and g.near.tolist() == [False, True]
    # near=0: the grasp of before
    g00 = ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=0.0)
    np.testing.assert_array_equal(g00.points, g0.points)
    np.testing.assert_array_equal(g00.stiffness, g0.stiffness)
    assert ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=0.4e-3).m == 1


def test_gap_beyond_the_objects_margin() -> None:
    """A sphere with 0.2 mm margin engages the wall 0.2 mm out: the gap is 0.3 mm (MuJoCo
    adds the two geoms' margins, which ihm.near relies on)."""
    model, data = _scene(own_body=False, margin=0.2e-3)
    g = ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=1e-3)
    assert g.near.tolist() == [False, True]
    assert g.gaps[1] == pytest.approx(GAP - 0.2e-3, abs=1e-6)


def test_near_refused_with_unit_springs() -> None:
    model, data = _scene(own_body=False)
    with pytest.raises(GraspError, match="compliance='mujoco'"):
        ihm.grasp_from_mujoco(model, data, near=1e-3)
    with pytest.raises(GraspError, match="near must be"):
        ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=-1.0)


@pytest.mark.parametrize("own_body", [False, True])
def test_scene_disturbance_preload_and_mask(own_body: bool) -> None:
    model, data = _scene(own_body=own_body)
    g = ihm.grasp_from_mujoco(model, data, compliance="mujoco", near=1e-3)
    q = scene_disturbance(g, np.array([1.0, 0, 0, 0, 0, 0]), None, 10.0)
    assert q.preload[0] == g.forces[0, 0]
    assert q.preload[1] == pytest.approx(-g.stiffness[1] * g.gaps[1])
    np.testing.assert_array_equal(q.motion_limit.open, [False, own_body])
