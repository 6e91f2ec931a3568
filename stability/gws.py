"""Grasp wrench space baseline: force closure and Ferrari-Canny (``method="gws"``).

The classic test of grasp stability (Ferrari and Canny 1992; thesis sec. 2 and
sec. 4, fig. "GWS"): a wrench ``w`` is called resistible when contact forces in
the friction cones balance it,

    exists c:  G c + w = 0,   c_i in FC_i  for every contact i,

with ``FC_i = {(c_n, c_t): |c_t| <= mu_i c_n}``. This asks only whether
balancing forces *exist*, not whether they *arise*: the method ignores preload,
the compliance (virtual spring) model and maximum dissipation, which is why the
thesis shows it calling grasps stable that are not (e.g. the three-contact grasp
under ``w = (0, 1, 0)`` without preload). It serves as a baseline.

Friction cones
--------------
Planar cones are exact: a planar cone is the conic hull of its two edges
``(c_n, c_t) = (1, +mu)`` and ``(1, -mu)``. Spatial cones are replaced by the
pyramid with ``edges`` edges inscribed in the circular cone,

    e_k = (1, mu cos(theta_k), mu sin(theta_k)),   theta_k = 2 pi k / edges,

in the contact frame ``[n, t1, t2]`` (``k = 0 .. edges-1``). The pyramid is an
*inner* approximation: every force it admits satisfies ``|c_t| <= mu c_n``, so
``stable`` with few edges implies ``stable`` with more and with the exact cone;
``unstable`` may be an artefact of the linearisation (the pyramid's inscribed
radius is ``mu cos(pi / edges)``).

Forces are parametrised by non-negative edge weights ``lam >= 0``:
``c_i = sum_k lam_ik e_k``, so ``c_in = sum_k lam_ik``.

Conventions follow docs/design.md: contact frames ``[n, t]`` / ``[n, t1, t2]`` with
``n`` pointing into the object, forces applied by the hand on the object [N],
wrenches ``(fx, fy, tz)`` or ``(fx, fy, fz, tx, ty, tz)`` about the object-frame
origin [N, N m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

from ._lp import solve_lp
from .api import register
from .errors import GraspError, SolverError
from .grasp import Grasp
from .options import Deadline, MethodOptions
from .queries import Existence, MaxDisturbance, Query, checked_base, checked_direction_cap
from .solution import Solution

__all__ = [
    "GwsOptions",
    "primitive_wrenches",
    "ferrari_canny",
    "force_closure",
    "solve_gws",
    "cone_edges",
]

_IGNORES = "preload, compliance, maximum dissipation"


# -- cones ----------------------------------------------------------------------------
def _check_edges(edges: object) -> int:
    if isinstance(edges, bool) or not isinstance(edges, int | np.integer) or int(edges) < 3:
        raise GraspError(f"edges (friction pyramid edges) must be an integer >= 3, got {edges!r}")
    return int(edges)


def cone_edges(grasp: Grasp, edges: int = 8) -> NDArray[np.float64]:
    """Friction cone edges in contact frames, normalised to ``c_n = 1``.

    Returns an ``(m, k, dim)`` array: ``k = 2`` planar (the exact cone,
    ``(1, +mu)`` and ``(1, -mu)``; ``edges`` is validated but unused), ``k =
    edges`` spatial (``(1, mu cos theta_j, mu sin theta_j)``, ``theta_j = 2 pi
    j / edges``, a pyramid inscribed in the circular cone). Dimensionless.

    Raises
    ------
    GraspError
        ``edges`` not an integer ``>= 3``.
    """
    edges = _check_edges(edges)
    mu = grasp.mu
    if grasp.planar:
        sign = np.array([1.0, -1.0])
        out = np.empty((grasp.m, 2, 2))
        out[:, :, 0] = 1.0
        out[:, :, 1] = mu[:, None] * sign[None, :]
        return out
    theta = 2.0 * np.pi * np.arange(edges) / edges
    out = np.empty((grasp.m, edges, 3))
    out[:, :, 0] = 1.0
    out[:, :, 1] = mu[:, None] * np.cos(theta)[None, :]
    out[:, :, 2] = mu[:, None] * np.sin(theta)[None, :]
    return out


def _edge_matrix(grasp: Grasp, edges: int) -> NDArray[np.float64]:
    """Block-diagonal ``E`` (dim m, K) with ``c = E lam`` (stacked contact forces)."""
    e = cone_edges(grasp, edges)  # (m, k, dim)
    m, k, dim = e.shape
    E = np.zeros((m * dim, m * k))
    for i in range(m):
        E[i * dim : (i + 1) * dim, i * k : (i + 1) * k] = e[i].T
    return E


def primitive_wrenches(grasp: Grasp, edges: int = 8) -> NDArray[np.float64]:
    """Wrenches of the friction-cone edge forces: ``(K, wrench_dim)``.

    Row ``i k + j`` is ``G_i e_ij``: the wrench on the object [N, N m] of the
    unit-normal edge force ``e_ij`` (``c_n = 1`` N) at contact ``i``, about the
    object-frame origin. ``K = 2 m`` planar (exact cone), ``K = edges * m``
    spatial (inscribed pyramid, see :func:`cone_edges`). The convex hull of
    these rows is the L1 grasp wrench space: all ``G c`` with ``c`` in the
    (linearised) cones and ``sum_i c_in = 1``.

    Raises
    ------
    GraspError
        ``edges`` not an integer ``>= 3``.
    """
    return np.ascontiguousarray((grasp.G @ _edge_matrix(grasp, edges)).T)


# -- Ferrari-Canny ----------------------------------------------------------------------
def ferrari_canny(grasp: Grasp, edges: int = 8, torque_scale: float = 1.0) -> float:
    """Ferrari-Canny epsilon metric of the L1 grasp wrench space.

    ``eps = min over facets f of (-b_f)``, the radius of the largest ball centred
    at the origin inside ``conv(primitive_wrenches)``, where the hull is
    ``{x : a_f . x + b_f <= 0}`` with unit ``a_f``. Torques are divided by
    ``torque_scale`` [m] first, so ``eps`` is in newtons per newton of total
    normal force (the hull is that of ``sum c_n = 1``). Scale ``torque_scale``
    to a characteristic object length to make forces and torques comparable.

    Returns 0.0 when the origin is not strictly inside the hull, including
    hulls of lower dimension than the wrench space (too few contacts, no
    friction, collinear geometry): such grasps have no force closure.

    Raises
    ------
    GraspError
        ``edges`` not an integer ``>= 3``, or ``torque_scale`` not finite and > 0.
    """
    try:
        ts = float(torque_scale)
    except (TypeError, ValueError) as exc:
        raise GraspError(f"torque_scale must be a positive number, got {torque_scale!r}") from exc
    if not (np.isfinite(ts) and ts > 0):
        raise GraspError(f"torque_scale must be finite and > 0 [m], got {torque_scale!r}")
    W = primitive_wrenches(grasp, edges)
    nf = 2 if grasp.planar else 3
    W[:, nf:] /= ts
    K, d = W.shape
    if K < d + 1:
        return 0.0
    # Quick rank test: a hull of lower dimension cannot contain a ball.
    scale = max(1.0, float(np.abs(W).max()))
    if np.linalg.matrix_rank(W - W.mean(axis=0), tol=1e-10 * scale) < d:
        return 0.0
    try:
        hull = ConvexHull(W)
    except QhullError:
        return 0.0
    eq = hull.equations
    eps = float(np.min(-eq[:, -1]))
    if not np.isfinite(eps) or eps <= 1e-12 * scale:
        return 0.0
    return eps


def force_closure(grasp: Grasp, edges: int = 8) -> bool:
    """Force closure with the (linearised) friction cones: ``ferrari_canny > 1e-12``.

    True iff every wrench can be balanced by contact forces in the cones
    (origin strictly inside the convex hull of :func:`primitive_wrenches`).
    Spatial cones are inscribed pyramids, so ``True`` is conservative.
    """
    return ferrari_canny(grasp, edges) > 1e-12


# -- LPs ------------------------------------------------------------------------------
def _solve_lp(
    cost: NDArray[np.float64],
    A: NDArray[np.float64],
    row_lower: NDArray[np.float64],
    row_upper: NDArray[np.float64],
    col_lower: NDArray[np.float64],
    col_upper: NDArray[np.float64],
) -> tuple[NDArray[np.float64] | None, int]:
    """Minimise ``cost . x`` s.t. ``row_lower <= A x <= row_upper``, column bounds.

    Returns ``(x, simplex_iterations)``, ``x`` None when infeasible (both LPs
    here have bounded objectives). Raises SolverError on any other status.
    """
    res = solve_lp(cost, A, row_lower, row_upper, col_lower, col_upper, feas_tol=1e-10)
    return res.x, res.iterations


def _forces(grasp: Grasp, E: NDArray[np.float64], lam: NDArray[np.float64]) -> NDArray:
    lam = np.maximum(lam, 0.0)  # remove solver round-off below the bound
    return (E @ lam).reshape(grasp.m, grasp.dim)


@dataclass(frozen=True)
class GwsOptions(MethodOptions):
    """Options of ``method="gws"``: ``edges``, the sides of each spatial contact's inscribed
    friction pyramid (planar cones are exact)."""

    edges: int = 8

    def check(self) -> None:
        _check_edges(self.edges)


@register(
    "gws",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=True,
    options=GwsOptions,
    hand=False,
    compliance=True,  # its answer ignores every spring, unit or not
    summary=(
        "grasp wrench space baseline (Ferrari-Canny): balancing forces exist in the "
        "friction cones; ignores preload, compliance and maximum dissipation"
    ),
)
def solve_gws(grasp: Grasp, query: Query, opts: GwsOptions | None = None,
              deadline: Deadline | None = None) -> Solution:  # fmt: skip
    """Answer ``query`` with the grasp wrench space model (one LP, HiGHS; ``edges`` is
    ``opts.edges``; the LP takes no time limit, ``deadline`` is not read).

    Existence(wrench=w): stable iff ``lam >= 0`` exists with ``G E lam + w = 0``
    (``c = E lam``, cones exact planar, ``edges``-edge inscribed pyramids
    spatial). Among balancing forces it returns one of least total normal force
    ``sum_i c_in`` [N]; ``forces`` is None when unstable.

    MaxDisturbance(direction=d, cap): on the L1 grasp wrench space,

        value = max s  s.t.  G c + s d = 0,  c in cones,  sum_i c_in <= 1,  0 <= s <= cap,

    i.e. how far the hull of :func:`primitive_wrenches` (plus the origin)
    reaches along ``-d``: the wrench ``s d`` [N, N m] resisted per newton of
    total normal force. ``stable`` is always True (``s = 0`` with ``c = 0``);
    ``stats["capped"]`` flags ``value >= cap``. ``forces`` are those at the
    optimum.

    ``preload`` is validated and ignored; ``stats["ignores"]`` says so. No
    ``motion`` or ``states``: the model has none.

    Raises
    ------
    GraspError
        Bad ``edges``, wrench/direction (wrong size, NaN, zero direction),
        negative preload or cap.
    SolverError
        HiGHS ends with a status other than optimal or infeasible.
    """
    edges = (GwsOptions() if opts is None else opts).edges
    if not isinstance(query, Existence | MaxDisturbance):
        raise GraspError(f"gws answers Existence and MaxDisturbance, got {type(query).__name__}")
    grasp.per_contact(query.preload, "preload")  # validated for consistency; ignored
    E = _edge_matrix(grasp, edges)
    GE = grasp.G @ E  # (wd, K)
    wd, K = GE.shape
    stats: dict[str, object] = {
        "ignores": _IGNORES,
        "edges": 2 if grasp.planar else edges,
        "exact_cone": grasp.planar,
        "lps": 1,
    }
    if isinstance(query, Existence):
        w = grasp.wrench(query.wrench)
        lam, iters = _solve_lp(
            cost=np.ones(K),  # sum of lam = total normal force
            A=GE,
            row_lower=-w,
            row_upper=-w,
            col_lower=np.zeros(K),
            col_upper=np.full(K, np.inf),
        )
        stats["iterations"] = iters
        if lam is None:
            return Solution(False, "gws", grasp, query, forces=None, stats=stats)
        return Solution(True, "gws", grasp, query, forces=_forces(grasp, E, lam), stats=stats)

    d, cap = checked_direction_cap(grasp, query)
    base = checked_base(grasp, query)
    # variables x = (lam (K), s); rows: G E lam + s d = -base, sum lam <= 1
    A = np.zeros((wd + 1, K + 1))
    A[:wd, :K] = GE
    A[:wd, K] = d
    A[wd, :K] = 1.0
    cost = np.zeros(K + 1)
    cost[K] = -1.0
    row_lower = np.concatenate([-base, [-np.inf]])
    row_upper = np.concatenate([-base, [1.0]])
    x, iters = _solve_lp(
        cost,
        A,
        row_lower,
        row_upper,
        col_lower=np.zeros(K + 1),
        col_upper=np.concatenate([np.full(K, np.inf), [cap]]),
    )
    stats["iterations"] = iters
    if x is None:
        if not base.any():  # cannot happen: s = 0, c = 0 is feasible
            raise SolverError("gws MaxDisturbance LP infeasible although s = 0 is feasible")
        stats["capped"] = False  # the base alone is outside the grasp wrench space
        return Solution(False, "gws", grasp, query, forces=None, stats=stats)
    s = float(min(max(x[K], 0.0), cap))
    stats["capped"] = bool(s >= cap * (1.0 - 1e-12))
    forces = _forces(grasp, E, x[:K])
    return Solution(True, "gws", grasp, query, forces=forces, value=s, stats=stats)
