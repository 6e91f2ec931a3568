"""Contact and actuator stiffness and stop gaps in the 3D methods, against closed forms.

Two grasps whose answers follow from statics by hand (derivations in the docstrings), and
the invariances that hold whatever the solver: uniform contact stiffness changes no force
answer, and the thesis' model (unit springs, rigid transmissions) is what every method
solved before the stiffness existed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import stability as st
from stability import GraspError, MethodError

A = 0.05  # [m] half the pinch's width
MU = 0.5
P = 1.0  # [N] preload of each contact
THETA = math.radians(70.0)  # the load's angle from the pinch axis
EXACT_METHODS = ("modesearch", "refinement", "exact", "no_mdp")


def pinch(stiffness: tuple[float, float], **hand) -> st.Grasp:
    """Two opposed contacts on the x axis at ``-A`` (normal +x) and ``+A`` (normal -x)."""
    return st.Grasp([[-A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0]], MU, stiffness=stiffness,
                    **hand)  # fmt: skip


def pinch_limit(k1: float, k2: float) -> float:
    """MaxDisturbance of :func:`pinch` along ``(cos THETA, sin THETA, 0)`` (through the
    origin), contact 1 unloading.

    The object moves ``x`` along the axis: ``c_1 = p - k_1 x``, ``c_2 = p + k_2 x``, and
    ``c_1 - c_2 + s cos(theta) = 0`` gives ``x = s cos(theta) / (k_1 + k_2)``. No torque
    about z is applied, so the two contacts carry the same friction, ``s sin(theta) / 2``
    each, and the weaker contact slides first: ``s sin(theta) = 2 mu c_1``, so
    ``s = 2 mu p / (sin(theta) + 2 mu cos(theta) k_1 / (k_1 + k_2))``. With unit springs
    the split is even; a stiffer unloading contact sheds its force faster."""
    return 2 * MU * P / (math.sin(THETA) + 2 * MU * math.cos(THETA) * k1 / (k1 + k2))


@pytest.mark.parametrize("k", [(3.0, 1.0), (1.0, 3.0), (1000.0, 250.0)])
@pytest.mark.parametrize("method", EXACT_METHODS)
def test_pinch_with_unequal_stiffness_splits_as_statics_says(k, method):
    g = pinch(k)
    d = np.array([math.cos(THETA), math.sin(THETA), 0, 0, 0, 0])
    sol = st.solve(g, st.MaxDisturbance(d, preload=[P, P], cap=100.0), method=method)
    assert sol.status == "solved" and sol.stable
    assert sol.value == pytest.approx(pinch_limit(*k), rel=1e-6)
    res = sol.residuals()
    assert max(res.values()) < 1e-7, res
    # the spring law in physical units: c_n = p - k d_n at both (closed) contacts
    dn = g.contact_motion(sol.motion)[:, 0]
    assert sol.forces[:, 0] == pytest.approx(P - np.asarray(k) * dn, abs=1e-7)


def stepped_pinch_limit(k1: float, k2: float, ks: float, g: float) -> float:
    """:func:`pinch_limit` with a third contact of stiffness ``ks`` at contact 2's point that
    takes load once contact 2 has pressed ``g`` (preload ``-ks g``: a convex contact law
    with one slope step). Beyond the step ``c_1 - c_2 - c_s + s cos(theta) = 0`` gives
    ``x = (s cos(theta) + ks g) / K``, ``K = k_1 + k_2 + ks``, and contact 1 slides at
    ``s sin(theta) = 2 mu (p - k_1 x)``: ``s = 2 mu (p - k_1 ks g / K) / (sin(theta) + 2 mu
    cos(theta) k_1 / K)``."""
    s = pinch_limit(k1, k2)
    if s * math.cos(THETA) / (k1 + k2) <= g:
        return s
    K = k1 + k2 + ks
    return 2 * MU * (P - k1 * ks * g / K) / (math.sin(THETA) + 2 * MU * math.cos(THETA) * k1 / K)


@pytest.mark.parametrize("method", EXACT_METHODS)
@pytest.mark.parametrize("case", ["split sliding contact", "step at a gap"])
def test_contacts_at_one_point_act_as_one_contact_law(method, case):
    """Two contacts at one point with one motion. Contact 1 (the one that unloads and
    slides) split into springs of 1 and 2 N/m with the preload split alike is contact 1 of
    3 N/m; a 2 N/m step at contact 2 that engages after 0.03 m is the convex law of
    :func:`stepped_pinch_limit`."""
    k1, k2 = 3.0, 1.0
    if case == "split sliding contact":
        pts, nrm = [[-A, 0, 0], [A, 0, 0], [-A, 0, 0]], [[1, 0, 0], [-1, 0, 0], [1, 0, 0]]
        k, pre, want = [1.0, k2, 2.0], [P / 3, P, 2 * P / 3], pinch_limit(k1, k2)
    else:
        pts, nrm = [[-A, 0, 0], [A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0], [-1, 0, 0]]
        k, pre, want = [k1, k2, 2.0], [P, P, -2.0 * 0.03], stepped_pinch_limit(k1, k2, 2.0, 0.03)
        assert abs(want / pinch_limit(k1, k2) - 1.0) > 0.01  # the step engages
    g = st.Grasp(pts, nrm, MU, stiffness=k)
    d = np.array([math.cos(THETA), math.sin(THETA), 0, 0, 0, 0])
    sol = st.solve(g, st.MaxDisturbance(d, preload=pre, cap=100.0), method=method)
    assert sol.status == "solved" and sol.stable
    assert sol.value == pytest.approx(want, rel=1e-6)
    assert max(sol.residuals().values()) < 1e-7


@pytest.mark.parametrize("k", [(3.0, 1.0), (1.0, 3.0)])
def test_iterative_follows_the_stiffness_too(k):
    """The iterative scheme (no guarantee; its bisection stops at 1e-3) lands within 0.2 %
    of the closed form."""
    d = np.array([math.cos(THETA), math.sin(THETA), 0, 0, 0, 0])
    q = st.MaxDisturbance(d, preload=[P, P], cap=100.0)
    sol = st.solve(pinch(k), q, method="iterative")
    assert sol.value == pytest.approx(pinch_limit(*k), rel=2e-3)


K_JOINT = 0.5  # [N/m] the finger's spring
J_FINGER = np.zeros((6, 1))
J_FINGER[0, 0] = 1.0  # the finger moves contact 1 along its normal (into the object)


def finger(gap: float | None) -> st.Grasp:
    """:func:`pinch` with unit contacts, contact 1 on a one-joint finger driven by a
    spring-loaded actuator (``K_JOINT``, command ``P``) whose stop is ``gap`` behind it
    (None: no stop, a backdrivable spring)."""
    return pinch((1.0, 1.0), J=J_FINGER, R=[[1.0]], backdrivable=[gap is None],
                 actuator_stiffness=[K_JOINT], stop_gap=[gap or 0.0])  # fmt: skip


def finger_limit(gap: float | None) -> float:
    """MaxDisturbance of :func:`finger` along ``(-cos THETA, sin THETA, 0)`` (into the
    finger), contact 2 (the fixed one) unloading.

    On the spring (``v = q > -g``): ``c_1 = f = p - K q`` and ``c_1 = p - k_1 (x - q)`` give
    ``q = k_1 x / (K + k_1)``: the finger and its contact are springs in series,
    ``K_e = K k_1 / (K + k_1)``; ``c_2 = p + k_2 x``, ``x = -s cos(theta) / (K_e + k_2)``,
    and contact 2 slides at ``s sin(theta) = 2 mu c_2``:
    ``s = 2 mu p / (sin(theta) + 2 mu cos(theta) k_2 / (K_e + k_2))``. The finger reaches its
    stop (``q = -g``) at ``s_g = g (K + k_1) (K_e + k_2) / (k_1 cos(theta))``; beyond it the
    finger is rigid: ``x = -(s cos(theta) + k_1 g) / (k_1 + k_2)`` and
    ``s = 2 mu (p - k_1 k_2 g / (k_1 + k_2)) / (sin(theta) + 2 mu cos(theta) k_2 / (k_1 +
    k_2))``."""
    k1 = k2 = 1.0
    ke = K_JOINT * k1 / (K_JOINT + k1)
    spring = 2 * MU * P / (math.sin(THETA) + 2 * MU * math.cos(THETA) * k2 / (ke + k2))
    if gap is None or spring <= gap * (K_JOINT + k1) * (ke + k2) / (k1 * math.cos(THETA)):
        return spring
    return (2 * MU * (P - k1 * k2 * gap / (k1 + k2))
            / (math.sin(THETA) + 2 * MU * math.cos(THETA) * k2 / (k1 + k2)))  # fmt: skip


def switch_gap() -> float:
    """The gap at which :func:`finger`'s answer turns from stop-limited to spring-limited."""
    k1 = k2 = 1.0
    ke = K_JOINT * k1 / (K_JOINT + k1)
    spring = finger_limit(None)
    return spring * k1 * math.cos(THETA) / ((K_JOINT + k1) * (ke + k2))


