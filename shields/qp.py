"""The linearised-compliance QP shield for in-hand manipulation (thesis sec. "Constructing a
shield for in-hand manipulation", eqs. force_constr .. optimization).

Given the agent's action ``a`` (servo setpoint change ``dq = s a``, ``s`` the env's
``max_setpoint_step`` [rad]) at the current MuJoCo state, :class:`GraspQP` returns the action
``a~`` nearest to ``a`` whose one-step prediction under the linearised grasp
(:func:`shields.compliance.linearize`: ``c' = c + E dq``, ``u' = u + F dq``) keeps a
force-closure subset of the contacts stable and the object inside its box::

    minimise  ||a~ - a||^2
    s.t.      c'_n,i >= c_min                                   shielded contacts i
              e_j . c'_t,i + rho_i |c'_tau,i| <= mu_i cos(pi / k) c'_n,i,  j = 1..k
              box_low <= p' <= box_high                          object position [m], world
              tilt_low <= r_x', r_y' <= tilt_high                object tilt [rad]
              a~_j = a_j  for every servo j in the kinematic chain of an unshielded contact
              a~ in [-1, 1]^l, ctrl + s a~ within the servos' ctrlrange

The friction constraint's right-hand side is ``mu c_n`` (the thesis prints ``mu t_normal``)
and the polygon with ``k`` edges inscribed in the circle of radius ``mu c_n`` has the apothem
``mu cos(pi / k) c_n``. The four-finger env's contacts also have torsional friction
(``condim`` 4: MuJoCo's elliptic cone is ``|c_t / mu|^2 + (c_tau / mu_tau)^2 <= c_n^2``);
with ``rho = cos(pi / k) mu / mu_tau`` the constraint above (2k rows, one per sign of
``c_tau``) is a polyhedral cone inscribed in that cone: it gives ``|c_t| <= mu c_n - |s|``
with ``s = mu c_tau / mu_tau``, and ``sqrt(|c_t|^2 + s^2) <= |c_t| + |s|``. Without
torsional friction (``rho = 0``) it is the thesis' cone. The tilt angles are the thesis'
(eq. rot_constr): with ``z`` the object's z axis in world coordinates, ``r_x = atan2(z_y,
z_z)`` and ``r_y = atan2(-z_x, z_z)`` (the signed angle between the projection of ``z`` onto
the world yz (xz) plane and world +Z), linearised in the object's rotation. A box or tilt
bound the object already violates is relaxed to its current value (the shield then forbids
moving further out).

Contact subsets (thesis' enumeration): the contacts of one hand link are shielded or not
together (a link is the unit the observation reports). Every set of at least two touching
links whose contacts are in force closure is a candidate, tested on the primitive wrenches
of the friction polygon the constraints enforce (its k vertices; the Ferrari-Canny
construction of :mod:`stability.gws`; the test: :mod:`shields.force_closure`), i.e. as point
contacts, which need three contacts.
``ShieldLimits(soft_closure=True)`` adds the torsional rays ``c_tau = +-mu_tau c_n`` of
condim-4 contacts (soft fingers), so that two fingertips can be a candidate; measured,
that shield releases more and drops the object more often (docs/shields.md), so it is not the
default. The servos of the
unshielded links' kinematic chains keep the agent's action. The candidate with the
smallest ``||a~ - a||`` wins, ties to the one that shields more links. For speed, each
set's QP is solved first and its force closure (one more QP) tested only if its solution
would win; the answer is the same as testing every set first.

The drop criteria of the shield study (docs/shield_study.md) switch rows off:
``ShieldLimits(contacts=False)`` keeps only the object's box and tilt (one QP over every
servo, no link sets), ``friction=False`` keeps only the shielded contacts' normal-force rows,
``tilt=False`` drops the tilt rows; ``GraspQP(drift_steps=H)`` adds the object's velocity
over ``H`` policy periods to the predicted pose.

Outcomes (``ShieldResult.status``):

* ``"safe"``: ``a`` itself satisfies some candidate's constraints; returned unchanged.
* ``"corrected"``: the best candidate's QP solution.
* ``"fallback"``: no candidate's QP is feasible: the zero action (keep every setpoint).
  The shield never raises inside a step for this.
* ``"no_closure"``: fewer than two links touch the object, or no set of them is in force
  closure: there is no stable grasp to keep, and ``a`` passes unchanged.

QP backends: DAQP (default; a dual active-set solver for small dense QPs, one solve per
candidate with ``H = I``, whose factorisation is trivial: the candidates differ in rows and
free variables, so there is nothing else to reuse) and OSQP (one setup per step with every
row; each candidate only updates the bounds: unshielded rows to +-inf, fixed servos to ``l
= u``. The sparsity pattern and its symbolic factorisation are reused, but OSQP refactors
numerically whenever a row changes type (loose, inequality, equality), which every candidate
does, and polishing factors a reduced system: about two numeric factorisations per
candidate). Both results are verified against the linear model before they are used.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import combinations
from typing import Any

import daqp
import mujoco
import numpy as np
import osqp
import scipy.sparse as sp
from numpy.typing import NDArray

from shields.compliance import GraspLinearization, ShieldError, linearize
from shields.force_closure import force_closure_wrenches
from shields.limits import ShieldLimits

__all__ = [
    "BACKENDS",
    "STATUSES",
    "GraspQP",
    "ShieldLimits",
    "ShieldProblem",
    "ShieldResult",
    "tilt_angles",
]

BACKENDS = ("daqp", "osqp")
STATUSES = ("safe", "corrected", "fallback", "no_closure")
_INF = 1e30  # DAQP's infinity
_TOL = 1e-6  # accepted constraint violation of a returned action under the linear model


@dataclass
class ShieldResult:
    """What the shield did in one step.

    action : (l,) the action to execute, ``a~``
    status : one of :data:`STATUSES`
    links : names of the shielded links (empty for ``"fallback"`` and ``"no_closure"``)
    correction : ``||a~ - a||`` (Euclidean, action units)
    candidates : force-closure link sets found among those tested (1 when the agent's action
        is safe: the set it keeps); a set is tested only if its QP solution would win
    qps : QPs solved (one per link set that could be in force closure)
    violation : largest constraint violation of ``a~`` under the linear model, for its
        candidate's constraints (<= 1e-6 for ``"safe"`` and ``"corrected"``) [N, m, rad]
    solve_time_s : wall time of the whole shield call, linearisation included [s]
    """

    action: NDArray[np.float64]
    status: str
    links: tuple[str, ...]
    correction: float
    candidates: int
    qps: int
    violation: float
    solve_time_s: float


@dataclass
class ShieldProblem:
    """The constraints of one step, all as ``low <= A a~ <= high`` (for tests and logging).

    lin : the linearised grasp; groups : contact indices of each touching hand link;
    links : their names; chains : (n_groups, l) servos in each link's kinematic chain;
    A_contact (m, 1 + 2k, l), low_contact (m, 1 + 2k): rows of each contact (normal force,
    then the k friction edges with ``-rho c_tau``, then with ``+rho c_tau``; upper bound
    +inf); A_global (5, l), low_global, high_global:
    object position (3) and tilt (2) rows; x_low, x_high: action bounds (l,);
    W_groups : per link, the primitive wrenches (contacts, rays, 6) of its contacts'
    inscribed cones (the rows' extreme rays; torques divided by the grasp's largest contact
    distance from the object origin); soft_groups : per link, its contacts with torsional
    friction.
    """

    lin: GraspLinearization
    groups: list[list[int]]
    links: list[str]
    chains: NDArray[np.bool_]
    A_contact: NDArray[np.float64]
    low_contact: NDArray[np.float64]
    A_global: NDArray[np.float64]
    low_global: NDArray[np.float64]
    high_global: NDArray[np.float64]
    x_low: NDArray[np.float64]
    x_high: NDArray[np.float64]
    W_groups: list[NDArray[np.float64]]
    soft_groups: list[int]
    _closure: dict[int, bool] = field(default_factory=dict)
    _candidates: list[int] | None = None
    _blocks: list[tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None

    def members(self, mask: int) -> list[int]:
        """Indices of the links (groups) in the bit mask ``mask``."""
        return [g for g in range(len(self.groups)) if mask >> g & 1]

    def _possible(self, mask: int) -> bool:
        """At least two links and enough contacts for force closure: three point contacts,
        or two of which one has torsional friction (a soft finger)."""
        members = self.members(mask)
        n_contacts = sum(len(self.groups[g]) for g in members)
        soft = sum(self.soft_groups[g] for g in members)
        return len(members) >= 2 and n_contacts >= (2 if soft else 3)

    def closure(self, mask: int) -> bool:
        """Force closure of the contacts of the links in ``mask`` (memoised; a superset of a
        force-closure set is one; see :meth:`_possible`)."""
        hit = self._closure.get(mask)
        if hit is not None:
            return hit
        members = self.members(mask)
        if not self._possible(mask):
            ok = False
        elif any(self._closure.get(mask & ~(1 << g), False) for g in members):
            ok = True
        else:
            W = np.concatenate([self.W_groups[g] for g in members])  # (contacts, k, 6)
            ok = force_closure_wrenches(W.reshape(-1, 6))
        self._closure[mask] = ok
        return ok

    def known_closure(self, mask: int) -> bool:
        """Whether :meth:`closure` has found the link set ``mask`` in force closure (its memo
        only: tests nothing new)."""
        return self._closure.get(mask, False)

    def link_sets(self) -> list[int]:
        """Bit masks of the link sets that could be in force closure (:meth:`_possible`), the
        largest first."""
        n = len(self.groups)
        return [
            mask for size in range(n, 1, -1) for mask in _masks(n, size) if self._possible(mask)
        ]

    @property
    def candidates(self) -> list[int]:
        """Bit masks of the link sets (>= 2 links) in force closure, smallest first."""
        if self._candidates is None:
            n = len(self.groups)
            self._candidates = [
                mask for size in range(2, n + 1) for mask in _masks(n, size) if self.closure(mask)
            ]
        return self._candidates

    def rows(self, mask: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray]:
        """``(A, low, high)`` of candidate ``mask``: its shielded contacts' rows, then the
        global rows."""
        if self._blocks is None:
            nl = self.A_global.shape[1]
            self._blocks = [
                (self.A_contact[members].reshape(-1, nl), self.low_contact[members].reshape(-1))
                for members in self.groups
            ]
        sel = [self._blocks[g] for g in self.members(mask)]
        A = np.concatenate([b[0] for b in sel] + [self.A_global])
        low = np.concatenate([b[1] for b in sel] + [self.low_global])
        high = np.full(len(low), np.inf)
        high[len(low) - len(self.high_global) :] = self.high_global
        return A, low, high

    def fixed(self, mask: int) -> NDArray[np.bool_]:
        """Servos the candidate ``mask`` fixes to the agent's action (unshielded chains)."""
        out = np.zeros(self.chains.shape[1], dtype=bool)
        for g in range(len(self.groups)):
            if not mask >> g & 1:
                out |= self.chains[g]
        return out

    def violation(
        self,
        mask: int,
        x: NDArray[np.float64],
        rows: tuple[NDArray[np.float64], NDArray[np.float64], NDArray] | None = None,
    ) -> float:
        """Largest violation of candidate ``mask``'s rows (``rows``: :meth:`rows` of it, if
        already built) and the action bounds by ``x``."""
        A, low, high = self.rows(mask) if rows is None else rows
        y = A @ x
        v = np.concatenate([low - y, y - high, self.x_low - x, x - self.x_high])
        worst = float(v.max())
        return max(worst, 0.0) if np.isfinite(worst) else np.inf  # NaN: not verified


