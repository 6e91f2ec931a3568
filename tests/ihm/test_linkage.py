"""A user's gripper: closed four-bar fingers (``linkage_box``) read into the grasp model.

What is checked against MuJoCo itself: the hand's statics ``J^T c = R f`` with the
forces MuJoCo computed (and that it fails without folding the equalities), the stops'
and springs' values read back from ``mj_data``/``mj_model``, merged contacts' forces,
refusals of what the model cannot represent, ``settle``'s checks, and stability answers
against MuJoCo's simulated resistance.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
import ihm.handmodel
from ihm.contacts import HandModelError, HandModelWarning, HandOptions, grasp_from_mujoco
from ihm.hands import linkage_gripper as lg
from ihm.resistance import ResistanceOptions, simulated_resistance
from ihm.scenes import SceneError, load_scene
from stability import Existence, GraspError, MaxDisturbance, solve

SCENE = "linkage_box"


@pytest.fixture(scope="module")
def settled():
    model, data = load_scene(SCENE)
    return model, data, grasp_from_mujoco(model, data)


def test_constants_match_model():
    model = mujoco.MjModel.from_xml_path(str(lg.XML))
    assert (model.nq, model.nv, model.nu, model.neq) == (lg.NQ, lg.NV, lg.NU, lg.NEQ)
    assert tuple(model.joint(j).name for j in range(model.njnt)) == tuple(
        n for n in lg.JOINT_NAMES if n.startswith("right")
    ) + tuple(n for n in lg.JOINT_NAMES if n.startswith("left"))
    assert tuple(model.equality(e).name for e in range(model.neq)) == lg.EQUALITY_NAMES
    assert model.actuator("fingers").forcerange[1] == lg.FORCE_LIMIT
    for side in lg.SIDES:
        assert model.jnt_stiffness[model.joint(f"{side}_spring_link").id] == lg.SPRING_STIFFNESS


def test_statics_hold_with_mujocos_forces(settled):
    """J^T c = R f and G c + w = 0 with the forces MuJoCo computed, over the 3 independent
    coordinates that remain of 8 joints under 3 equalities (rank 5)."""
    model, data, g = settled
    assert g.T.shape == (lg.NV, lg.N_INDEPENDENT)
    load = np.abs(g.forces).max()
    res = g.equilibrium_residuals()
    assert res["hand"] <= 1e-6 * load and res["object"] <= 1e-6 * load, res
    assert np.allclose(g.J.T @ g.forces.reshape(-1), g.R @ g.actuator_forces, atol=1e-6 * load)
    assert g.hand_residual < 1e-6
    # the closed chains: every column of T moves the joints compatibly with all equalities
    eq = np.flatnonzero(data.efc_type[: data.nefc] == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY))
    A = ihm.handmodel.efc_jacobian(model, data)[eq][:, g.hand_dofs]
    assert np.abs(A @ g.T).max() < 1e-9
    kinds = {e.name: (e.kind, e.model) for e in g.elements}
    for name in lg.EQUALITY_NAMES:
        assert any(k.endswith(name) and v == ("equality", "folded") for k, v in kinds.items())


def test_without_folding_the_equalities_it_fails(settled, monkeypatch):
    """The same state with the equalities left out (every joint independent): the
    equality forces are missing from the statics and the check refuses the grasp."""
    model, data, _ = settled

    def no_fold(model, A, joints, prefer):
        return np.eye(len(joints)), []

    monkeypatch.setattr(ihm.handmodel, "_fold", no_fold)
    with pytest.raises(HandModelError, match="hand equilibrium J\\^T c = R f does not hold"):
        grasp_from_mujoco(model, data, hand=HandOptions(spring_held="warn"))


def test_elements_read_back_from_mujoco(settled):
    """Saturated servo -> constant force at its forcerange bound; coupler limits -> one-way
    stops carrying MuJoCo's limit force; springs -> their torque -k (q - springref) on the
    spring joint, mapped to the independent coordinates by T^T."""
    model, data, g = settled
    col = dict(zip(g.actuator_names, range(len(g.actuator_names)), strict=True))
    a = col["fingers"]
    assert g.backdrivable[a] and g.commands[a] == pytest.approx(lg.FORCE_LIMIT)
    assert data.actuator_force[0] == pytest.approx(lg.FORCE_LIMIT)
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
    for side in lg.SIDES:
        j = model.joint(f"{side}_coupler").id
        rows = np.flatnonzero(
            (data.efc_type[: data.nefc] == limit) & (data.efc_id[: data.nefc] == j)
        )
        k = col[f"limit:{side}_coupler"]
        assert not g.backdrivable[k] and g.commands[k] == 0.0
        assert g.actuator_forces[k] == pytest.approx(data.efc_force[rows].sum(), rel=1e-12)
        assert g.actuator_forces[k] > 0.1  # the parallel-jaw stop carries load
        js = model.joint(f"{side}_spring_link")
        torque = -model.jnt_stiffness[js.id] * (
            data.qpos[js.qposadr[0]] - model.qpos_spring[js.qposadr[0]]
        )
        dof = js.dofadr[0]
        assert data.qfrc_spring[dof] == pytest.approx(torque, rel=1e-9)
        e = np.where(g.hand_dofs == dof, torque, 0.0)  # the spring's torque, all joints
        k = col[f"spring:{side}_spring_link"]
        assert g.backdrivable[k]
        assert np.allclose(g.R[:, k] * g.commands[k], g.T.T @ e, atol=1e-12)
    # one command per MuJoCo actuator fills the actuators' columns, the rest keep theirs
    assert np.array_equal(g.full_commands([lg.FORCE_LIMIT]), g.commands)
    assert g.full_commands([1.5])[a] == 1.5 and g.command_weights()[a] == 1.0
    assert g.command_weights().sum() == 1.0
    with pytest.raises(GraspError, match="2 values for 1 actuators"):
        g.full_commands([1.0, 2.0])


def test_merged_seam_contacts_sum_mujocos_forces(settled):
    """The pad's upper and lower boxes meet at a seam where MuJoCo reports two coincident
    contacts (different geoms, one body): one contact, force the sum of the two."""
    model, data, g = settled
    merged = [k for k, ids in enumerate(g.contact_ids) if len(ids) == 2]
    assert len(merged) == 4  # two seam corners per pad
    for k in merged:
        i, j = g.contact_ids[k]
        assert data.contact[i].geom1 != data.contact[j].geom1 or (
            data.contact[i].geom2 != data.contact[j].geom2
        )
        total = np.zeros(3)
        for c in (i, j):
            f6 = np.zeros(6)
            mujoco.mj_contactForce(model, data, c, f6)
            frame = data.contact[c].frame.reshape(3, 3)
            on_geom2 = frame.T @ f6[:3]
            obj_first = model.geom_bodyid[data.contact[c].geom1] == model.body("object").id
            total += -on_geom2 if obj_first else on_geom2
        assert np.allclose(g.forces_world()[k], total, atol=1e-9 * np.abs(total).max())
    assert g.m == data.ncon - len(merged)


@pytest.mark.parametrize("opts", [{"reduce": "line"}, {"reduce": "rect"},
                                  {"reduce": "extremes", "patch_points": 3}])  # fmt: skip
def test_reduced_patches_keep_the_patch_wrench(settled, opts):
    """A reduced pad patch carries the same wrench as MuJoCo's points: both equilibria
    still hold with the reduced forces (line: 2 points per pad through the centre of
    pressure; extremes: 3 of MuJoCo's points per pad)."""
    model, data, g = settled
    gr = grasp_from_mujoco(model, data, **opts)
    assert gr.m == {"line": 4, "rect": 8, "extremes": 6}[opts["reduce"]]
    load = np.abs(g.forces).max()
    assert np.allclose(gr.forces_world().sum(axis=0), g.forces_world().sum(axis=0), atol=1e-9)
    assert gr.hand_residual < 1e-6
    assert gr.equilibrium_residuals()["object"] < 1e-6 * load
    # the patch's moment about the object origin is kept too
    mom = np.cross(gr.points, gr.forces_world() @ gr.object_mat).sum(axis=0)
    ref = np.cross(g.points, g.forces_world() @ g.object_mat).sum(axis=0)
    assert np.allclose(mom, ref, atol=1e-6 * load * 0.03)
    if opts["reduce"] == "rect":  # the pads' corners (x = +-11 mm, z = +-15 mm)
        assert np.allclose(np.abs(gr.points[:, [0, 2]]), [0.011, 0.015], atol=2e-7)
    if opts["reduce"] == "line":  # each pad's two points lie on its patch, on one line
        for body in np.unique(gr.hand_bodies):
            full = g.points_world()[g.hand_bodies == body]
            ends = gr.points_world()[gr.hand_bodies == body]
            lo, hi = full.min(axis=0) - 1e-4, full.max(axis=0) + 1e-4  # pads tilt ~1e-3 rad
            assert np.all((ends >= lo) & (ends <= hi))
            assert np.linalg.norm(ends[0] - ends[1]) > 0.5 * np.ptp(full, axis=0).max()


def test_weight_alone_is_stable_and_answers_match_mujoco(settled):
    """refinement on the line-reduced grasp (4 contacts): the weight alone is stable
    (MuJoCo holds the box), and the pushes along +x (friction) and +z (friction dragging
    the pads up their path) agree with MuJoCo's simulated resistance within 10 %."""
    model, data, _ = settled
    g = grasp_from_mujoco(model, data, reduce="line")
    assert g.m == 4
    w = solve(g, Existence(g.gravity_wrench, commands=g.commands), method="refinement",
              time_limit=30)  # fmt: skip
    assert w.stable is True
    for axis in (0, 2):
        u = np.zeros(6)
        u[axis] = 1.0
        sol = solve(g, MaxDisturbance(u, commands=g.commands, base=g.gravity_wrench, cap=100),
                    method="refinement", time_limit=30)  # fmt: skip
        assert sol.status == "solved"
        assert max(sol.residuals().values()) < 1e-4 * (1 + sol.value)
        m2, d2 = load_scene(SCENE)
        sim = simulated_resistance(m2, d2, u, options=ResistanceOptions(cap=100, check_rate=False))
        assert sol.value == pytest.approx(sim.value, rel=0.1), (axis, sol.value, sim.value)


# -- what the model cannot represent --------------------------------------------------
TOY = """
<mujoco>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" jacobian="dense" cone="elliptic" gravity="0 0 0"/>
  <worldbody>
    <body name="left" pos="-0.05 0 0" gravcomp="1">
      <joint name="lslide" type="slide" axis="1 0 0" damping="1"/>
      <geom type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01" mass="0.05"/>
    </body>
    <body name="right" pos="0.05 0 0" gravcomp="1">
      <joint name="rslide" type="slide" axis="-1 0 0" damping="1"/>
      <geom type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01" mass="0.05"/>
    </body>
    <body name="object">
      <freejoint name="object"/>
      <geom type="box" size="0.03 0.03 0.03" mass="0.1" friction="1"/>
    </body>
  </worldbody>
  <equality>
    <weld name="glue" body1="left" body2="object" active="false"/>
  </equality>
  <actuator>
    <motor name="lm" joint="lslide"/>
    <motor name="rm" joint="rslide"/>
  </actuator>
</mujoco>
"""


def _toy():
    model = mujoco.MjModel.from_xml_string(TOY)
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [5.0, 5.0])
    return model, data