@pytest.mark.parametrize("method", EXACT_METHODS)
def test_spring_then_stop_switches_at_the_analytic_load(method):
    g_sw = switch_gap()
    d = np.array([-math.cos(THETA), math.sin(THETA), 0, 0, 0, 0])
    values = {}
    for gap in (0.0, 0.5 * g_sw, 0.9 * g_sw, 1.1 * g_sw, 3.0 * g_sw, None):
        q = st.MaxDisturbance(d, preload=[P, P], commands=[P], cap=100.0)
        sol = st.solve(finger(gap), q, method=method)
        assert sol.status == "solved" and sol.stable
        assert sol.value == pytest.approx(finger_limit(gap), rel=1e-6), gap
        res = sol.residuals()
        assert max(res.values()) < 1e-7, (gap, res)
        values[gap] = sol.value
    # stop-limited below the switch (the answer falls as the gap grows), spring-limited
    # above it (the same answer as no stop at all)
    assert values[0.0] > values[0.5 * g_sw] > values[0.9 * g_sw] > values[None]
    assert values[1.1 * g_sw] == pytest.approx(values[None], rel=1e-9)
    assert values[3.0 * g_sw] == pytest.approx(values[None], rel=1e-9)


def test_the_answer_reports_the_physical_actuator_force():
    """On the spring, ``f = f_c - K q``; on the stop, ``f = f_c - K q + lambda``, lambda > 0."""
    d = np.array([-math.cos(THETA), math.sin(THETA), 0, 0, 0, 0])
    q = st.MaxDisturbance(d, preload=[P, P], commands=[P], cap=100.0)
    on_spring = st.solve(finger(None), q, method="modesearch")
    qv = float(on_spring.hand_motion[0])
    assert qv < 0  # the finger gave way
    assert on_spring.actuator_forces[0] == pytest.approx(P - K_JOINT * qv, abs=1e-9)
    gap = 0.5 * switch_gap()
    on_stop = st.solve(finger(gap), q, method="modesearch")
    assert on_stop.hand_motion[0] == pytest.approx(-gap, abs=1e-9)
    lam = on_stop.actuator_forces[0] - P + K_JOINT * on_stop.hand_motion[0]
    assert lam > 1e-3
    assert on_stop.forces[0, 0] == pytest.approx(on_stop.actuator_forces[0], abs=1e-9)


