"""The grasp model (stability/grasp.py), input validation, the ``solve`` front end and
``Solution.residuals`` (stability/api.py, queries.py, solution.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stability import (
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    MethodError,
    OptimalCommands,
    available_methods,
    solve,
)
from stability import planar as pl
from stability.grasp import default_tangents

MOTION_KEYS = {"equilibrium", "normal_sign", "friction_cone", "spring_law", "max_dissipation",
               "slide_alignment"}  # fmt: skip
FORCE_KEYS = {"equilibrium", "normal_sign", "friction_cone"}


def three() -> Grasp:
    """The thesis' three-contact planar grasp (ch. 4, fig. grasp2), mu = 0.5."""
    return Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)


def spatial() -> Grasp:
    """Three contacts on a sphere, normals towards the centre."""
    p = [[1.0, 0.0, 0.0], [-0.5, 0.8, 0.1], [-0.5, -0.8, -0.2]]
    return Grasp(points=p, normals=-np.asarray(p), mu=0.5)


def random_planar(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray, Grasp]:
    p = rng.uniform(-1, 1, (m, 2))
    n = rng.normal(size=(m, 2)) * rng.uniform(0.1, 10.0, (m, 1))  # deliberately non-unit
    return p, n, Grasp(p, n, rng.uniform(0.1, 1.0, m))