def test_equality_to_the_object_is_refused():
    model, data = _toy()
    data.eq_active[0] = 1
    mujoco.mj_forward(model, data)
    with pytest.raises(HandModelError, match="weld equality glue ties the hand to the object"):
        grasp_from_mujoco(model, data)


def test_ball_joint_in_the_hand_is_refused():
    xml = TOY.replace('<joint name="lslide" type="slide" axis="1 0 0" damping="1"/>',
                      '<joint name="lball" type="ball" damping="1"/>')  # fmt: skip
    xml = xml.replace('<motor name="lm" joint="lslide"/>', "")
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with pytest.raises(HandModelError, match="hinges or slides.*lball"):
        grasp_from_mujoco(model, data)


def test_joint_friction_is_named():
    """Dry joint friction holds part of the load where the model has none: a warning
    names the joint, and when it carries much of the torque the residual check raises."""
    model, data = _toy()
    model.dof_frictionloss[model.joint("lslide").dofadr[0]] = 3.0
    data.ctrl[0] = 3.0  # 2 N of the 5 N squeeze now held by the joint's friction
    for _ in range(2000):
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    with pytest.warns(HandModelWarning, match="frictionloss.*lslide"):
        with pytest.raises(HandModelError, match="frictionloss"):
            grasp_from_mujoco(model, data)