@pytest.mark.parametrize("method", ["modesearch", "refinement", "no_mdp"])
def test_uniform_contact_stiffness_changes_no_force_answer(method):
    """``k`` on every contact and no joint stiffness: every motion scales by ``1 / k`` and
    every force stays (the model is homogeneous in the motion; ``exact`` takes minutes on
    this grasp)."""
    from stability.bench.grasps import grasps, queries_of

    label, g, f = grasps()[0]
    stiff = st.Grasp(g.points, g.normals, g.mu, g.tangents, g.J, g.R, stiffness=2500.0)
    for task, _k, q in queries_of(label, f, directions=2, wrenches=0)[1:]:
        unit = st.solve(g, q, method=method)
        scaled = st.solve(stiff, q, method=method)
        assert scaled.status == unit.status == "solved", task
        assert scaled.value == pytest.approx(unit.value, rel=1e-6, abs=1e-9)
        assert scaled.motion == pytest.approx(unit.motion / 2500.0, abs=1e-12)
        assert scaled.max_residual(enforced=True) < 1e-7


def test_bad_compliance_is_refused_by_name():
    with pytest.raises(GraspError, match="stiffness must be > 0"):
        pinch((1.0, 0.0))
    with pytest.raises(GraspError, match="stiffness must be a scalar"):
        pinch((1.0, 1.0, 1.0))
    with pytest.raises(GraspError, match="actuator_stiffness given without J"):
        st.Grasp([[0, 0, 0]], [[1, 0, 0]], 0.5, actuator_stiffness=[1.0])
    with pytest.raises(GraspError, match="stop_gap must be >= 0"):
        finger(-0.1)
    with pytest.raises(GraspError, match="backdrivable actuator has no stop"):
        pinch((1.0, 1.0), J=J_FINGER, R=[[1.0]], backdrivable=[True], stop_gap=[0.1])
    with pytest.raises(GraspError, match="one per actuator"):
        pinch((1.0, 1.0), J=J_FINGER, R=[[1.0]], actuator_stiffness=[1.0, 2.0])


