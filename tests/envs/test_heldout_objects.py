"""The held-out objects of the four-finger rotation env (capsule, ellipsoid): the object
lists, each object's geometry and mass as MuJoCo reads them, its scene settling into a
four-fingertip grasp, and start grasps of both grips that hold with the hand still."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from envs.four_finger import (
    GRIPS,
    HELDOUT_OBJECTS,
    OBJECTS,
    TRAIN_OBJECTS,
    VERIFY_STEPS,
    FourFingerError,
    FourFingerRotate,
    scene_name,
)

N = 8  # start grasps per object and grip
# geom type and MuJoCo size of each held-out object [m]: the capsule's radius and
# half-length of its cylindrical part, the ellipsoid's semi-axes along the object x, y, z
SHAPES = {
    "capsule": (mujoco.mjtGeom.mjGEOM_CAPSULE, (0.03, 0.015, 0.0)),
    "ellipsoid": (mujoco.mjtGeom.mjGEOM_ELLIPSOID, (0.04, 0.033, 0.03)),
}


def test_object_lists() -> None:
    assert TRAIN_OBJECTS == ("sphere", "cylinder", "cube")
    assert HELDOUT_OBJECTS == tuple(SHAPES)
    assert OBJECTS == TRAIN_OBJECTS + HELDOUT_OBJECTS
    assert scene_name("capsule") == "four_finger_capsule"
    with pytest.raises(FourFingerError, match="capsule, ellipsoid"):
        scene_name("torus")


@pytest.mark.parametrize("obj", HELDOUT_OBJECTS)
def test_object_geometry_and_mass_read_back(obj: str) -> None:
    """The env's model holds the object as the scene states it: geom type and size, 0.1 kg;
    the ellipsoid's inertia is MuJoCo's solid one, ``m (b^2 + c^2) / 5`` etc."""
    env = FourFingerRotate(object=obj, n_grasps=N)
    m = env.model
    body, geom = m.body("object").id, m.geom("object").id
    kind, size = SHAPES[obj]
    assert m.geom_type[geom] == kind
    np.testing.assert_allclose(m.geom_size[geom], size, atol=1e-12)
    assert m.body_mass[body] == pytest.approx(0.1, rel=1e-12)
    if obj == "ellipsoid":
        a, b, c = size
        want = 0.1 / 5 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
        np.testing.assert_allclose(m.body_inertia[body], want, rtol=1e-9)
    env.close()


@pytest.mark.parametrize("obj", HELDOUT_OBJECTS)
def test_scene_settles_into_a_fingertip_grasp(obj: str) -> None:
    """``ihm.load_scene`` closes the hand on the object with ``ihm_preload``: at rest, one
    contact on each fingertip, the object held near its start height."""
    model, data = ihm.load_scene(scene_name(obj))
    assert np.abs(data.qvel).max() < 1e-3
    g = ihm.grasp_from_mujoco(model, data)
    assert sorted(model.body(b).name for b in g.hand_bodies) == [
        f"f{k}_distal" for k in range(1, 5)
    ]
    assert g.m == 4 and np.all(g.forces[:, 0] > 0.5)
    assert abs(data.qpos[model.joint("object").qposadr[0] + 2] - 0.0768) < 2e-3


@pytest.mark.parametrize("grip", GRIPS)
@pytest.mark.parametrize("obj", HELDOUT_OBJECTS)
def test_start_grasps_hold_with_the_hand_still(obj: str, grip: str) -> None:
    """Every start grasp of a small cache holds the object for ``VERIFY_STEPS`` (40) policy
    steps of zero actions through the env: not dropped, moved under 5 mm."""
    env = FourFingerRotate(object=obj, n_grasps=N, grip=grip)
    env.reset(seed=0)
    zero = np.zeros(12, dtype=np.float32)
    for i in range(N):
        env.reset(options={"grasp": i})
        p0 = env.physics.object_pos().copy()
        for _ in range(VERIFY_STEPS):
            assert not env.step(zero)[2], f"{obj} {grip} grasp {i} dropped"
        assert np.linalg.norm(env.physics.object_pos() - p0) < 5e-3
    env.close()
