"""Hand-built grasps with known answers for the 3D methods: the tests' shared problems (like
qpsolvers' ``tests/problems.py``) and the MIP benchmark's cases (``python -m stability.bench
mip``). No MuJoCo needed.

Each builder returns a :class:`stability.Grasp`; the module constants give the analytic
answers the tests assert.
"""

from __future__ import annotations

import numpy as np

from .grasp import Grasp

# --- pinch: a box between two single-joint fingers -------------------------------------
PINCH_HALF_WIDTH = 0.045  # contacts at (+-0.045, 0, 0) [m]
PINCH_LEVER = 0.09  # joint motion moves its contact along the normal by 0.09 m / rad
PINCH_MU = 1.0
PINCH_TORQUE = 0.1  # commanded torque per finger [N m]
# each finger pushes with tau / lever; friction mu c_n at both contacts holds a force along z
PINCH_MAX_Z = 2 * PINCH_MU * PINCH_TORQUE / PINCH_LEVER  # 2.22 N


def pinch() -> Grasp:
    """Finger 0 at +x pushing along -x, finger 1 at -x pushing along +x; joint ``i`` moves
    contact ``i`` along its normal (into the object) with lever 0.09 m; ``R = I``."""
    a = PINCH_HALF_WIDTH
    J = np.zeros((6, 2))
    J[0, 0] = J[3, 1] = PINCH_LEVER
    return Grasp(
        points=[[a, 0, 0], [-a, 0, 0]],
        normals=[[-1, 0, 0], [1, 0, 0]],
        mu=PINCH_MU,
        J=J,
        R=np.eye(2),
    )


# --- wedge: a rigid fixture where dropping maximum dissipation creates energy ----------
WEDGE_A, WEDGE_H, WEDGE_MU = 0.05, 0.01, 0.5  # walls at x = -+a, contacts at y = +-h


def wedge(planar: bool = False) -> Grasp:
    """Two walls facing each other (left at ``x = -a`` pushing +x, right at ``x = +a``
    pushing -x), contacts offset along the walls: left at height ``+h``, right at ``-h``. A
    virtual rotation ``theta > 0`` compresses both springs by ``theta h``; without maximum
    dissipation friction then holds any force along the walls once ``mu > h / a``."""
    a, h = WEDGE_A, WEDGE_H
    if planar:
        return Grasp([[-a, h], [a, -h]], [[1, 0], [-1, 0]], WEDGE_MU)
    return Grasp([[-a, h, 0], [a, -h, 0]], [[1, 0, 0], [-1, 0, 0]], WEDGE_MU)


WEDGE_FORCE_DIR = (0, 1, 0, 0, 0, 0)  # along the walls


# --- underactuation: one tendon, two joints ------------------------------------------------
TENDON_ARMS = (0.02, 0.01)  # moment arms of the tendon at the proximal and distal joint [m]
TENDON_FORCE = 5.0  # commanded tendon tension [N]


def tendon_finger() -> Grasp:
    """A box pressed against a fixed palm (contact 0 at ``x = -0.03``, pushing +x, zero
    Jacobian rows) by a two-link finger (contacts 1 and 2 at ``x = +0.03``, pushing -x) whose
    two joints are driven by one tendon: ``R = [[0.02], [0.01]]`` (2 x 1).

    Normal levers: joint 1 moves the proximal contact by 0.04 and the distal one by 0.03,
    joint 2 the distal one by 0.025, both also move their contacts a little along ``t2``
    (+y), so friction enters hand equilibrium. With the tendon moving and no friction, hand
    equilibrium alone would give ``c_distal = 0.4 f`` and ``c_proximal = 0.2 f``; a locked
    tendon still keeps ``J^T c`` parallel to ``R`` (the finger has a free internal mode)."""
    J = np.zeros((9, 2))
    J[3, 0] = 0.04  # proximal contact normal, joint 1
    J[5, 0] = 0.005  # proximal contact t2 (object z), joint 1
    J[6, 0], J[6, 1] = 0.03, 0.025  # distal contact normal
    J[8, 1] = -0.004  # distal contact t2, joint 2
    return Grasp(
        points=[[-0.03, 0, 0], [0.03, -0.01, 0], [0.03, 0.01, 0]],
        normals=[[1, 0, 0], [-1, 0, 0], [-1, 0, 0]],
        mu=0.6,
        J=J,
        R=np.array([[TENDON_ARMS[0]], [TENDON_ARMS[1]]]),
    )


# --- the thesis' planar 3-contact grasp (Fig. grasp2) embedded in z = 0 ---------------------
THREE_POINTS = [[-1, 0], [0, -1], [1, 0]]
THREE_NORMALS = [[1, 0], [0, 1], [-1, 0]]
THREE_MU = 0.5
# thesis Table tab:three_contact: (planar wrench, preload, stable)
THREE_TABLE = [
    ((0, 0, 0), 0, True),
    ((0, 0, 0), 1, True),
    ((0, -1, 0), 0, True),
    ((0, -2, 0), 0, True),
    ((0, 1, 0), 0, False),
    ((0, 1, 0), 1, True),
    ((0, 1.1, 0), 1, False),
]


def three_planar() -> Grasp:
    return Grasp(THREE_POINTS, THREE_NORMALS, THREE_MU)


def three_embedded() -> Grasp:
    """The planar grasp in the plane z = 0 of a spatial one, ``t1`` the planar tangent (``n``
    turned +90 deg about z) and ``t2 = n x t1 = +z``."""
    p = np.array(THREE_POINTS, dtype=float)
    n = np.array(THREE_NORMALS, dtype=float)
    z = np.zeros((3, 1))
    t1 = np.hstack([-n[:, 1:2], n[:, 0:1], z])
    return Grasp(np.hstack([p, z]), np.hstack([n, z]), THREE_MU, tangents=t1)


def embed_wrench(w: tuple[float, float, float]) -> np.ndarray:
    """Planar ``(fx, fy, tz)`` as the spatial ``(fx, fy, 0, 0, 0, tz)``."""
    return np.array([w[0], w[1], 0.0, 0.0, 0.0, w[2]])


# --- random small grasps for backend agreement and the benchmark ---------------------------
def random_fingers(rng: np.random.Generator, m: int) -> Grasp:
    """``m`` contacts on the unit-ish sphere (radius 0.05 m), normals pointing at the centre
    (tilted up to 0.3 rad), mu in [0.3, 1], each contact on its own single-joint finger that
    moves it along its normal with a lever in [0.04, 0.1] m plus a tangential part; ``R = I``."""
    pts = rng.normal(size=(m, 3))
    pts *= 0.05 / np.linalg.norm(pts, axis=1, keepdims=True)
    n = -pts / np.linalg.norm(pts, axis=1, keepdims=True) + rng.normal(scale=0.15, size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    J = np.zeros((3 * m, m))
    for i in range(m):
        J[3 * i, i] = rng.uniform(0.04, 0.1)
        J[3 * i + 1 : 3 * i + 3, i] = rng.normal(scale=0.01, size=2)
    return Grasp(pts, n, rng.uniform(0.3, 1.0, m), J=J, R=np.eye(m))


RANDOM_WRENCH_SCALE = np.array([1, 1, 1, 0.05, 0.05, 0.05])  # std of forces [N], torques [N m]


def random_wrench(rng: np.random.Generator) -> np.ndarray:
    """A random spatial wrench for the random-finger grasps: forces ~N(0, 1) N, torques
    ~N(0, 0.05) N m (about a 5 cm grasp's torque per newton)."""
    return rng.normal(size=6) * RANDOM_WRENCH_SCALE