def random_spatial(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray, Grasp]:
    p = rng.uniform(-1, 1, (m, 3))
    n = rng.normal(size=(m, 3)) * rng.uniform(0.1, 10.0, (m, 1))  # deliberately non-unit
    return p, n, Grasp(p, n, 0.5)


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# -- 1. grasp model: planar ---------------------------------------------------------------
def test_planar_normals_normalised_and_tangent_is_n_rotated_plus_90():
    rng = np.random.default_rng(0)
    _, n_raw, g = random_planar(rng, 6)
    n = unit(n_raw)
    assert g.planar and g.dim == 2 and g.wrench_dim == 3 and g.m == 6
    np.testing.assert_allclose(g.normals, n, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(g.normals, axis=1), 1.0, atol=1e-15)
    assert g.tangents.shape == (6, 1, 2)
    t = g.tangents[:, 0, :]
    # rotation by +90 deg: (x, y) -> (-y, x), i.e. the frame [n, t] has det +1
    rot90 = np.array([[0.0, -1.0], [1.0, 0.0]])
    np.testing.assert_allclose(t, n @ rot90.T, atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(g.frames), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", n, t), 0.0, atol=1e-15)
    # one concrete case: n = +x gives t = +y
    g1 = Grasp([[0.0, 0.0]], [[2.0, 0.0]], 0.3)
    np.testing.assert_allclose(g1.tangents[0, 0], [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(g1.normals[0], [1.0, 0.0], atol=1e-15)


def test_planar_G_matches_column_formula_interleaved_per_contact():
    rng = np.random.default_rng(1)
    p, n_raw, g = random_planar(rng, 5)
    n = unit(n_raw)
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    cols = []
    for i in range(5):
        for f in (n[i], t[i]):  # c = [c_1n, c_1t, c_2n, c_2t, ...]
            cols.append([f[0], f[1], p[i, 0] * f[1] - p[i, 1] * f[0]])
    G_ref = np.array(cols).T
    assert g.G.shape == (3, 10)
    np.testing.assert_allclose(g.G, G_ref, atol=1e-14)
    # the thesis grasp, by hand: contact 2 at (0, -1), n = +y, t = -x
    np.testing.assert_allclose(g.G, G_ref)
    G3 = three().G
    np.testing.assert_allclose(G3[:, 2], [0, 1, 0], atol=1e-15)  # c_2n: force +y, moment 0
    np.testing.assert_allclose(G3[:, 3], [-1, 0, -1], atol=1e-15)  # c_2t: (-1,0) at (0,-1)


def test_planar_GT_r_is_contact_displacement_finite_difference():
    rng = np.random.default_rng(2)
    for _ in range(5):
        p, n_raw, g = random_planar(rng, 4)
        n = unit(n_raw)
        t = np.stack([-n[:, 1], n[:, 0]], axis=1)
        r = rng.normal(size=3) * 1e-6
        x, y, th = r
        Rm = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        delta = p @ Rm.T + np.array([x, y]) - p  # displacement of each contact point
        fd = np.stack([np.einsum("ij,ij->i", delta, n), np.einsum("ij,ij->i", delta, t)], 1)
        lin = (g.G.T @ r).reshape(4, 2)
        assert rel_err(lin, fd) < 1e-4
    # sign: moving the object along n (into which the hand pushes) separates it (d_n > 0)
    g = three()
    d = (g.G.T @ np.array([1e-3, 0.0, 0.0])).reshape(3, 2)
    assert d[0, 0] > 0 and d[2, 0] < 0 and abs(d[1, 0]) < 1e-15


# -- 1. grasp model: spatial --------------------------------------------------------------
def test_spatial_default_tangents_deterministic_orthonormal_right_handed():
    rng = np.random.default_rng(3)
    special = np.array(
        [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, 0, -1], [1, 1, 1], [1, -1, 0]], float
    )
    n_raw = np.concatenate([special, rng.normal(size=(20, 3))])
    m = len(n_raw)
    p = rng.uniform(-1, 1, (m, 3))
    g = Grasp(p, n_raw, 0.5)
    n = unit(n_raw)
    np.testing.assert_allclose(g.normals, n, atol=1e-15)
    assert g.tangents.shape == (m, 2, 3)
    t1, t2 = g.tangents[:, 0], g.tangents[:, 1]
    F = g.frames
    np.testing.assert_allclose(
        F @ F.transpose(0, 2, 1), np.broadcast_to(np.eye(3), F.shape), atol=1e-12
    )
    np.testing.assert_allclose(t2, np.cross(n, t1), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(F), 1.0, atol=1e-12)
    # deterministic, and a function of n alone (not of the point, the order or the scale)
    g2 = Grasp(-p[::-1], 3.0 * n_raw[::-1], 0.1)
    np.testing.assert_allclose(g2.tangents, g.tangents[::-1], atol=1e-15)
    np.testing.assert_array_equal(Grasp(p, n_raw, 0.5).tangents, g.tangents)
    # the documented rule: e = least-aligned axis (ties -> lower index), t1 = e x n / |.|
    gz = Grasp([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], 0.5)  # e = x: t1 = x x z = -y
    np.testing.assert_allclose(gz.tangents[0], [[0, -1, 0], [1, 0, 0]], atol=1e-15)
    np.testing.assert_array_equal(default_tangents(n), default_tangents(n.copy()))
    np.testing.assert_allclose(default_tangents(n), g.tangents, atol=1e-15)


def test_spatial_G_matches_column_formula():
    rng = np.random.default_rng(4)
    p, n_raw, g = random_spatial(rng, 4)
    F = g.frames
    G_ref = np.zeros((6, 12))
    for i in range(4):
        for k in range(3):
            f = F[i, k]
            G_ref[:, 3 * i + k] = np.concatenate([f, np.cross(p[i], f)])
    assert g.G.shape == (6, 12) and g.wrench_dim == 6
    np.testing.assert_allclose(g.G, G_ref, atol=1e-14)
    np.testing.assert_allclose(F[:, 0], unit(n_raw), atol=1e-15)


def test_spatial_GT_r_is_contact_displacement_finite_difference():
    rng = np.random.default_rng(5)
    for _ in range(5):
        p, _, g = random_spatial(rng, 4)
        r = rng.normal(size=6) * 1e-6
        v, omega = r[:3], r[3:]
        Rm = Rotation.from_rotvec(omega).as_matrix()
        delta = p @ Rm.T + v - p
        fd = np.einsum("ikj,ij->ik", g.frames, delta)  # (m, 3): (d_n, d_t1, d_t2)
        lin = (g.G.T @ r).reshape(4, 3)
        assert rel_err(lin, fd) < 1e-4


def test_spatial_given_t1_builds_t2_as_n_cross_t1():
    n = unit(np.array([[0.0, 0.0, 1.0], [1.0, 2.0, -2.0], [0.0, -1.0, 0.0]]))
    a = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 0.0, 0.5]])
    t1 = unit(a - np.einsum("ij,ij->i", a, n)[:, None] * n)  # orthogonalised against n
    p = np.array([[0.0, 0.0, -1.0], [0.3, 0.1, 0.2], [0.0, 1.0, 0.0]])
    g = Grasp(p, n, 0.4, tangents=t1)
    np.testing.assert_allclose(g.tangents[:, 0], t1, atol=1e-15)
    np.testing.assert_allclose(g.tangents[:, 1], np.cross(n, t1), atol=1e-15)
    assert not np.allclose(g.tangents, default_tangents(n))  # the given t1 was used
    # full (t1, t2) frames are kept as given
    tt = np.stack([t1, np.cross(n, t1)], axis=1)
    np.testing.assert_allclose(Grasp(p, n, 0.4, tangents=tt).tangents, tt, atol=1e-15)
    # G uses the given frames
    np.testing.assert_allclose(g.G[:3, 1::3].T, t1, atol=1e-15)


