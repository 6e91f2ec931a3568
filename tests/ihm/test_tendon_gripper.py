"""Tendon-driven underactuated gripper (thesis ch. 5, grasp example 3): the model against
its constants module, the exact moment arms R of the thesis, sign conventions, and the
box grasp ``tendon_box`` with contacts on all four links."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm.scenes
from ihm.contacts import grasp_from_mujoco, hand_coordinates, transmission
from ihm.experiments import tendon
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
        scene = ihm.scenes.load_scene(SCENE, preload)
        model, data = scene
        _CACHE[key] = (model, data, grasp_from_mujoco(model, data), scene.settle_info)
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


def test_dimensions_match_constants(hand):
    """Joint positions and link lengths of the MJCF are the constants module's: proximal
    joints JOINT_SPACING apart on the palm line, links PROXIMAL_LENGTH / DISTAL_LENGTH long,
    LINK_RADIUS thick; the palm is PALM_WIDTH wide and has no collision geom."""
    model, data = hand
    data.qpos[:] = 0.0
    mujoco.mj_kinematics(model, data)
    for side, sign in (("left", -1.0), ("right", 1.0)):
        prox, dist = (
            data.xpos[model.body(f"{side}_proximal").id],
            data.xpos[model.body(f"{side}_distal").id],
        )
        np.testing.assert_allclose(prox, [sign * tg.JOINT_SPACING / 2, 0, 0], atol=1e-12)
        np.testing.assert_allclose(dist - prox, [0, tg.PROXIMAL_LENGTH, 0], atol=1e-12)
        for link, length in (("proximal", tg.PROXIMAL_LENGTH), ("distal", tg.DISTAL_LENGTH)):
            g = model.geom(f"{side}_{link}").id
            np.testing.assert_allclose(model.geom_size[g][:2], [tg.LINK_RADIUS, length / 2])
    palm = model.geom("palm").id
    assert model.geom_size[palm][0] * 2 == pytest.approx(tg.PALM_WIDTH)
    assert model.geom_contype[palm] == model.geom_conaffinity[palm] == 0


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
    """Like the Barrett box: the proximal links lean over the box's side corners and the
    distal tips press its upper faces, so every contact pushes the box toward the palm
    (-y); the proximal contacts lie at the box centre's height, the distal ones 34.7 mm
    further out; the grasp is mirror symmetric and the box clears the palm."""
    model, data, g, _ = _scene()
    names = [model.body(b).name for b in g.hand_bodies]
    q1 = 0.115  # the design lean of the proximal links (scene header) [rad]
    for name, p, n in zip(names, g.points, g.normals, strict=True):
        side = -1.0 if name.startswith("left") else 1.0
        assert np.sign(p[0]) == side
        if name.endswith("proximal"):
            np.testing.assert_allclose(n, [-side * np.cos(q1), -np.sin(q1), 0], atol=2e-3)
            assert abs(p[1]) < 1e-3
        else:
            np.testing.assert_allclose(n, [-side, -1, 0] / np.sqrt(2), atol=2e-3)
            assert p[1] == pytest.approx(0.0347, abs=1e-3)
        assert abs(p[2]) < 1e-6  # in the grasp plane
    by = dict(zip(names, range(g.m), strict=True))
    for link in ("proximal", "distal"):
        left, right = by[f"left_{link}"], by[f"right_{link}"]
        assert np.allclose(g.points[left] * [-1, 1, 1], g.points[right], atol=1e-4)
        assert np.isclose(g.forces[left, 0], g.forces[right, 0], rtol=1e-3)
    box = model.geom("object").id
    corners = np.array([[sx, sy, 0.0] for sx in (-1, 1) for sy in (-1, 1)]) * model.geom_size[box]
    lowest = (data.geom_xpos[box] + corners @ data.geom_xmat[box].reshape(3, 3).T)[:, 1].min()
    palm = model.geom("palm").id
    palm_face = data.geom_xpos[palm][1] + model.geom_size[palm][1]
    assert lowest - palm_face > 0.004  # 4.7 mm: the box never touches the (visual) palm


def test_design_pose_touches_all_four_links():
    """The scene header's closed-form design: at q = (0.115, 0.9359) rad per finger and the
    box at its keyframe pose every link is at distance 0 from the box (mj_geomDistance),
    and the keyframe's open fingers touch nothing."""
    model = mujoco.MjModel.from_xml_path(str(ihm.scenes.scene_path(SCENE)))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("init").id)
    box = model.geom("object").id

    def distances() -> list[float]:
        mujoco.mj_forward(model, data)
        return [mujoco.mj_geomDistance(model, data, box, model.geom(n).id, 0.05, None)
                for n in tg.BODY_NAMES]  # fmt: skip

    assert min(distances()) > 1e-3
    data.qpos[:4] = [0.115, 0.9359, 0.115, 0.9359]
    np.testing.assert_allclose(distances(), 0.0, atol=2e-5)
    data.qpos[:4] = [0.105, 0.9259, 0.105, 0.9259]  # 0.01 rad more open: clear of the box
    assert min(distances()) > 1e-4