def test_methods_without_compliance_refuse_it():
    planar = st.Grasp([[-A, 0], [A, 0]], [[1, 0], [-1, 0]], MU, stiffness=[2.0, 1.0])
    assert planar.compliant
    with pytest.raises(MethodError, match="unit contact springs"):
        st.solve(planar, st.MaxDisturbance([0, 1, 0], preload=[P, P]), method="planar")
    # the wrench-space baseline ignores every spring: it answers the same either way
    g = pinch((2.0, 1.0))
    q = st.MaxDisturbance([0, 1, 0, 0, 0, 0], cap=10.0)
    assert st.solve(g, q, method="gws").value == st.solve(pinch((1, 1)), q, method="gws").value


def test_unit_springs_reproduce_the_answers_from_before_stiffness():
    """The benchmark's first grasps, answered by ``modesearch`` and ``no_mdp`` with the
    thesis' model before the stiffness existed (tests/stability/data/unit_answers.json):
    the same status and the same value to 1e-9."""
    import json
    from pathlib import Path

    from stability.bench.grasps import grasps, queries_of

    data = json.loads((Path(__file__).parent / "data" / "unit_answers.json").read_text())
    by_label = {label: (g, f) for label, g, f in grasps()[:5]}
    queries = {}
    for label, (_g, f) in by_label.items():
        for task, k, q in queries_of(label, f, directions=3, wrenches=2):
            queries[label, task, k] = q
    assert len(data["answers"]) >= 30
    for row in data["answers"]:
        g = by_label[row["label"]][0]
        assert not g.compliant
        sol = st.solve(g, queries[row["label"], row["task"], row["k"]], method=row["method"],
                       time_limit=60)  # fmt: skip
        assert (sol.status, sol.stable) == (row["status"], row["stable"]), row
        if row["value"] is not None:
            assert sol.value == pytest.approx(row["value"], rel=1e-9, abs=1e-12), row
