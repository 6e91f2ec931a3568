"""What MuJoCo simulates at each contact is what the models document: every active contact
of every scene carries the hand's skin (solref, solimp) and the documented friction."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.hands import barrett, four_finger, linkage_gripper, tendon_gripper

HANDS = {
    "barrett": barrett,
    "four_finger": four_finger,
    "tendon": tendon_gripper,
    "linkage": linkage_gripper,
}


@pytest.mark.parametrize("scene", ihm.available_scenes())
def test_effective_contact_parameters_are_the_documented_skin(scene):
    hand = next(h for k, h in HANDS.items() if scene.startswith(k))
    model, data = ihm.load_scene(scene)
    assert data.ncon > 0
    obj = model.body("object").id
    for k in range(data.ncon):
        con = data.contact[k]
        np.testing.assert_allclose(con.solref, hand.SKIN_SOLREF, rtol=1e-12)
        np.testing.assert_allclose(con.solimp, hand.SKIN_SOLIMP, rtol=1e-12)
        # friction: the object's where it has priority, else MuJoCo's max of the pair
        g = [con.geom1, con.geom2]
        og = [x for x in g if model.geom_bodyid[x] == obj or
              model.body_rootid[model.geom_bodyid[x]] == model.body_rootid[obj]]  # fmt: skip
        assert og, "a contact that does not touch the object"
        pr = model.geom_priority[g]
        if pr[0] != pr[1]:
            want = model.geom_friction[g[int(np.argmax(pr))], 0]
        else:
            want = max(model.geom_friction[g[0], 0], model.geom_friction[g[1], 0])
        assert con.friction[0] == pytest.approx(want, rel=1e-12)
        assert con.dim == 3
    # and the mixing does not change them: the pair's own values are equal
    for k in range(data.ncon):
        g1, g2 = data.contact[k].geom1, data.contact[k].geom2
        np.testing.assert_allclose(model.geom_solref[g1], model.geom_solref[g2])
        np.testing.assert_allclose(model.geom_solimp[g1], model.geom_solimp[g2])
    assert mujoco.mjtCone(model.opt.cone) == mujoco.mjtCone.mjCONE_ELLIPTIC