def test_settle_raises_when_the_fingers_cannot_close():
    with pytest.raises(SceneError, match="fingers did not close"):
        load_scene(SCENE, preload=[0.0], gravity=False)
    with pytest.raises(SceneError):  # with gravity the box falls out of the open hand
        load_scene(SCENE, preload=[0.0], max_s=1.0)
    with pytest.raises(SceneError, match="outside its forcerange"):
        load_scene(SCENE, preload=[3.0])


def test_settle_by_ctrl_closes_like_a_gripper_command(settled):
    """command="ctrl": 255 is the gripper's "close" (the servo's target past the object):
    the same saturated grasp as commanding the forcerange bound; ctrl 0 leaves the hand
    open; a ctrl outside ctrlrange is refused."""
    _, _, ref = settled
    model, data = load_scene(SCENE, settle_grasp=False)
    ihm.scenes.settle(model, data, [255.0], command="ctrl")
    assert data.actuator_force[0] == pytest.approx(lg.FORCE_LIMIT)
    g = grasp_from_mujoco(model, data)
    assert g.m == ref.m
    assert np.allclose(g.forces[:, 0], ref.forces[:, 0], rtol=1e-3, atol=1e-3)
    with pytest.raises(SceneError, match="outside its ctrlrange"):
        ihm.scenes.settle(model, data, [300.0], command="ctrl")
    model, data = load_scene(SCENE, settle_grasp=False, gravity=False)
    with pytest.raises(SceneError, match="fingers did not close"):
        ihm.scenes.settle(model, data, [0.0], command="ctrl")


