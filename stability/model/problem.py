"""The grasp model of thesis ch. 5 as one mixed-integer model, for every 3D method.

:class:`ExactProblem` states thesis eqs. object_eq .. underactuation on a
:class:`~stability.mip.MipModel`; the methods (``no_mdp``, ``iterative``, the refinement
of ch. 6 and ``exact``) add their friction law and objective to it. Called "exact" after
the thesis: the model of ch. 5, before any method's approximation of friction.

Variables (all in the grasp's units; springs have unit stiffness, so a virtual
displacement is measured in newtons):

* ``r`` object motion (``(x, y, theta)`` planar, ``(v, omega)`` spatial), free;
* ``c`` contact forces in contact frames, ``c_n in [0, B]``, ``|c_t| <= mu B``;
* ``u`` separation beyond the preload, ``u = c_n + k d_n - p in [0, B]`` with
  ``d = G^T r - J q`` (eq. rel_contact_motion) and ``k`` the contact's stiffness
  (``Grasp.stiffness``, 1 in the thesis);
* ``y`` per contact (eq. binary_contact): ``y = 1`` (closed) ``=> u = 0``, so
  ``c_n = p - k d_n >= 0``; ``y = 0`` (open) ``=> c_n = 0``, so ``k d_n >= p``. Together:
  ``c_n = max(0, p - k d_n)`` (thesis eq. normal_compliance with preload ``p``). A
  negative ``p`` is a gap (our extension): the contact closes once it has moved ``-p / k``
  towards the object, ``d_n <= p / k``; the rows are the same;
* hands (``J`` given; ``R`` defaults to the identity): joint motion ``q`` (free),
  actuator forces ``f in [f_c, f_c + E]``, transmission motion ``v = R^T (q - q_ref) in
  [0, V]`` (eq. underac_nonbackdrive; ``q_ref = 0`` unless a preload state is given),
  hand equilibrium ``J^T c = R f`` (eqs. hand_eq and torqueRatio in the sign convention
  of docs/design.md: ``c`` acts on the object, ``-c`` on the hand), and per actuator (eq.
  binary_actuator) ``z = 1`` (locked) ``=> v = 0``, ``z = 0`` (moving) ``=> f = f_c``.
* compliant actuators (our extension; ``Grasp.actuator_stiffness`` ``K`` and
  ``Grasp.stop_gap`` ``g``): the physical force is ``f_c - K v_p + lambda`` with ``v_p =
  R^T (q - q_ref)`` and a stop reaction ``lambda >= 0`` at ``v_p = -g``. The variables are
  shifted so that the thesis' rows above hold unchanged: ``v = v_p + g`` (the distance
  from the stop, in ``[0, V + g]``) and ``f = f_c + lambda`` (``f - f_c`` the stop's
  reaction); only hand equilibrium gains the spring, ``J^T c = R (f - K (v - g))``.
  ``K = 0, g = 0`` is the thesis' model exactly; a backdrivable actuator has ``f = f_c``
  and a free ``v = v_p``. :attr:`ExactPoint.actuator_forces` is the physical force.

Motion limit (our extension; query ``motion_limit``, :class:`~stability.queries.MotionLimit`):
the displacement of a point ``p`` of the object, ``v + omega x p``, and the rotation
``omega`` are held within balls of radius ``shift`` and ``turn`` by the inscribed polytopes
``|a_j . x| <= radius / rho`` (:func:`ball_directions`: 31 directions of the icosahedral
group, ``rho = 1.0705``; planar: 8 directions of a 16-gon and ``|theta| <= turn``), so that
every answer honours the Euclidean limit and reaches at least ``1 / rho`` of it in every
direction. Contacts the limit keeps open (``MotionLimit.open``) get the row ``c_n <= 0``:
with ``u >= 0`` their spring law leaves ``k d_n >= p`` (a gap that does not close).

The bounds ``B, V, E`` are not arbitrary big-M constants: :func:`scale_bounds` derives
them from the query's own force scale (the largest applied force or torque / size,
preload, or contact force that balances a command), times ``bound_factor``. They are part
of the model, the same for every backend: HiGHS uses them as big-M, SCIP as variable
bounds beside its native indicators. An answer that reaches a bound is flagged
(``at_bound``) so the factor can be raised; an infeasible model means "no equilibrium
with forces and motions within the bounds", and the bounds are reported beside it.

Friction (eq. frictioncone): planar contacts get the exact interval ``|c_t| <= mu c_n``;
spatial ones the polygon of ``edges`` sides inscribed in the cone (its vertices at
``mu c_n (cos 2 pi j / edges, sin 2 pi j / edges)``; conservative: every force in it is in
the cone), so with ``edges % 4 == 0`` the in-plane directions ``+-t1, +-t2`` keep their full
``mu``.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import GraspError
from ..grasp import Grasp, actuator_compliance
from ..mip import INF, MipModel
from ..queries import MotionLimit

__all__ = ["ExactBounds", "ExactProblem", "ExactPoint", "actuator_vector", "ball_directions",
           "clean_wrench", "hand_data", "length_scale", "scale_bounds"]  # fmt: skip


def length_scale(grasp: Grasp) -> float:
    """The grasp's size ``L`` [m]: the largest contact distance from the object origin (1 if
    all contacts sit at the origin). Torques divided by ``L`` are forces."""
    L = float(np.max(np.linalg.norm(grasp.points, axis=1)))
    return L if L > 0 else 1.0


@functools.cache
def ball_directions(dim: int) -> tuple[NDArray[np.float64], float]:
    """Unit directions ``a_j`` (one per antipodal pair) and ``rho``, the largest norm of a
    vertex of ``{x: |a_j . x| <= 1}``: the polytope ``|a_j . x| <= r / rho`` lies inside the
    ball of radius ``r`` and contains the ball of radius ``r / rho``. ``dim`` 3: the 6
    vertex, 10 face and 15 edge directions of the icosahedron (``rho = 1.0705``, by vertex
    enumeration); 2: 8 directions ``pi j / 8`` (a 16-gon, ``rho = 1 / cos(pi / 16)``)."""
    if dim == 2:
        th = np.pi * np.arange(8) / 8
        return np.stack([np.cos(th), np.sin(th)], axis=1), 1.0 / math.cos(math.pi / 16)
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    ico = np.array([[0, 1, phi], [0, 1, -phi], [1, phi, 0], [1, -phi, 0], [phi, 0, 1],
                    [-phi, 0, 1]])  # fmt: skip
    dod = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1], [0, 1 / phi, phi],
                    [0, 1 / phi, -phi], [1 / phi, phi, 0], [1 / phi, -phi, 0], [phi, 0, 1 / phi],
                    [-phi, 0, 1 / phi]])  # fmt: skip
    verts = np.r_[ico, -ico]  # edges join icosahedron vertices 2 apart: their midpoints
    mids = [(verts[i] + verts[j]) / 2 for i, j in itertools.combinations(range(12), 2)
            if abs(np.linalg.norm(verts[i] - verts[j]) - 2.0) < 1e-9]  # fmt: skip
    mids = [x for k, x in enumerate(mids) if not any(np.allclose(x, -y) for y in mids[:k])]
    a = np.r_[ico, dod, np.array(mids)]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    planes = np.r_[a, -a]
    trip = np.array(list(itertools.combinations(range(len(planes)), 3)))
    mats = planes[trip]
    ok = np.abs(np.linalg.det(mats)) > 1e-9
    x = np.linalg.solve(mats[ok], np.ones((int(ok.sum()), 3, 1)))[..., 0]
    inside = np.all(x @ planes.T <= 1.0 + 1e-9, axis=1)
    return a, float(np.linalg.norm(x[inside], axis=1).max())


def hand_data(
    grasp: Grasp, commands: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """``(R, f_c)`` for a grasp with a hand (``R`` the identity when not given, ``f_c`` zeros
    when no commands), None for a rigid fixture. Raises GraspError for commands that do not
    fit: a rigid fixture, a wrong shape, NaN/inf."""
    if grasp.J is None:
        if commands is not None:
            raise GraspError(
                "commands given for a grasp without a hand: set J (and R) on the Grasp"
            )
        return None
    R = np.eye(grasp.J.shape[1]) if grasp.R is None else np.asarray(grasp.R, dtype=float)
    a = R.shape[1]
    if commands is None:
        return R, np.zeros(a)
    return R, actuator_vector(commands, a, "commands")


def actuator_vector(
    value: ArrayLike | None, a: int, name: str, default: float = 0.0
) -> NDArray[np.float64]:
    """One finite number per actuator (a scalar is broadcast; None gives ``default``);
    GraspError naming ``name`` otherwise."""
    if value is None:
        return np.full(a, float(default))
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GraspError(f"{name} must be numeric, got {value!r}") from exc
    if arr.ndim == 0:
        arr = np.full(a, float(arr))
    if arr.shape != (a,):
        raise GraspError(f"{name} must have shape ({a},) for {a} actuators, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise GraspError(f"{name} contain NaN or inf")
    return arr


@dataclass(frozen=True)
class ExactBounds:
    """Model bounds [N, or the transmission's units]: ``force`` ``B`` on normal forces and
    on separations beyond the preload; ``motion`` ``V`` per actuator on ``R^T q``;
    ``excess`` ``E`` per actuator on ``f - f_c``; ``scale`` the force scale they came from;
    ``displacement`` the most a contact moves, ``2 B / min k`` [m] (``2 B`` with unit
    springs), the unit of the motions' box."""

    force: float
    motion: NDArray[np.float64]
    excess: NDArray[np.float64]
    scale: float
    displacement: float


def scale_bounds(
    grasp: Grasp,
    wrench_max: NDArray[np.float64],
    preload: NDArray[np.float64],
    hand: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    bound_factor: float = 100.0,
) -> ExactBounds:
    """Bounds from the problem's own scale (see the module docstring).

    ``S = max(|w_force|, |w_torque| / L, max |p|, max_j |(R f_c)_j| / |J_j|)`` with
    ``wrench_max`` the largest wrench the query applies (``cap * direction`` for
    MaxDisturbance) and ``|J_j|`` the norm of joint ``j``'s column (the contact force that
    balances the commanded torque through that joint's lever). ``B = bound_factor * S``
    (``S = 1`` N when nothing loads the grasp); contacts then move by at most ``D = 2 B /
    min k`` (``k`` the contact stiffness), so ``V_l = sum_j |R_jl| D / min_j |J_j| + g_l``
    (``g`` the stop gaps), and ``E = |R^+| |J^T| B (1 + max mu) sqrt(m) + K (V + g)`` (``K``
    the actuator stiffness).
    The motions ``r`` and ``q`` stay unbounded (no indicator row holds them): each answer is
    the least virtual motion among the optimal ones (:meth:`ExactProblem.tidy`).
    """
    if not (math.isfinite(bound_factor) and bound_factor >= 1.0):
        raise GraspError(f"bound_factor must be a finite number >= 1, got {bound_factor!r}")
    L = length_scale(grasp)
    k = 2 if grasp.planar else 3
    w = np.abs(wrench_max)
    S = max(float(w[:k].max()), float(w[k:].max()) / L, float(np.max(np.abs(preload), initial=0.0)))
    if hand is not None:
        R, fc = hand
        cols = np.linalg.norm(grasp.J, axis=0)
        live = cols > 1e-12 * max(1.0, float(cols.max(initial=0.0)))
        if np.any(live):
            S = max(S, float(np.max(np.abs(R @ fc)[live] / cols[live], initial=0.0)))
    if S <= 0.0:
        S = 1.0
    B = bound_factor * S
    D = 2.0 * B / float(grasp.stiffness.min())
    if hand is None:
        return ExactBounds(B, np.zeros(0), np.zeros(0), S, D)
    lever = float(cols[live].min()) if np.any(live) else 1.0
    motion = np.abs(R).sum(axis=0) * D / lever
    motion = np.where(motion > 0, motion, D / lever)
    c_norm = B * (1.0 + float(grasp.mu.max())) * math.sqrt(grasp.m)
    jt = float(np.linalg.norm(grasp.J, 2))
    rp = float(np.linalg.norm(np.linalg.pinv(R), 2)) if R.size else 0.0
    excess = np.full(R.shape[1], max(rp * jt * c_norm, B))
    K, gap = actuator_compliance(grasp, R.shape[1])
    if np.any(gap) or np.any(K):
        motion = motion + gap
        excess = excess + K * motion
    return ExactBounds(B, motion, excess, S, D)


CLEAN_RTOL = 1e-7


def _clean(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """``A`` with entries below ``CLEAN_RTOL max|A|`` (1e-7) set to 0: round-off of frames
    and Jacobians read from a simulator (4e-17 normal components; 1e-9 m/rad out-of-plane
    entries of the Barrett spread joint next to 0.12 m/rad), which a solver would otherwise
    exploit, or which make its LPs numerically singular (SCIP: "error in LP solver" on
    ``barrett_box``). A 1e-7 relative entry moves no answer beyond the solvers' tolerances."""
    big = float(np.abs(A).max(initial=0.0))
    return np.where(np.abs(A) > CLEAN_RTOL * big, A, 0.0)


def clean_wrench(
    w: NDArray[np.float64], scale: float, length: float, planar: bool
) -> NDArray[np.float64]:
    """``w`` with components below ``CLEAN_RTOL scale`` set to 0 (torques compared over the
    grasp's size ``length``, as forces): the round-off of a wrench rotated into the object
    frame (a box's weight read from a simulator carries 4e-10 N out of its plane), the
    right-hand side's counterpart of :func:`_clean`. It matters where the grasp cannot
    resist a load of one sign at all: a planar Barrett grasp takes an out-of-plane load
    only through friction whose torque the nonbackdrivable spread joint must hold, which it
    can for one sign only, so the exact problem flips from stable to unstable at zero load.
    The solvers accept that 4e-10 N residual as zero (feasibility tolerance 1e-6), but
    SCIP's infeasibility proofs use it exactly: a Farkas proof can scale it into a bound on
    a friction force that cuts off the optimum (tests/stability/test_solver_regressions.py);
    zeroed, it cannot."""
    k = 2 if planar else 3
    mag = np.abs(np.asarray(w, dtype=float))
    mag = np.r_[mag[:k], mag[k:] / length]
    return np.where(mag > CLEAN_RTOL * scale, w, 0.0)


@dataclass
class ExactPoint:
    """One solution of the exact model, in the grasp's terms."""

    forces: NDArray[np.float64]  # (m, k) [c_n, c_t...]
    motion: NDArray[np.float64]  # r
    hand_motion: NDArray[np.float64] | None  # q
    actuator_forces: NDArray[np.float64] | None  # f
    closed: NDArray[np.bool_]  # y
    locked: NDArray[np.bool_] | None  # z
    at_bound: bool
    x: NDArray[np.float64]  # the model's solution vector


def _backdrivable(grasp: Grasp, na: int) -> NDArray[np.bool_]:
    """The grasp's backdrivable mask over its ``na`` actuators (all False when not set)."""
    back = getattr(grasp, "backdrivable", None)
    if back is None:
        return np.zeros(na, dtype=bool)
    back = np.asarray(back, dtype=bool)
    if back.shape != (na,):
        raise GraspError(f"backdrivable has {back.size} entries for {na} actuators")
    return back


class ExactProblem:
    """The constraint set of thesis eqs. object_eq .. underactuation on a fresh
    :class:`~stability.mip.MipModel` (``self.model``), object equilibrium left to the
    caller (:meth:`add_object_equilibrium` or :meth:`add_net_wrench`).

    Parameters
    ----------
    grasp : Grasp
        Planar or spatial; a rigid fixture (``J is None``) or a hand (``J``, ``R``).
    preload : (m,) array
        Spring preloads ``p`` [N]; ``p < 0`` is a gap of ``-p / k`` (module docstring).
    hand : (R, f_c) or None
        From :func:`hand_data`.
    bounds : ExactBounds
        From :func:`scale_bounds`.
    edges : int
        Sides of the inscribed friction polygon (spatial contacts), ``>= 3``.
    friction : bool
        False leaves the tangential forces out of the cone (the caller states its own law,
        e.g. the SOS2 relaxation of ch. 6); the variables exist either way.
    hand_reference : (l,) array, optional
        Joint motion ``q_ref`` at which the actuators lock: ``v = R^T (q - q_ref) >= 0``.
        Default 0 (the thesis' one-shot model: commands and disturbance applied together).
        A disturbance applied after a commanded preload uses the preload's ``q`` (a
        nonbackdrivable transmission locks where the preload left it).
    command_range : (lower, upper) arrays, optional
        The commands are variables ``f_c`` (``self.fc``) in ``[lower, upper]`` instead of
        ``hand[1]`` (query OptimalCommands): ``f - f_c in [0, E]`` and ``z = 0 => f = f_c``.
    """

    def __init__(
        self,
        grasp: Grasp,
        preload: NDArray[np.float64],
        hand: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
        bounds: ExactBounds,
        edges: int = 8,
        friction: bool = True,
        name: str = "exact",
        hand_reference: NDArray[np.float64] | None = None,
        command_range: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> None:
        if not isinstance(edges, int | np.integer) or edges < 3:
            raise GraspError(f"edges (friction polygon sides) must be an int >= 3, got {edges!r}")
        self.grasp, self.preload, self.hand, self.bounds = grasp, preload, hand, bounds
        self.edges = int(edges)
        g, m, k, B = grasp, grasp.m, grasp.dim, bounds.force
        M = self.model = MipModel(name)
        self.r = M.add_vars(g.wrench_dim, -INF, INF, "C", "r")
        lo = np.stack([np.zeros(m)] + [-g.mu * B] * (k - 1), axis=1).reshape(-1)
        hi = np.stack([np.full(m, B)] + [g.mu * B] * (k - 1), axis=1).reshape(-1)
        self.c = M.add_vars(m * k, lo, hi, "C", "c").reshape(m, k)
        self.u = M.add_vars(m, 0.0, B, "C", "u")
        self.y = M.add_vars(m, 0, 1, "B", "y")
        self.q = self.f = self.v = self.z = self.hand_reference = self.fc = None
        self.stiffness = self.gap = None
        self.spring_rows: list[int] = []
        self.G = _clean(g.G)  # (wrench_dim, k m), round-off entries zeroed
        Gt = self.G.T.reshape(m, k, -1)
        self.J = None if g.J is None else _clean(g.J)
        Jn = None if g.J is None else self.J.reshape(m, k, -1)[:, 0, :]
        self.backdrivable = None
        if hand is not None:
            R, fc = hand
            nl, na = R.shape
            back = self.backdrivable = _backdrivable(grasp, na)
            excess = np.where(back, 0.0, bounds.excess)  # a constant force source: f = f_c
            self.q = M.add_vars(nl, -INF, INF, "C", "q")
            if command_range is None:
                self.f = M.add_vars(na, fc, fc + excess, "C", "f")
            else:
                lo_c, hi_c = command_range
                self.fc = M.add_vars(na, lo_c, hi_c, "C", "fc")
                self.f = M.add_vars(na, lo_c, hi_c + excess, "C", "f")
                for a in range(na):  # 0 <= f - f_c <= E (0 for a backdrivable actuator)
                    M.add_row([self.f[a], self.fc[a]], [1.0, -1.0], 0.0, float(excess[a]),
                              f"excess{a}")  # fmt: skip
            # transmission motion: one-way for a nonbackdrivable actuator, free otherwise
            self.v = M.add_vars(na, np.where(back, -INF, 0.0), np.where(back, INF, bounds.motion),
                                "C", "v")  # fmt: skip
            # z: locked (1) or moving (0); a backdrivable actuator always "moves" (z = 0)
            self.z = M.add_vars(na, 0, np.where(back, 0, 1), "B", "z")
        kc = g.stiffness
        for i in range(m):
            # c_n + k d_n - u = p, d_n = G_n^T r - J_n q
            idx, val = [self.c[i, 0], self.u[i]], [1.0, -1.0]
            idx, val = self.extend(idx, val, self.r, kc[i] * Gt[i, 0])
            if Jn is not None:
                idx, val = self.extend(idx, val, self.q, -kc[i] * Jn[i])
            self.spring_rows.append(M.add_constraint(idx, val, "==", float(preload[i]),
                                                     f"spring{i}"))  # fmt: skip
            M.add_indicator(self.y[i], [self.u[i]], [1.0], "<=", 0.0, 1, f"closed{i}")
            M.add_indicator(self.y[i], [self.c[i, 0]], [1.0], "<=", 0.0, 0, f"open{i}")
        if friction:
            self._friction_polygon()
        if hand is not None:
            R, fc = hand
            K, gap = self.stiffness, self.gap = actuator_compliance(grasp, R.shape[1])
            for j in range(R.shape[0]):  # J^T c - R f + R K v = R K g
                idx, val = self.extend([], [], self.c.reshape(-1), self.J[:, j])
                idx, val = self.extend(idx, val, self.f, -R[j])
                idx, val = self.extend(idx, val, self.v, R[j] * K)
                M.add_constraint(idx, val, "==", float(R[j] @ (K * gap)), f"hand{j}")
            ref = np.zeros(R.shape[1]) if hand_reference is None else R.T @ hand_reference
            self.hand_reference = hand_reference
            for a in range(R.shape[1]):  # R^T q - v = R^T q_ref - g
                idx, val = self.extend([self.v[a]], [-1.0], self.q, R[:, a])
                M.add_constraint(idx, val, "==", float(ref[a] - gap[a]), f"transmission{a}")
                if back[a]:
                    continue  # f = f_c by its bounds, v free: no lock
                M.add_indicator(self.z[a], [self.v[a]], [1.0], "<=", 0.0, 1, f"locked{a}")
                if self.fc is None:
                    M.add_indicator(self.z[a], [self.f[a]], [1.0], "<=", float(fc[a]), 0,
                                    f"moving{a}")  # fmt: skip
                else:
                    M.add_indicator(self.z[a], [self.f[a], self.fc[a]], [1.0, -1.0], "<=", 0.0,
                                    0, f"moving{a}")  # fmt: skip
        self.n_base = M.n_vars  # the variables above, the same for the same arguments

    @staticmethod
    def extend(idx, val, var, coef) -> tuple[list, list]:
        """``(idx, val)`` of a sparse row with ``coef[j]`` on variable ``var[j]`` appended
        (the nonzero coefficients only)."""
        coef = np.asarray(coef, dtype=float)
        nz = np.flatnonzero(coef)
        return list(idx) + [int(var[j]) for j in nz], list(val) + coef[nz].tolist()

    def _friction_polygon(self) -> None:
        g, M = self.grasp, self.model
        for i in range(g.m):
            mu = float(g.mu[i])
            if g.planar:
                dirs = np.array([[1.0], [-1.0]])
                rhs = mu
            else:
                th = 2 * np.pi * (np.arange(self.edges) + 0.5) / self.edges
                dirs = np.stack([np.cos(th), np.sin(th)], axis=1)
                rhs = mu * math.cos(math.pi / self.edges)
            for e, dvec in enumerate(dirs):  # dvec . c_t - rhs c_n <= 0
                idx = [int(self.c[i, 0])] + [int(x) for x in self.c[i, 1:]]
                M.add_constraint(idx, [-rhs, *dvec.tolist()], "<=", 0.0, f"cone{i}.{e}")

    def limit_motion(self, limit: MotionLimit) -> None:
        """The object's motion within ``limit`` (module docstring, "Motion limit"): rows
        ``|a_j . (v + omega x p)| <= shift / rho`` and ``|a_j . omega| <= turn / rho`` in the
        directions of :func:`ball_directions` (planar: ``|theta| <= turn``); ``c_n <= 0`` at
        the contacts of ``limit.open``."""
        g, M = self.grasp, self.model
        if limit.open is not None:
            for i in np.flatnonzero(limit.open):
                M.add_row([int(self.c[i, 0])], [1.0], -INF, 0.0, f"stay_open{i}")
        a, rho = ball_directions(g.dim)
        p = np.asarray(limit.point, dtype=float)
        k = g.dim
        if math.isfinite(limit.shift):
            for j, aj in enumerate(a):
                # a . (omega x p) = omega . (p x a); planar: theta (a_y p_x - a_x p_y)
                rot = [aj[1] * p[0] - aj[0] * p[1]] if g.planar else np.cross(p, aj)
                idx, val = self.extend([], [], self.r, np.r_[aj, rot])
                M.add_row(idx, val, -limit.shift / rho, limit.shift / rho, f"shift{j}")
        if math.isfinite(limit.turn):
            if g.planar:
                M.add_row([int(self.r[2])], [1.0], -limit.turn, limit.turn, "turn")
                return
            for j, aj in enumerate(a):
                idx, val = self.extend([], [], self.r[k:], aj)
                M.add_row(idx, val, -limit.turn / rho, limit.turn / rho, f"turn{j}")

    # ------------------------------------------------------------------ object wrench

    def add_object_equilibrium(
        self, wrench: NDArray[np.float64], direction: NDArray[np.float64] | None = None,
        cap: float = 0.0,
    ) -> int | None:  # fmt: skip
        """``G c + wrench + s direction = 0`` (eq. object_eq); with ``direction`` a new
        variable ``s in [0, cap]`` (its index is returned), else None. Round-off in
        ``wrench`` and ``direction`` is zeroed first (:func:`clean_wrench`)."""
        M, G = self.model, self.G
        wrench = self._clean_wrench(wrench)
        if direction is not None:
            direction = self._clean_wrench(direction, own=True)
        s = None if direction is None else M.add_var(0.0, cap, "C", "s")
        for row in range(G.shape[0]):
            idx, val = self.extend([], [], self.c.reshape(-1), G[row])
            if s is not None and direction[row] != 0:
                idx, val = idx + [s], val + [float(direction[row])]
            M.add_constraint(idx, val, "==", -float(wrench[row]), f"object{row}")
        return s

    def _clean_wrench(self, w: NDArray[np.float64], own: bool = False) -> NDArray[np.float64]:
        """:func:`clean_wrench` at the problem's force scale (``own``: at ``w``'s own, for a
        direction, whose length is arbitrary)."""
        g = self.grasp
        L = length_scale(g)
        w = np.asarray(w, dtype=float)
        scale = self.bounds.scale
        if own:
            k = 2 if g.planar else 3
            scale = max(float(np.abs(w[:k]).max()), float(np.abs(w[k:]).max()) / L)
        return clean_wrench(w, scale, L, g.planar)

    def add_net_wrench(self, wrench: NDArray[np.float64], weights: NDArray[np.float64]) -> None:
        """Object equilibrium dropped (thesis sec. iterative): the net wrench
        ``G c + wrench = e+ - e-`` is free and the objective is ``sum weights (e+ + e-)``, its
        weighted 1-norm."""
        M, G = self.model, self.G
        wrench = self._clean_wrench(wrench)
        ep = M.add_vars(G.shape[0], 0.0, INF, "C", "e+")
        em = M.add_vars(G.shape[0], 0.0, INF, "C", "e-")
        for row in range(G.shape[0]):
            idx, val = self.extend([ep[row], em[row]], [-1.0, 1.0], self.c.reshape(-1), G[row])
            M.add_constraint(idx, val, "==", -float(wrench[row]), f"net{row}")
        M.set_objective(np.concatenate([ep, em]), np.concatenate([weights, weights]))

    def add_motion_ray(
        self, start: NDArray[np.float64], direction: NDArray[np.float64], gamma: float
    ) -> int:
        """``r = start + s direction`` with ``0 <= s <= gamma`` (eq. movement); returns s."""
        M = self.model
        s = M.add_var(0.0, gamma, "C", "step")
        for j in range(len(start)):
            idx, val = [int(self.r[j])], [1.0]
            if direction[j] != 0:
                idx, val = idx + [s], val + [-float(direction[j])]
            M.add_constraint(idx, val, "==", float(start[j]), f"ray{j}")
        return s

    # ------------------------------------------------------------------ answers

    def tidy(
        self, x: NDArray[np.float64], rtol: float = 1e-10, lp: MipModel | None = None
    ) -> NDArray[np.float64] | None:
        """The least-motion point with ``x``'s binaries and objective value: the LP of
        :meth:`MipModel.fixed` plus ``objective within rtol of x's``, minimising the weighted
        1-norm of the virtual motion (translations, rotations times ``L``, joint motions
        times their lever ``|J_j|``: all in contact-displacement units). Motions that load no
        spring are otherwise arbitrary, and a simplex vertex can put them anywhere. None if
        the LP fails (the caller keeps ``x``). ``lp``: a fixed LP of this model's variables
        to use instead (e.g. with more rows: ``exact`` fixes slide directions), copied."""
        from ..mip import solve as mip_solve

        lp = self.model.fixed(x) if lp is None else lp.fixed(x)
        obj = self.model.objective
        nz = np.flatnonzero(obj)
        if nz.size:
            val = float(obj @ x[: obj.size])
            slack = rtol * max(1.0, abs(val))
            if self.model.maximize:
                lp.add_row(nz, obj[nz], val - slack, INF, "objective")
            else:
                lp.add_row(nz, obj[nz], -INF, val + slack, "objective")
        g = self.grasp
        kk = 2 if g.planar else 3
        L = length_scale(g)
        wr = np.r_[np.ones(kk), np.full(g.wrench_dim - kk, L)]
        motion, weight = list(self.r), list(wr)
        if self.q is not None:
            cols = np.linalg.norm(self.J, axis=0)
            motion += list(self.q)
            weight += list(np.where(cols > 0, cols, 1.0))
        idx, val = [], []
        for j, w in zip(motion, weight, strict=True):
            t = lp.add_var(0.0, INF, "C", f"|{lp.var_names[j]}|")  # t >= |x_j|
            lp.add_row([t, j], [1.0, -1.0], 0.0, INF)
            lp.add_row([t, j], [1.0, 1.0], 0.0, INF)
            idx.append(t)
            val.append(float(w))
        lp.set_objective(idx, val)
        res = mip_solve(lp, backend="highs", polish=False)
        if res.status != "optimal" or res.x is None:
            return None
        return res.x[: self.model.n_vars]

    def point(self, x: NDArray[np.float64]) -> ExactPoint:
        """The grasp quantities of a model solution ``x``."""
        B = self.bounds.force
        c = x[self.c]
        at = bool(np.any(c[:, 0] >= 0.99 * B) or np.any(x[self.u] >= 0.99 * B))

        q = f = z = None
        if self.hand is not None:
            q, f, z = x[self.q], x[self.f], np.round(x[self.z]) == 1
            fc = self.hand[1] if self.fc is None else x[self.fc]
            at = at or bool(np.any(f - fc >= 0.99 * self.bounds.excess))
            f = f - self.stiffness * (x[self.v] - self.gap)  # the physical force
            moved = np.where(self.backdrivable, 0.0, x[self.v])  # a free transmission: no bound
            at = at or bool(np.any(moved >= 0.99 * self.bounds.motion))
        return ExactPoint(c, x[self.r], q, f, np.round(x[self.y]) == 1, z, at, x)

    def states(self, pt: ExactPoint, tol: float = 1e-9) -> NDArray[np.str_]:
        """Per contact: ``"detach"`` (open), ``"stick"`` (closed, no tangential motion) or
        ``"slip"`` (closed, ``|d_t| > tol (1 + |d|)``)."""
        d = self.grasp.contact_motion(pt.motion, pt.hand_motion)
        slide = np.linalg.norm(d[:, 1:], axis=1) > tol * (1.0 + np.abs(d).max(initial=0.0))
        out = np.where(slide, "slip", "stick")
        return np.where(pt.closed, out, "detach")