def test_equilibrium_residuals():
    _, _, g, _ = _scene()
    res = g.equilibrium_residuals()
    scale = g.forces[:, 0].max()
    assert res["object"] < 1e-6 * scale, res
    assert res["hand"] < 1e-6 * scale, res


# -- the thesis' preload experiment: one tendon active, the other nonbackdrivable ----------
# ihm.experiments.tendon settles these exactly so (seat, ratchet, then one tendon loaded).
F = tendon.FORCE_N


def _case(commands):
    key = ("ratchet", *commands)
    if key not in _CACHE:
        (model, data), g = tendon.settle_case(commands)
        _CACHE[key] = (model, data, g, tendon.passive_tensions(model, data))
    return _CACHE[key]


@pytest.mark.parametrize("commands", [(F, 0.0), (0.0, F)])
def test_ratcheted_cases_at_rest(commands):
    """Both preload cases rest at the design pose with four contacts, no joint limit, the
    object frame equal to the world axes (the experiment's torque direction), and the hand
    in equilibrium only with the ratchet's passive tendon tensions added: J^T c = R (f_c +
    f_passive), which is what :func:`passive_tensions` reads."""
    model, data, g, passive = _case(commands)
    assert g.m == 4 and sorted(model.body(b).name for b in g.hand_bodies) == sorted(tg.BODY_NAMES)
    np.testing.assert_allclose(data.qpos[:4], [0.115, 0.936, 0.115, 0.936], atol=2e-3)
    # rest as the ratcheted protocol defines it (ihm.load_scene with seat: |qvel| < 1e-3;
    # the ratchet follows the fingers as they creep closed at ~3e-4 rad/s)
    assert np.abs(data.qvel).max() < 1e-3
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    assert not np.any(data.efc_type[: data.nefc] == limit)
    np.testing.assert_allclose(g.object_mat, np.eye(3), atol=1e-5)
    c = g.forces.reshape(-1)
    total = np.asarray(commands) + passive
    # 1e-3: the protocol rests at |qvel| < 1e-3 (damping and armature terms ~1e-4 of c)
    assert np.abs(g.J.T @ c - g.R @ total).max() < 1e-3 * g.forces[:, 0].max()
    assert np.abs(g.J.T @ c - g.R @ np.asarray(commands)).max() > 1e-3  # passive load is real