def test_stop_gap_and_near_limit_warning():
    """A limit 0.5 mm beyond the settled slide finger, on the side its motor does not
    hold (a stop there would push the finger open): warned about by name; with
    ``stop_gap`` it becomes a stop column commanded 0 that carries no force yet."""
    xml = TOY.replace('<joint name="lslide" type="slide" axis="1 0 0" damping="1"/>',
                      '<joint name="lslide" type="slide" axis="1 0 0" damping="1" '
                      'range="-0.05 LIM"/>')  # fmt: skip
    model = mujoco.MjModel.from_xml_string(xml.replace("LIM", "0.05"))
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [5.0, 5.0])
    q = float(data.qpos[model.joint("lslide").qposadr[0]])
    model = mujoco.MjModel.from_xml_string(xml.replace("LIM", f"{q + 0.0005:.6f}"))
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [5.0, 5.0])
    with pytest.warns(HandModelWarning, match="lslide .* from its limit"):
        g = grasp_from_mujoco(model, data)
    assert "limit:lslide" not in g.actuator_names
    g = grasp_from_mujoco(model, data, hand=HandOptions(stop_gap=0.002))
    k = g.actuator_names.index("limit:lslide")
    assert g.commands[k] == 0.0 and g.actuator_forces[k] == 0.0 and not g.backdrivable[k]
    assert np.allclose(g.R[:, k], [-1.0, 0.0])  # pushes lslide back, away from its limit


def test_reduced_forces_stay_in_the_cone(settled):
    """The line and 3-point reductions of the pads give pushing forces inside the cone
    (MuJoCo's state is a state of the reduced grasp): no warning, c_n >= 0, |c_t| <= mu c_n."""
    model, data, _ = settled
    import warnings

    for opts in ({"reduce": "line"}, {"reduce": "extremes", "patch_points": 3}):
        with warnings.catch_warnings():
            warnings.simplefilter("error", HandModelWarning)
            g = grasp_from_mujoco(model, data, **opts)
        assert np.all(g.forces[:, 0] >= 0)
        assert np.all(np.linalg.norm(g.forces[:, 1:], axis=1) <= g.mu * g.forces[:, 0] + 1e-9)


def test_spring_held_motion_is_refused_by_name():
    """The right finger has no actuator, only a spring pushing it closed: its motion is
    held by the spring alone, which the model (no joint stiffness) cannot represent: a
    HandModelError naming the spring, or with spring_held="warn" a warning and a grasp."""
    xml = TOY.replace('<joint name="rslide" type="slide" axis="-1 0 0" damping="1"/>',
                      '<joint name="rslide" type="slide" axis="-1 0 0" damping="1" '
                      'stiffness="100" springref="0.05"/>')  # fmt: skip
    xml = xml.replace('<motor name="rm" joint="rslide"/>', "")
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    ihm.scenes.settle(model, data, [3.0])
    with pytest.raises(HandModelError, match="held by the spring.*spring:rslide.*Not supported"):
        grasp_from_mujoco(model, data)
    with pytest.warns(HandModelWarning, match="spring:rslide: a passive motion"):
        g = grasp_from_mujoco(model, data, hand=HandOptions(spring_held="warn"))
    k = g.actuator_names.index("spring:rslide")
    assert g.backdrivable[k] and g.hand_residual < 1e-3


def test_rect_reduction_with_mujocos_stiffness_matches_the_push_along_x():
    """With MuJoCo's stiffness and preload each pad's centre of pressure is 0.45 mm above
    the box centre, so the friction of a push along x, saturated, turns the box about y;
    MuJoCo's patch balances that with torsion about the pad normals (z friction at x =
    +-11 mm). The line (points at x = 0) cannot: its answer is the lower points' friction,
    4 x 0.7 x 10.42 N = 29.16 N. The rect reduction keeps the lever: MuJoCo's 30.03 N."""
    from ihm.sim_maps import scene_disturbance

    model, data = load_scene(SCENE)
    out = {}
    for red in ("line", "rect"):
        g = grasp_from_mujoco(model, data, reduce=red, compliance="mujoco")
        q = scene_disturbance(g, np.r_[g.object_mat.T @ [1.0, 0, 0], 0, 0, 0], g.commands, 100.0)
        out[red] = solve(g, q, method="modesearch", time_limit=5).value
    assert out["line"] == pytest.approx(4 * 0.7 * 10.4156, rel=1e-3)
    assert out["rect"] == pytest.approx(30.03, rel=0.01)