def tilt_angles(object_mat: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray]:
    """``(r, dr)``: the thesis' tilt angles ``r = (r_x, r_y)`` [rad] of an object with the
    rotation matrix ``object_mat`` (columns: its axes in world), and their gradient (2, 3)
    with respect to a small world rotation vector ``dtheta`` (``r' ~ r + dr dtheta``)."""
    zx, zy, zz = np.asarray(object_mat, dtype=np.float64)[:, 2].tolist()
    r = np.array([math.atan2(zy, zz), math.atan2(-zx, zz)])
    # dr = g . dz with dz = dtheta x z, so dr/dtheta = z x g; with g_x = (0, zz, -zy) / n_x
    # and g_y = (-zz, 0, zx) / n_y, written out:
    n_x, n_y = max(zy * zy + zz * zz, 1e-300), max(zx * zx + zz * zz, 1e-300)
    dr = np.array(
        [
            [(-zy * zy - zz * zz) / n_x, zx * zy / n_x, zx * zz / n_x],
            [zx * zy / n_y, (-zx * zx - zz * zz) / n_y, zy * zz / n_y],
        ]
    )
    return r, dr


def _pyramid(edges: int) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """Facet normals ``e_j`` (k, 2) at ``2 pi j / k``, the apothem ``cos(pi / k)`` of the
    unit-circumradius k-gon, and its vertices (k, 2) at ``2 pi j / k + pi / k``."""
    theta = 2.0 * np.pi * np.arange(edges) / edges
    v = theta + np.pi / edges
    return (
        np.stack([np.cos(theta), np.sin(theta)], axis=1),
        float(np.cos(np.pi / edges)),
        np.stack([np.cos(v), np.sin(v)], axis=1),
    )