# -- 2. bad grasp input -------------------------------------------------------------------
P2 = [[-1.0, 0.0], [1.0, 0.0]]
N2 = [[1.0, 0.0], [-1.0, 0.0]]
P3 = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]
N3 = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
T1 = [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]  # valid t1 for N3


def _nan(a, i=(0, 0), v=np.nan):
    a = np.array(a, dtype=float)
    a[i] = v
    return a


BAD_GRASPS = {
    "points 1-d": (dict(points=[1.0, 2.0], normals=[1.0, 0.0], mu=0.5), r"points must have shape"),
    "points 3-d": (
        dict(points=np.zeros((2, 2, 2)), normals=np.ones((2, 2, 2)), mu=0.5),
        r"points must have shape",
    ),
    "points 4 columns": (
        dict(points=np.zeros((2, 4)), normals=np.ones((2, 4)), mu=0.5),
        r"points must have shape",
    ),
    "zero contacts": (
        dict(points=np.zeros((0, 2)), normals=np.zeros((0, 2)), mu=0.5),
        r"at least one contact",
    ),
    "normals rows": (dict(points=P2, normals=N2[:1], mu=0.5), r"normals shape"),
    "normals columns": (dict(points=P2, normals=N3, mu=0.5), r"normals shape"),
    "NaN point": (dict(points=_nan(P2), normals=N2, mu=0.5), r"points contains NaN or inf"),
    "inf point": (dict(points=_nan(P3, v=np.inf), normals=N3, mu=0.5), r"points contains NaN"),
    "NaN normal": (dict(points=P2, normals=_nan(N2, (1, 1)), mu=0.5), r"normals contains NaN"),
    "inf normal": (dict(points=P3, normals=_nan(N3, v=-np.inf), mu=0.5), r"normals contains"),
    "NaN mu": (dict(points=P2, normals=N2, mu=np.nan), r"mu contains NaN or inf"),
    "inf mu": (dict(points=P2, normals=N2, mu=[0.5, np.inf]), r"mu contains NaN or inf"),
    "negative mu": (dict(points=P2, normals=N2, mu=[0.5, -0.1]), r"mu must be >= 0"),
    "mu length": (dict(points=P2, normals=N2, mu=[0.5, 0.5, 0.5]), r"mu must be a scalar"),
    "mu 2-d": (dict(points=P2, normals=N2, mu=[[0.5, 0.5]]), r"mu must be a scalar"),
    "zero normal": (dict(points=P2, normals=[[1.0, 0.0], [0.0, 0.0]], mu=0.5), r"zero normal"),
    "zero normal 3d": (dict(points=P3, normals=[[0, 0, 0], [1, 0, 0]], mu=0.5), r"zero normal"),
    "t1 not orthogonal to n": (
        dict(points=P3, normals=N3, mu=0.5, tangents=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
        r"not orthonormal",
    ),
    "t1 not unit": (
        dict(points=P3, normals=N3, mu=0.5, tangents=[[0.0, 2.0, 0.0], [0.0, 1.0, 0.0]]),
        r"not orthonormal",
    ),
    "t2 not orthogonal": (
        dict(
            points=P3,
            normals=N3,
            mu=0.5,
            tangents=[[[0, 1, 0], [0, 1, 0]], [[0, 1, 0], [0, 0, 1]]],
        ),
        r"not orthonormal",
    ),
    "left-handed": (
        # contact 0: n = -x, t1 = +y, so n x t1 = -z; t2 = +z is left-handed
        dict(
            points=P3,
            normals=N3,
            mu=0.5,
            tangents=[[[0, 1, 0], [0, 0, 1]], [[0, 1, 0], [0, 0, 1]]],
        ),
        r"left-handed",
    ),
    "planar tangents": (
        dict(points=P2, normals=N2, mu=0.5, tangents=[[0.0, 1.0], [0.0, -1.0]]),
        r"planar grasps take no tangents",
    ),
    "tangents shape": (
        dict(points=P3, normals=N3, mu=0.5, tangents=[[0.0, 1.0, 0.0]]),
        r"tangents must have shape",
    ),
    "tangents columns": (
        dict(points=P3, normals=N3, mu=0.5, tangents=[[0.0, 1.0], [0.0, 1.0]]),
        r"tangents must have shape",
    ),
    "NaN tangents": (
        dict(points=P3, normals=N3, mu=0.5, tangents=_nan(T1, (1, 2))),
        r"tangents contains NaN",
    ),
    "J rows": (dict(points=P2, normals=N2, mu=0.5, J=np.eye(3)), r"J must have shape"),
    "J rows spatial": (dict(points=P3, normals=N3, mu=0.5, J=np.eye(4)), r"J must have shape"),
    "J 1-d": (dict(points=P2, normals=N2, mu=0.5, J=np.ones(4)), r"J must have shape"),
    "NaN J": (dict(points=P2, normals=N2, mu=0.5, J=_nan(np.eye(4))), r"J contains NaN"),
    "inf J": (dict(points=P2, normals=N2, mu=0.5, J=_nan(np.eye(4), v=np.inf)), r"J contains"),
    "R without J": (dict(points=P2, normals=N2, mu=0.5, R=np.eye(2)), r"without J"),
    "R rows": (dict(points=P2, normals=N2, mu=0.5, J=np.eye(4), R=np.eye(3)), r"R must have"),
    "R 1-d": (dict(points=P2, normals=N2, mu=0.5, J=np.eye(4), R=np.ones(4)), r"R must have"),
    "NaN R": (
        dict(points=P2, normals=N2, mu=0.5, J=np.eye(4), R=_nan(np.eye(4))),
        r"R contains NaN",
    ),
    "string points": (dict(points="abc", normals=N2, mu=0.5), r"points must be numeric"),
    "string in normals": (
        dict(points=P2, normals=[["x", 0.0], [1.0, 0.0]], mu=0.5),
        r"normals must be numeric",
    ),
    "string mu": (dict(points=P2, normals=N2, mu="high"), r"mu must be numeric"),
    "ragged points": (dict(points=[[0.0, 1.0], [2.0]], normals=N2, mu=0.5), r"points must be"),
    "object J": (dict(points=P2, normals=N2, mu=0.5, J={"a": 1}), r"J must be numeric"),
}


@pytest.mark.parametrize(("kwargs", "match"), BAD_GRASPS.values(), ids=BAD_GRASPS.keys())
def test_bad_grasp_input_raises_grasp_error(kwargs, match):
    with pytest.raises(GraspError, match=match):
        Grasp(**kwargs)


def test_valid_hand_matrices_are_kept():
    J = np.arange(8.0).reshape(4, 2)
    g = Grasp(P2, N2, 0.5, J=J, R=np.ones((2, 1)))
    np.testing.assert_array_equal(g.J, J)
    np.testing.assert_array_equal(g.R, np.ones((2, 1)))
    assert Grasp(P2, N2, 0.5).J is None and Grasp(P2, N2, 0.5).R is None


# -- 3. query / solve errors ----------------------------------------------------------------
def test_method_error_is_a_grasp_error():
    assert issubclass(MethodError, GraspError)
    with pytest.raises(GraspError):  # callers catching GraspError also catch MethodError
        solve(three(), Existence(wrench=[0, 0, 0]), method="no-such-method")


def test_unknown_method_lists_methods_that_can_answer():
    with pytest.raises(MethodError, match="unknown method") as exc:
        solve(three(), Existence(wrench=[0, -1, 0]), method="no-such-method")
    msg = str(exc.value)
    assert "'planar'" in msg and "'gws'" in msg and "no-such-method" in msg


def test_planar_method_on_spatial_grasp_names_gws():
    with pytest.raises(MethodError, match="planar grasps only") as exc:
        solve(spatial(), Existence(wrench=np.zeros(6)), method="planar")
    assert "'gws'" in str(exc.value)
    # the planar-only helpers refuse too
    with pytest.raises(MethodError, match="planar grasp"):
        pl.slip_states(spatial())


def test_optimal_commands_refused_by_planar():
    with pytest.raises(MethodError, match="OptimalCommands"):
        solve(three(), OptimalCommands(wrench=[0, -1, 0]), method="planar")


@pytest.mark.parametrize(
    "query",
    [Existence(wrench=[0, -1, 0], commands=[1.0]), MaxDisturbance([0, 1, 0], commands=[1.0])],
    ids=["existence", "max_disturbance"],
)
def test_commands_refused_by_rigid_hand_planar(query):
    with pytest.raises(MethodError, match="rigid hand"):
        solve(three(), query, method="planar")
    with pytest.raises(MethodError, match="rigid hand"):  # a grasp with J is refused too
        solve(Grasp(P2, N2, 0.5, J=np.eye(4)), Existence([0, 0, 0]), method="planar")


BAD_QUERIES = {
    "wrench too short": (Existence(wrench=[0.0, 1.0]), r"wrench must have shape \(3,\)"),
    "spatial wrench": (Existence(wrench=np.zeros(6)), r"wrench must have shape \(3,\)"),
    "wrench 2-d": (Existence(wrench=[[0.0, 1.0, 0.0]]), r"wrench must have shape"),
    "NaN wrench": (Existence(wrench=[0.0, np.nan, 0.0]), r"wrench contains NaN"),
    "inf wrench": (Existence(wrench=[np.inf, 0.0, 0.0]), r"wrench contains NaN or inf"),
    "string wrench": (Existence(wrench="up"), r"wrench must be numeric"),
    "negative preload": (Existence(wrench=[0, -1, 0], preload=-1.0), r"preload must be >= 0"),
    "negative preload entry": (
        Existence(wrench=[0, -1, 0], preload=[1.0, -0.5, 1.0]),
        r"preload must be >= 0",
    ),
    "preload length": (Existence(wrench=[0, -1, 0], preload=[1.0, 1.0]), r"preload must be a"),
    "NaN preload": (Existence(wrench=[0, -1, 0], preload=np.nan), r"preload contains NaN"),
    "inf preload": (
        Existence(wrench=[0, -1, 0], preload=[1.0, np.inf, 1.0]),
        r"preload contains NaN",
    ),
    "direction size": (MaxDisturbance(direction=[0.0, 1.0]), r"direction must have shape"),
    "NaN direction": (MaxDisturbance(direction=[0.0, np.nan, 0.0]), r"direction contains NaN"),
    "zero direction": (MaxDisturbance(direction=[0.0, 0.0, 0.0]), r"non-?zero"),
    "md negative preload": (MaxDisturbance([0, 1, 0], preload=-1.0), r"preload must be >= 0"),
}


@pytest.mark.parametrize("method", ["planar", "gws"])
@pytest.mark.parametrize(("query", "match"), BAD_QUERIES.values(), ids=BAD_QUERIES.keys())
def test_bad_query_data_raises_grasp_error(method, query, match):
    with pytest.raises(GraspError, match=match) as exc:
        solve(three(), query, method=method)
    assert not isinstance(exc.value, MethodError)  # bad data, not a refusal


@pytest.mark.parametrize("cap", [0.0, -1.0, np.inf, np.nan])
def test_planar_cap_must_be_finite_positive(cap):
    with pytest.raises(GraspError, match="cap must be finite"):
        solve(three(), MaxDisturbance(direction=[0, 1, 0], cap=cap), method="planar")


@pytest.mark.parametrize("cap", ["big", None], ids=["str", "None"])
def test_planar_non_numeric_cap_raises_grasp_error(cap):
    with pytest.raises(GraspError, match="cap"):
        solve(three(), MaxDisturbance(direction=[0, 1, 0], cap=cap), method="planar")


def test_unknown_option_to_planar():
    with pytest.raises(GraspError, match="unknown option") as exc:
        solve(three(), Existence(wrench=[0, -1, 0]), method="planar", tolerance=1e-3)
    assert "tolerance" in str(exc.value)


@pytest.mark.parametrize(
    "grasp", [None, {"points": P2}, np.zeros((2, 2))], ids=["None", "dict", "array"]
)
def test_non_grasp_passed_to_solve(grasp):
    with pytest.raises(GraspError, match="stability.Grasp"):
        solve(grasp, Existence(wrench=[0, -1, 0]), method="planar")


@pytest.mark.parametrize(
    "query", [None, [0, -1, 0], {"wrench": [0, -1, 0]}], ids=["None", "list", "dict"]
)
def test_non_query_passed_to_solve(query):
    with pytest.raises(GraspError, match="query must be"):
        solve(three(), query, method="planar")


# -- 4. Solution.residuals ------------------------------------------------------------------
def test_residuals_of_unstable_answer_raise():
    sol = solve(three(), Existence(wrench=[0, 1, 0], preload=0.0), method="planar")
    assert sol.stable is False and sol.forces is None
    with pytest.raises(ValueError, match="unstable"):
        sol.residuals()
    frictionless = Grasp([[-1, 0], [0, -1], [1, 0]], [[1, 0], [0, 1], [-1, 0]], 0.0)
    gsol = solve(frictionless, Existence(wrench=[0, 1, 0]), method="gws")
    assert gsol.stable is False
    with pytest.raises(ValueError, match="unstable"):
        gsol.residuals()


def test_planar_residuals_have_the_motion_keys_and_detect_tampering():
    g = three()
    sol = solve(g, Existence(wrench=[0, 0.5, 0], preload=1.0), method="planar")
    assert sol.stable
    res = sol.residuals()
    assert set(res) == MOTION_KEYS
    assert max(res.values()) <= 1e-9, res
    assert sol.max_residual() == max(res.values())

    forces = np.array(sol.forces, dtype=float, copy=True)
    forces[0, 0] += 0.1  # one normal force off by 0.1 N
    bad = dataclasses.replace(sol, forces=forces).residuals()
    assert bad["equilibrium"] > 0.05, bad
    assert sol.residuals()["equilibrium"] <= 1e-9  # the original is untouched

    forces = np.array(sol.forces, dtype=float, copy=True)
    forces[1, 1] = g.mu[1] * forces[1, 0] + 0.2  # outside the friction cone
    assert dataclasses.replace(sol, forces=forces).residuals()["friction_cone"] > 0.15

    moved = dataclasses.replace(sol, motion=np.asarray(sol.motion) + [0.1, 0.0, 0.0])
    assert moved.residuals()["spring_law"] > 0.05  # contacts 1 and 3 change d_n by 0.1


def test_slide_alignment_sees_friction_misaligned_on_a_small_slide():
    """Maximum dissipation as a force: friction 0.3 N inside the cone (mu c_n = 0.5 N) of a
    contact that slides by 7e-5 passes the product residual (5.6e-5) and fails
    ``slide_alignment`` by 0.8 N; aligned friction passes both; a round-off slide (1e-12)
    is no slide. ``max_residual`` covers every condition, ``conditions`` picks some."""
    from stability.solution import model_residuals

    g = spatial()
    r = np.zeros(6)
    r[2] = 7e-5  # along z: tangential at contact 0 (normal -x)
    d = (g.G.T @ r).reshape(3, 3)
    u = d[0, 1:] / np.linalg.norm(d[0, 1:])
    w = np.zeros(6)

    def res(ct0, motion):
        c = np.zeros((3, 3))
        c[0] = [1.0, *ct0]
        return model_residuals(g, -(g.G @ c.reshape(-1)), c, motion)

    bad = res(0.3 * u, r)
    assert bad["max_dissipation"] == pytest.approx(0.8 * 7e-5, rel=1e-6)
    assert bad["slide_alignment"] == pytest.approx(0.8, rel=1e-9)
    assert bad["friction_cone"] == 0.0 and bad["equilibrium"] <= 1e-15
    good = res(-0.5 * u, r)
    assert good["slide_alignment"] <= 1e-15 and good["max_dissipation"] <= 1e-15
    assert res(0.3 * u, r * 1e-12 / 7e-5)["slide_alignment"] == 0.0  # round-off: no slide
    sol = solve(g, Existence(wrench=w), method="gws")  # no motion: no slide_alignment key
    assert "slide_alignment" not in sol.residuals()


def test_max_disturbance_residuals_use_value_times_direction():
    sol = solve(three(), MaxDisturbance(direction=[0, 1, 0], preload=1.0), method="planar")
    assert sol.value == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(sol.wrench, [0, sol.value, 0])
    res = sol.residuals()
    assert set(res) == MOTION_KEYS and max(res.values()) <= 1e-9, res
    wrong = dataclasses.replace(sol, value=0.5)  # same forces, smaller wrench
    assert wrong.residuals()["equilibrium"] > 0.4


@pytest.mark.parametrize("grasp", [three(), spatial()], ids=["planar", "spatial"])
def test_gws_residuals_have_force_keys_only(grasp):
    w = np.zeros(grasp.wrench_dim)
    w[1] = -0.5 if grasp.planar else 0.3
    sol = solve(grasp, Existence(wrench=w), method="gws")
    assert sol.stable and sol.motion is None
    res = sol.residuals()
    assert set(res) == FORCE_KEYS
    assert max(res.values()) <= 1e-9, res
    forces = np.array(sol.forces, dtype=float, copy=True)
    forces[0, 0] += 0.1
    assert dataclasses.replace(sol, forces=forces).residuals()["equilibrium"] > 0.05


def test_solve_turns_a_solved_answer_without_its_value_into_an_error():
    """The one gate every method passes (``stability.solve``): a stable answer of an
    optimisation query without a finite value, or "solved" without stable/unstable, is
    status "error" with a message, never an answer."""
    from dataclasses import dataclass

    from stability import Solution, api
    from stability.options import MethodOptions

    answers = {"stable": (True, None), "nan": (True, float("nan")), "none": (None, 1.0)}

    @dataclass(frozen=True)
    class BrokenOptions(MethodOptions):
        answer: str = "stable"

    @api.register("_broken", queries=(Existence, MaxDisturbance, OptimalCommands),
                  planar=True, spatial=True, options=BrokenOptions, hand=True)  # fmt: skip
    def _broken(grasp, query, opts, deadline):
        stable, value = answers[opts.answer]
        return Solution(stable, "_broken", grasp, query, value=value)

    try:
        g = three()
        for answer in answers:
            for q in (MaxDisturbance(direction=[0, 1, 0]), OptimalCommands([0, 1, 0])):
                sol = solve(g, q, method="_broken", answer=answer)
                assert sol.status == "error" and sol.stable is None, (answer, q)
                assert "_broken" in sol.stats["message"]
        assert solve(g, Existence([0, 1, 0]), method="_broken").status == "solved"
        assert solve(g, Existence([0, 1, 0]), method="_broken", answer="none").status == "error"
    finally:
        api._METHODS.pop("_broken")
    ok = solve(g, MaxDisturbance(direction=[0, 1, 0], preload=1.0), method="planar")
    assert ok.status == "solved" and ok.value == pytest.approx(1.0)


# -- 5. available_methods -------------------------------------------------------------------
def test_available_methods():
    names = available_methods()
    assert {"planar", "gws"} <= set(names)
    assert names == sorted(names)
    sp = available_methods(spatial(), Existence(wrench=np.zeros(6)))
    assert "planar" not in sp and "gws" in sp
    pq = available_methods(three(), Existence(wrench=[0, -1, 0]))
    assert {"planar", "gws"} <= set(pq)
    assert "planar" not in available_methods(three(), OptimalCommands(wrench=[0, -1, 0]))
    assert "planar" not in available_methods(three(), Existence([0, -1, 0], commands=[1.0]))


def test_unknown_option_to_gws_and_bad_chunk():
    with pytest.raises(GraspError, match="unknown option"):
        solve(three(), Existence(wrench=[0, -1, 0]), method="gws", tolerance=1e-3)
    for chunk in (0, "x"):
        with pytest.raises(GraspError, match="chunk"):
            solve(three(), Existence(wrench=[0, -1, 0]), method="planar", chunk=chunk)


def test_hand_matrices_read_only():
    g = Grasp([[0.0, 0.0]], [[0.0, 1.0]], 0.5, J=np.eye(2), R=np.eye(2))
    for arr in (g.J, g.R):
        with pytest.raises(ValueError):
            arr[0, 0] = 5.0