def test_proximal_tendon_only_loads_the_distal_tendon_passively():
    """Thesis (fig. tendon_loads a): with only the proximal tendon active the distal tendon
    is loaded passively through its nonbackdrivable actuator, and the preload concentrates
    on the distal links. MuJoCo reproduces the passive load (2.3 N on the distal tendon
    at F = 4 N; plain motors would leave it at 0) and a slightly larger distal share, but
    NOT "the contacts on the proximal links break entirely": they keep ~90 % of the distal
    force. Why (model vs thesis): in this Barrett-like grasp the links lean over the box, so
    the box's weight (out of the hand) and the seat's load, which the ratchets lock in,
    press the box against the proximal links; and the thesis' own model (refinement) on
    this grasp keeps them loaded too (0.12 N vs 0.27 N distal). The thesis' figure of its
    grasp is not in our copy of the text, so its exact geometry is unknown."""
    model, _, g, passive = _case((F, 0.0))
    loads = _link_normal_forces(model, g)
    assert passive[1] > 0.3 * F and passive[0] == 0.0, passive
    distal = loads["left_distal"] + loads["right_distal"]
    proximal = loads["left_proximal"] + loads["right_proximal"]
    assert distal > proximal  # "concentrated at the distal contacts" (mildly: 1.1x)
    assert proximal > 0.5 * distal  # ... but the proximal contacts do not break


def test_distal_tendon_only_loads_all_four_links():
    """Thesis (fig. tendon_loads b): with only the distal tendon active, contact forces
    arise on all four links. MuJoCo agrees: the proximal tendon is held passively (9.1 N
    at F = 4 N, more than F: the distal tips' reaction opens the proximal joints) and
    every link carries load, the distal links about 3x the proximal ones."""
    model, _, g, passive = _case((0.0, F))
    loads = _link_normal_forces(model, g)
    assert passive[0] > F, passive
    assert all(v > 0.2 * max(loads.values()) for v in loads.values()), loads
    assert loads["left_distal"] > 2 * loads["left_proximal"], loads


def test_distal_tendon_only_ejects_the_box_beyond_its_weight():
    """Not in the thesis: every contact pushes the box toward the palm, so a distal-only
    preload is balanced only by the box's weight (0.98 N, out of the hand) and friction.
    At 5.5 N the proximal contacts have nearly opened (0.03 N); at 8 N the distal tips
    squeeze the box toward the palm and the fingers give way asymmetrically through the
    differential (the ejection of underactuated fingers): no rest. Hence F = 4 N in the
    experiment. (The thesis' model finds an equilibrium for any F: friction on the cone's
    edge at the distal tips, which MuJoCo's soft friction does not hold.)"""
    with pytest.raises(ihm.scenes.SceneError, match="not at rest"):
        tendon.settle_case((0.0, 8.0))


def test_torque_resistance_same_for_both_preloads():
    """Thesis: the distal-only preload resists almost twice the torque about x. MuJoCo: the
    same within 15 % (both ~0.04 N m at 0.05 rad), equal for +x and -x (the grasp is
    mirror symmetric about the grasp plane). Why: the torque is resisted by out-of-plane
    friction at contacts at two heights (proximal and distal); with the box's weight
    pulling it into the links that lean over it and the ratchets following, both cases
    keep all four contacts and their normal forces grow 2-4x during the ramp, so the
    preload case matters little. (The thesis' model on this grasp: refinement 0.0065 N m
    proximal-only and 0 distal-only, where its equilibrium has the proximal contacts
    open; see docs/experiments/tendon_box_summary.json.)"""
    from ihm.resistance import ResistanceOptions, simulated_resistance

    values = {}
    for commands in ((F, 0.0), (0.0, F)):
        for sign in (1.0, -1.0):
            scene, _ = tendon.settle_case(commands)
            ratchet = scene.ratchet
            opts = ResistanceOptions(cap=tendon.TORQUE_CAP_NM, check_rate=False,
                                     stop_rule="distance")  # fmt: skip
            r = simulated_resistance(scene.model, scene.data, [0, 0, 0, sign, 0, 0],
                                     ratchet=ratchet, options=opts)  # fmt: skip
            assert not r.capped and r.turn > 0.05
            values[commands, sign] = r.value
    for commands in ((F, 0.0), (0.0, F)):
        assert values[commands, 1.0] == pytest.approx(values[commands, -1.0], rel=1e-3)
        assert 0.02 < values[commands, 1.0] < 0.08
    ratio = values[(0.0, F), 1.0] / values[(F, 0.0), 1.0]
    assert 0.85 < ratio < 1.15, values