class GraspQP:
    """The QP shield of the module docstring for one MuJoCo model.

    Parameters
    ----------
    model : the scene (position servos on hinges, elliptic cone; see
        :func:`shields.compliance.linearize`).
    max_setpoint_step : ``s`` [rad]: the setpoint change is ``dq = s a~``.
    horizon : the prediction horizon [s] (the policy period).
    limits : :class:`ShieldLimits`.
    backend : ``"daqp"`` (default) or ``"osqp"``.
    object_body : the object's body name.
    drift_steps : 0 (default, the thesis): the object's pose changes only by ``F dq``. ``H >
        0``: it also keeps its current velocity for ``H`` policy periods, ``p' = p + H h v +
        F_p dq`` and ``r' = r + dr (H h omega + F_r dq)`` (``v``, ``omega`` the object's linear
        and angular velocity, world; ``h`` the horizon): the box and tilt rows then see where
        a falling or sliding object is heading, and a bound the object violates now is
        relaxed to its current value, not to the drifted one.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        max_setpoint_step: float,
        horizon: float,
        limits: ShieldLimits | None = None,
        backend: str = "daqp",
        object_body: str = "object",
        drift_steps: float = 0.0,
    ) -> None:
        if not (np.isfinite(drift_steps) and drift_steps >= 0):
            raise ShieldError(f"drift_steps must be a finite number >= 0, got {drift_steps!r}")
        self.drift = float(drift_steps) * float(horizon)  # [s]
        if backend not in BACKENDS:
            raise ShieldError(f"unknown QP backend {backend!r}; choose one of {BACKENDS}")
        if not (np.isfinite(max_setpoint_step) and max_setpoint_step > 0):
            raise ShieldError(f"max_setpoint_step must be > 0 [rad], got {max_setpoint_step!r}")
        if not (np.isfinite(horizon) and horizon > 0):
            raise ShieldError(f"horizon must be > 0 [s], got {horizon!r}")
        self.model = model
        self.step = float(max_setpoint_step)
        self.horizon = float(horizon)
        self.limits = ShieldLimits() if limits is None else limits
        if not isinstance(self.limits, ShieldLimits):
            raise ShieldError(f"limits must be a ShieldLimits, got {type(limits).__name__}")
        self.backend = backend
        self.object_body = object_body
        self._obj_dof = int(model.jnt_dofadr[model.body_jntadr[model.body(object_body).id]])
        self.l = model.nu
        self.ctrl_low = model.actuator_ctrlrange[:, 0].copy()
        self.ctrl_high = model.actuator_ctrlrange[:, 1].copy()
        limited = model.actuator_ctrllimited.astype(bool)
        self.ctrl_low[~limited], self.ctrl_high[~limited] = -np.inf, np.inf
        # servos in each body's kinematic chain (the dofs of the body and its ancestors)
        servo_dof = model.jnt_dofadr[model.actuator_trnid[:, 0]]
        self.chain = np.zeros((model.nbody, self.l), dtype=bool)
        for b in range(1, model.nbody):
            dofs = set(range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b]))
            self.chain[b] = self.chain[model.body_parentid[b]] | np.isin(servo_dof, list(dofs))
        self.dirs, self.apothem, self.verts = _pyramid(self.limits.edges)
        # check the model once (raises ShieldError for what linearize cannot model)
        linearize(model, mujoco.MjData(model), object_body, horizon=self.horizon)
        self.last_problem: ShieldProblem | None = None

    # -- the problem ---------------------------------------------------------------------
    def problem(self, data: mujoco.MjData) -> ShieldProblem:
        """Linearise the grasp at ``data`` and build every constraint row."""
        lin = linearize(self.model, data, self.object_body, horizon=self.horizon)
        lim, s = self.limits, self.step
        k = len(self.dirs)
        groups: dict[int, list[int]] = {}
        for i, b in enumerate(lin.bodies.tolist()):
            if self.model.body_weldid[b] != 0:  # hand links only; palm/floor are fixed
                groups.setdefault(b, []).append(i)
        bodies = list(groups)
        m, nc = lin.m, lin.nc
        E = lin.E.reshape(m, nc, self.l) * s
        c = lin.forces
        # rows per contact: the normal force, then for each pyramid edge j and sign +-:
        # mu' (c_n + E_n dq) - e_j . (c_t + E_t dq) -+ rho (c_tau + E_tau dq) >= 0
        # with mu' = mu cos(pi / k), rho = cos(pi / k) mu / mu_tau (0 without torsion)
        A_c = np.empty((m, 1 + 2 * k, self.l))
        low_c = np.empty((m, 1 + 2 * k))
        A_c[:, 0] = E[:, 0]
        low_c[:, 0] = lim.c_min - c[:, 0]
        mu_a = (lin.mu * self.apothem)[:, None]
        fric = mu_a[:, :, None] * E[:, None, 0] - self.dirs @ E[:, 1:3]
        fric_low = -(mu_a * c[:, :1] - c[:, 1:3] @ self.dirs.T)
        if nc == 4:
            tors = lin.mu_torsion > 0
            rho = np.where(tors, self.apothem * lin.mu / np.where(tors, lin.mu_torsion, 1.0), 0)
            t_row = (rho[:, None] * E[:, 3])[:, None, :]
            t_low = (rho * c[:, 3])[:, None]
        else:
            t_row, t_low = np.zeros((m, 1, self.l)), np.zeros((m, 1))
        A_c[:, 1 : 1 + k] = fric - t_row
        A_c[:, 1 + k :] = fric + t_row
        low_c[:, 1 : 1 + k] = fric_low + t_low
        low_c[:, 1 + k :] = fric_low - t_low
        if lim.relax_contacts:
            np.minimum(low_c, 0.0, out=low_c)  # a violated row: no worse than now
        if not lim.friction:
            low_c[:, 1:] = -_INF  # the normal-force rows only
        p = lin.object_pos
        r, dr = tilt_angles(lin.object_mat)
        A_g = np.concatenate([lin.F[:3], dr @ lin.F[3:]]) * s
        low_g = np.concatenate([np.asarray(lim.box_low) - p, lim.tilt_low - r])
        high_g = np.concatenate([np.asarray(lim.box_high) - p, lim.tilt_high - r])
        low_g, high_g = np.minimum(low_g, 0.0), np.maximum(high_g, 0.0)
        if self.drift > 0:  # the object keeps its velocity; violated bounds relaxed to now
            dof = self._obj_dof
            v = data.qvel[dof : dof + 3]
            w = lin.object_mat @ data.qvel[dof + 3 : dof + 6]  # body -> world
            shift = np.concatenate([v, dr @ w]) * self.drift
            low_g, high_g = low_g - shift, high_g - shift
        if not lim.tilt:
            low_g[3:], high_g[3:] = -_INF, _INF
        ctrl = data.ctrl
        x_low = np.maximum(-1.0, (self.ctrl_low - ctrl) / s)
        x_high = np.minimum(1.0, (self.ctrl_high - ctrl) / s)
        # primitive wrenches: the extreme rays (at c_n = 1) of the cone the rows above enforce,
        # i.e. the k vertices mu (cos, sin)(2 pi j / k + pi / k) of the friction polygon and,
        # with soft_closure and torsional friction, the rays c_tau = +-mu_tau (a soft-finger
        # contact; a point contact gets the normal twice, inside its cone); torques over L
        L = max(float(np.abs(lin.points - lin.object_pos).max(initial=0.0)), 1e-3)
        soft = nc == 4 and lim.soft_closure
        e = np.zeros((m, k + 2 if soft else k, nc))
        e[:, :, 0] = 1.0
        e[:, :k, 1:3] = lin.mu[:, None, None] * self.verts[None]
        if soft:
            e[:, k, 3], e[:, k + 1, 3] = lin.mu_torsion, -lin.mu_torsion
        Gm = lin.G.reshape(6, m, nc).transpose(1, 0, 2)  # (m, 6, nc)
        W = np.einsum("mwc,mkc->mkw", Gm, e)
        W[:, :, 3:] /= L
        prob = ShieldProblem(
            lin=lin,
            groups=[groups[b] for b in bodies],
            links=[lin.links[groups[b][0]] for b in bodies],
            chains=self.chain[bodies] if bodies else np.zeros((0, self.l), dtype=bool),
            A_contact=A_c,
            low_contact=low_c,
            A_global=A_g,
            low_global=low_g,
            high_global=high_g,
            x_low=np.minimum(x_low, 0.0),
            x_high=np.maximum(x_high, 0.0),
            W_groups=[W[groups[b]] for b in bodies],
            soft_groups=[
                int(np.count_nonzero(lin.mu_torsion[groups[b]] > 0)) if soft else 0 for b in bodies
            ],
        )
        return prob

    # -- the shield ----------------------------------------------------------------------
    def __call__(self, data: mujoco.MjData, action: NDArray[Any]) -> ShieldResult:
        """Shield ``action`` (l,) in ``[-1, 1]`` at the state ``data`` (after a step or
        ``mj_forward``)."""
        t0 = time.perf_counter()
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.l,):
            raise ShieldError(f"action must have shape ({self.l},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ShieldError(f"action contains NaN or inf: {a}")
        prob = self.problem(data)
        self.last_problem = prob
        a_eff = np.minimum(np.maximum(a, prob.x_low), prob.x_high)
        n = len(prob.groups)
        full = (1 << n) - 1
        finite = bool(np.isfinite(prob.A_contact).all() and np.isfinite(prob.A_global).all())
        finite = finite and bool(np.isfinite(prob.low_contact).all())

        def done(
            x: NDArray, status: str, mask: int, cands: int, qps: int, viol: float
        ) -> ShieldResult:
            links = tuple(prob.links[g] for g in prob.members(mask))
            return ShieldResult(
                action=x,
                status=status,
                links=links,
                correction=float(np.linalg.norm(x - a)),
                candidates=cands,
                qps=qps,
                violation=viol,
                solve_time_s=time.perf_counter() - t0,
            )

        if not finite:  # a broken state (NaN/inf in MuJoCo's data): nothing to trust
            return done(np.zeros(self.l), "fallback", 0, 0, 0, 0.0)
        if not self.limits.contacts:  # the object's box and tilt only: one QP, all free
            return self._global_only(prob, a, a_eff, done)
        # the agent's action: it is safe if the links whose constraints it satisfies are in
        # force closure (every candidate is a subset of that set or violated)
        tol = _TOL
        y_g = prob.A_global @ a_eff
        in_box = np.all(y_g >= prob.low_global - tol) and np.all(y_g <= prob.high_global + tol)
        if n >= 2 and in_box:
            slack = (prob.A_contact @ a_eff - prob.low_contact).min(axis=1)
            ok = 0
            for g, members in enumerate(prob.groups):
                if slack[members].min() >= -tol:
                    ok |= 1 << g
            if prob.closure(ok):
                return done(a.copy(), "safe", ok, 1, 0, prob.violation(ok, a_eff))
        if n < 2 or not prob.closure(full):
            return done(a.copy(), "no_closure", 0, 0, 0, 0.0)
        # every link set that could be in force closure (ShieldProblem._possible), the
        # largest first; a set's QP is solved first and its force closure tested only if its
        # solution would win (the closure test costs more than the QP)
        sets = prob.link_sets()
        solve = self._solve_daqp if self.backend == "daqp" else self._solve_osqp
        best_x, best_mask, best_obj, best_viol, qps, cands = None, 0, np.inf, 0.0, 0, 0
        for mask, x, rows in solve(prob, a, a_eff, sets):
            qps += 1
            if x is None:
                continue
            viol = prob.violation(mask, x, rows)
            if viol > tol:
                continue
            obj = float(np.sum((x - a) ** 2))
            better = obj < best_obj - 1e-12 or (
                obj <= best_obj + 1e-12 and bin(mask).count("1") > bin(best_mask).count("1")
            )
            if better and prob.closure(mask):
                best_x, best_mask, best_obj, best_viol = x, mask, obj, viol
        cands = sum(1 for mask in sets if prob.known_closure(mask))
        if best_x is None:
            return done(np.zeros(self.l), "fallback", 0, cands, qps, 0.0)
        return done(best_x, "corrected", best_mask, cands, qps, best_viol)

    def _global_only(self, prob: ShieldProblem, a: NDArray, a_eff: NDArray, done: Any) -> Any:
        """``ShieldLimits(contacts=False)``: the nearest action whose predicted object pose
        keeps the box and tilt rows (no link set, every servo free; one DAQP solve whatever
        the backend). ``"fallback"`` (zero action) when that QP is infeasible."""
        A, low, high = prob.A_global, prob.low_global, prob.high_global
        y = A @ a_eff
        if np.all(y >= low - _TOL) and np.all(y <= high + _TOL):
            return done(a.copy(), "safe", 0, 1, 0, 0.0)
        n = self.l
        bl = np.concatenate([prob.x_low, np.maximum(low, -_INF)])
        bu = np.concatenate([prob.x_high, np.minimum(high, _INF)])
        x, _, flag, _ = daqp.solve(_eye(n), -a, np.ascontiguousarray(A), bu, bl, _sense(len(bu)))
        if flag < 1:
            return done(np.zeros(n), "fallback", 0, 0, 1, 0.0)
        x = np.minimum(np.maximum(x, prob.x_low), prob.x_high)
        yx = A @ x
        viol = float(max(0.0, (low - yx).max(), (yx - high).max()))
        if viol > _TOL:
            return done(np.zeros(n), "fallback", 0, 0, 1, 0.0)
        return done(x, "corrected", 0, 0, 1, viol)

    def _solve_daqp(
        self, prob: ShieldProblem, a: NDArray, a_eff: NDArray, masks: list[int]
    ) -> _Solves:
        """One DAQP solve per link set over its free servos (``H = I``); yields ``(mask,
        x or None, rows)``."""
        for mask in masks:
            fixed = prob.fixed(mask)
            free = ~fixed
            nf = int(free.sum())
            rows = prob.rows(mask)
            if nf == 0:
                yield mask, None, rows
                continue
            A, low, high = rows
            shift = A[:, fixed] @ a_eff[fixed]
            bl = np.concatenate([prob.x_low[free], low - shift])
            bu = np.concatenate([prob.x_high[free], np.minimum(high - shift, _INF)])
            y, _, flag, _ = daqp.solve(
                _eye(nf), -a[free], np.ascontiguousarray(A[:, free]), bu, bl, _sense(len(bu))
            )
            if flag < 1:
                yield mask, None, rows
                continue
            x = a_eff.copy()
            x[free] = np.minimum(np.maximum(y, prob.x_low[free]), prob.x_high[free])
            yield mask, x, rows

    def _solve_osqp(
        self, prob: ShieldProblem, a: NDArray, a_eff: NDArray, masks: list[int]
    ) -> _Solves:
        """One OSQP setup (factorisation) per step; per candidate only bounds change; yields
        ``(mask, x or None, rows)``."""
        n = self.l
        m = prob.lin.m
        k1 = prob.A_contact.shape[1]
        A = np.concatenate([np.eye(n), prob.A_contact.reshape(-1, n), prob.A_global])
        n_c = m * k1
        low0 = np.concatenate([prob.x_low, np.full(n_c, -np.inf), prob.low_global])
        high0 = np.concatenate([prob.x_high, np.full(n_c, np.inf), prob.high_global])
        solver = osqp.OSQP()
        solver.setup(
            P=sp.identity(n, format="csc"), q=-a, A=sp.csc_matrix(A), l=low0, u=high0,
            verbose=False, eps_abs=1e-8, eps_rel=1e-8, polishing=True, max_iter=4000,
        )  # fmt: skip
        contact_rows = np.arange(n_c).reshape(m, k1) + n
        for mask in masks:
            low, high = low0.copy(), high0.copy()
            for g in prob.members(mask):
                contacts = prob.groups[g]
                low[contact_rows[contacts].reshape(-1)] = prob.low_contact[contacts].reshape(-1)
            fixed = prob.fixed(mask)
            low[:n][fixed] = high[:n][fixed] = a_eff[fixed]
            solver.update(l=low, u=high)
            res = solver.solve(raise_error=False)
            if res.info.status_val not in (1, 2):  # solved, solved inaccurate
                yield mask, None, None
                continue
            x = np.minimum(np.maximum(res.x, prob.x_low), prob.x_high)
            x[fixed] = a_eff[fixed]
            yield mask, x, None


_Solves = Iterator[tuple[int, NDArray[np.float64] | None, tuple | None]]


@lru_cache(maxsize=64)
def _eye(n: int) -> NDArray[np.float64]:
    return np.eye(n)


@lru_cache(maxsize=256)
def _sense(n: int) -> NDArray[np.int32]:
    return np.zeros(n, dtype=np.int32)


def _masks(n: int, size: int) -> Iterator[int]:
    """Bit masks of the ``size``-element subsets of ``range(n)``."""
    for combo in combinations(range(n), size):
        mask = 0
        for g in combo:
            mask |= 1 << g
        yield mask
