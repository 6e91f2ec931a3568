"""``method="modesearch"``: Coulomb friction with maximum dissipation by one branch-and-bound
tree over contact modes and slide arcs, one LP per node (the thesis' ch. 6 Discussion and
ch. 8: "make the refinement part of the branch and bound itself").

The model is the exact one of ch. 5 (:class:`~stability.model.coulomb.CoulombModel`:
unilateral springs with preload, nonbackdrivable actuators, equilibrium, tangential motions
``d_t``), with its on/off conditions and its friction law relaxed per node:

* per contact a **normal state**: undecided, closed (``u = 0``: ``c_n = p - d_n``) or open
  (``c_n = 0``); undecided keeps the convex hull of ``c_n u = 0`` in the box,
  ``c_n + u <= B``;
* per nonbackdrivable actuator: undecided, locked (``v = 0``) or moving (``f = f_c``);
  undecided keeps the hull ``(f - f_c) / E + v / V <= 1``;
* per contact a **tangential state**: undecided; sticking (``d_t = 0``) with friction in an
  arc ``[a, a + w]`` of directions; or sliding within an arc: friction ``c_t`` and the
  negative slide ``-d_t`` both in the arc's cone (``n_a . c_t >= 0``, ``n_b . c_t >= 0`` with
  the arc's inward normals, the same for ``-d_t``) and ``|c_t| = mu c_n`` relaxed to
  the chord, ``m . c_t >= mu c_n cos(w / 2)`` (``m`` the arc's mid direction). Friction is
  always within the outer octagon of the cone, and in an arc also within the tangents at
  its ends and middle (``e . c_t <= mu c_n``).

Every exact solution lies in some child of every node (the states split a closed set into
closed pieces that cover it: ``C``/``O``, locked/moving, stick / two half-circle slide arcs,
an arc into two), so the LP optimum of a node bounds every exact point in it: **the largest
bound over the open, unresolved and pruned nodes is a proven bound** on the query's optimum.
Branching takes the most violated complementarity, normal and actuator ones first, then
the largest misalignment of friction against the slide (or friction outside the cone),
and splits an arc between the friction's and the slide's angles; nodes are taken
best-first, deeper first on ties.

Exact points come from polishing only (:func:`stability.model.coulomb.slide_search`, the
certificate of ``refinement``): a node's modes and slide directions are fixed and the slide
angles optimised by sequential LP; the point must pass the exact conditions. A leaf whose LP
point satisfies every complementarity (within ``1e-7 (1 + B)``) is polished; so is a dive
every :data:`DIVE_EVERY` nodes. A leaf with an arc narrower than ``min_width`` whose polish
falls short keeps its bound as "unresolved".

Round-off: a node's bound is not HiGHS's objective but a safe dual bound (Neumaier and
Shcherbina, Math. Program. 99, 2004) from its duals: for any multipliers ``y`` of the rows
``L <= A x <= U`` and the box ``l <= x <= u``, ``c.x <= sum_i max(y_i L_i, y_i U_i) +
sum_j max(z_j l_j, z_j u_j)`` with ``z = c - A^T y``; every variable has finite bounds (the
motion box below), so the bound is finite, and it holds whatever the LP's tolerances. A
node proven infeasible by HiGHS is pruned only when its dual ray certifies it the same way;
otherwise it is solved again at tight tolerances, and kept with its parent's bound if it
still cannot be certified.

The box (``bound_factor``, default :data:`MODESEARCH_BOUND_FACTOR` times the query's force
scale): forces and separations ``B``, transmission motions ``V``, excess actuator forces
``E`` (:func:`~stability.model.problem.scale_bounds`) and the motions ``r``, ``q``, ``d_t``
(``motion_bound * 2 B``, as ``exact``). The bound holds for exact points inside it; an
exact point beyond the bound, or one at the box, grows it tenfold and the query is solved
again (:data:`BOX_RETRIES` times).

Status semantics are ``refinement``'s: ``"solved"`` only with an exact point that passes
:meth:`Solution.residuals`; ``lower``/``upper`` the bracket, the feasible side an exact
point's value and the other a proven bound; ``stats["certified"]`` when they meet within
``gap`` relative or ``abs_gap`` times the force scale absolute; a time-out returns the
bracket reached. ``Existence`` is "stable" only with an exact point and "unstable" only
when the tree is exhausted.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, fields
from typing import Any

import highspy
import numpy as np
from numpy.typing import NDArray

from ._lp import quiet_highs
from .api import register
from .errors import GraspError
from .grasp import Grasp
from .model.coulomb import CERTIFY_TRIES, CoulombModel, exact_conditions, slide_search, stuck_point
from .model.problem import ExactBounds, length_scale, scale_bounds
from .model.query import QueryData, add_query, query_value
from .model.run import bounds_stats, solution
from .queries import Existence, MaxDisturbance, OptimalCommands
from .solution import Solution

__all__ = ["ModeSearchOptions", "MODESEARCH_BOUND_FACTOR"]

MODESEARCH_BOUND_FACTOR = 1e3  # the default box, times the query's force scale
BOX_RETRIES = 2  # tenfold enlargements of the box when an exact point shows it cut
WEDGE = 0.3  # [rad] a sticking contact's friction wedge in a quick mode LP (Search.mode_node)
POLISH_EVERY = 30  # at most one dive's full polish per this many nodes taken
DIVE_EVERY = 10  # polish the node's point every this many nodes (an early incumbent)
OCTAGON = 8  # sides of the outer friction polygon at every node
HINF = highspy.kHighsInf
_OPT = highspy.HighsModelStatus.kOptimal
_INFEASIBLE = (highspy.HighsModelStatus.kInfeasible,)
TWO_PI = 2.0 * math.pi


@dataclass
class ModeSearchOptions:
    """Options of ``method="modesearch"``.

    ``time_limit`` [s] (None: none); ``gap``: relative width at which a bracket is closed
    (default 1e-4); ``abs_gap``: absolute width, as a fraction of the query's force scale
    (:func:`~stability.model.problem.scale_bounds`'s ``S``, in the value's units: divided
    by the direction's force for MaxDisturbance), default 1e-6, so that a value near zero
    closes too; ``bound_factor``: the box (module docstring); ``motion_bound``: the motions'
    box per ``2 B`` (as ``exact``); ``min_width`` [rad]: arcs narrower than this are not
    split; ``node_limit``: nodes before the search stops (``status="not_converged"``)."""

    time_limit: float | None = None
    gap: float = 1e-4
    abs_gap: float = 1e-6
    bound_factor: float = MODESEARCH_BOUND_FACTOR
    motion_bound: float = 4.0
    min_width: float = 1e-6
    node_limit: int = 1_000_000

    @classmethod
    def of(cls, options: dict[str, Any]) -> ModeSearchOptions:
        """From ``solve(..., **options)``; GraspError naming an unknown or bad option."""
        known = {f.name for f in fields(cls)}
        bad = sorted(set(options) - known)
        if bad:
            raise GraspError(f"unknown option(s) for method 'modesearch': {bad}; known: "
                             f"{sorted(known)}")  # fmt: skip
        o = cls(**options)
        checks = [
            ("time_limit", o.time_limit is None or (_finite(o.time_limit) and o.time_limit >= 0)),
            ("gap", _finite(o.gap) and 0.0 <= o.gap < 1.0),
            ("abs_gap", _finite(o.abs_gap) and 0.0 <= o.abs_gap < 1.0),
            ("bound_factor", _finite(o.bound_factor) and o.bound_factor >= 1.0),
            ("motion_bound", _finite(o.motion_bound) and o.motion_bound >= 1.0),
            ("min_width", _finite(o.min_width) and 0.0 < o.min_width < 1.0),
            ("node_limit", isinstance(o.node_limit, int | np.integer) and o.node_limit >= 1),
        ]
        for name, ok in checks:
            if not ok:
                raise GraspError(f"modesearch option {name}={getattr(o, name)!r} is out of range")
        return o


def _finite(v: Any) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


# A node: per contact the normal state ("U", "C", "O"), per contact the tangential state
# (kind, arc) with kind "U" (undecided), "S" (stick) or "A" (slide) and arc (start, width)
# [rad] or None, per actuator "U", "L" (locked) or "M" (moving).
Node = tuple[tuple[str, ...], tuple[tuple[str, tuple[float, float] | None], ...], tuple[str, ...]]


@dataclass
class NodeResult:
    """One node LP: ``bound`` a safe bound on the node's objective (the search maximises),
    ``x`` the LP point (None: infeasible), ``certified`` False where an infeasible node's
    proof could not be checked (it then keeps its parent's bound)."""

    bound: float | None
    x: NDArray[np.float64] | None
    certified: bool = True


class NodeLP:
    """The relaxation of one query as one persistent HiGHS LP whose bounds and arc rows
    change from node to node (module docstring). Variables are those of ``ex`` (a
    :class:`CoulombModel` with the query added): its linear rows, the hulls of its
    indicators, the outer octagon of each cone and eight arc rows per contact."""

    def __init__(self, ex: CoulombModel, data: QueryData) -> None:
        self.ex, self.prob = ex, ex.prob
        prob, M, g = ex.prob, ex.prob.model, ex.grasp
        self.m = g.m
        self.mu = np.asarray(g.mu, dtype=float)
        B = prob.bounds.force
        n = M.n_vars
        lb, ub = np.array(M.lb, dtype=float), np.array(M.ub, dtype=float)
        lb[prob.y], ub[prob.y] = 0.0, 0.0  # binaries: their rows are the hulls below
        self.has_hand = prob.hand is not None
        if self.has_hand:
            lb[prob.z], ub[prob.z] = 0.0, 0.0
            # a backdrivable transmission moves freely: boxed by the joints' box through R
            qbox = ub[prob.q]
            for a in np.flatnonzero(prob.backdrivable):
                lim = float(np.abs(prob.hand[0][:, a]) @ qbox)
                lb[prob.v[a]], ub[prob.v[a]] = -lim, lim
        rows: list[tuple[list[int], list[float], float, float]] = []
        for r in M.rows:
            rows.append((r.idx.tolist(), r.val.tolist(), r.lo, r.hi))
        for i in range(self.m):  # hull of c_n u = 0 in [0, B]^2
            rows.append(([int(prob.c[i, 0]), int(prob.u[i])], [1.0, 1.0], -HINF, B))
        self.act: list[int] = []  # nonbackdrivable actuators: the branched ones
        self.excess_row: dict[int, int] = {}
        if self.has_hand:
            R = prob.hand[0]
            E, V = prob.bounds.excess, prob.bounds.motion
            names = {r.name: k for k, r in enumerate(M.rows)}
            for a in range(R.shape[1]):
                if prob.backdrivable[a]:
                    continue
                self.act.append(a)
                f, v = int(prob.f[a]), int(prob.v[a])
                if prob.fc is None:  # (f - f_c) / E + v / V <= 1, f_c the command
                    fc = float(prob.hand[1][a])
                    rows.append(([f, v], [1.0 / E[a], 1.0 / V[a]], -HINF, 1.0 + fc / E[a]))
                else:
                    fcv = int(prob.fc[a])
                    rows.append(([f, fcv, v], [1.0 / E[a], -1.0 / E[a], 1.0 / V[a]], -HINF, 1.0))
                    self.excess_row[a] = names[f"excess{a}"]
        self.cone0 = len(rows)
        for i in range(self.m):  # outer octagon of the cone: e . c_t - mu c_n <= 0
            ci, ti = int(prob.c[i, 0]), [int(j) for j in prob.c[i, 1:]]
            for th in TWO_PI * np.arange(OCTAGON) / OCTAGON:
                rows.append(([ti[0], ti[1], ci], [math.cos(th), math.sin(th), -self.mu[i]],
                             -HINF, 0.0))  # fmt: skip
        self.arc0 = len(rows)
        for i in range(self.m):  # 8 arc rows per contact, free until a node sets them
            ci, ti = int(prob.c[i, 0]), [int(j) for j in prob.c[i, 1:]]
            di = [int(j) for j in ex.dt[i]]
            for k in range(8):
                idx = di if k in (2, 3) else ti + ([ci] if k >= 4 else [])
                rows.append((idx, [1.0] * len(idx), -HINF, HINF))
        nr = len(rows)
        A = np.zeros((nr, n))
        rlo, rhi = np.empty(nr), np.empty(nr)
        for k, (idx, val, lo, hi) in enumerate(rows):
            A[k, idx] = val
            rlo[k], rhi[k] = (-HINF if lo == -math.inf else lo), (HINF if hi == math.inf else hi)
        self.A, self.rlo, self.rhi = A, rlo, rhi
        self.lb, self.ub = np.where(np.isinf(lb), -HINF, lb), np.where(np.isinf(ub), HINF, ub)
        self.lb0, self.ub0 = self.lb.copy(), self.ub.copy()
        self.sign = 1.0 if M.maximize else -1.0  # the search maximises sign * objective
        self.cost = self.sign * np.asarray(M.objective, dtype=float)
        if not np.any(self.cost):  # Existence: any point will do; guide the LPs towards
            # complementary ones, min sum (c_n + u) + B sum ((f - f_c) / E + v / V): with
            # c_n - u fixed by the motion, its least c_n + u has min(c_n, u) = 0
            self.cost[prob.c[:, 0]] = self.cost[prob.u] = -1.0
            for a in self.act:
                self.cost[prob.f[a]] = -B / float(prob.bounds.excess[a])
                self.cost[prob.v[a]] = -B / float(prob.bounds.motion[a])
        h = self.h = quiet_highs()
        for opt, val in (("presolve", "off"), ("solver", "simplex"),
                         ("primal_feasibility_tolerance", 1e-9),
                         ("dual_feasibility_tolerance", 1e-9)):  # fmt: skip
            h.setOptionValue(opt, val)
        lp = highspy.HighsLp()
        lp.num_col_, lp.num_row_ = n, nr
        lp.col_cost_, lp.col_lower_, lp.col_upper_ = self.cost, self.lb, self.ub
        lp.row_lower_, lp.row_upper_ = rlo, rhi
        lp.sense_ = highspy.ObjSense.kMaximize
        nz_c, nz_r = np.nonzero(A.T)
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = np.concatenate([[0], np.cumsum(np.bincount(nz_c, minlength=n))])
        lp.a_matrix_.index_ = nz_r.astype(np.int32)
        lp.a_matrix_.value_ = A.T[nz_c, nz_r]
        lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, nr
        h.passModel(lp)
        self.n = n
        a_count = len(self.act)
        self.cur: Node = (("U",) * self.m, (("U", None),) * self.m, ("U",) * a_count)
        self.lp_count, self.lp_time, self.iterations = 0, 0.0, 0

    # ---------------------------------------------------------------- node state

    def root(self) -> Node:
        return (("U",) * self.m, (("U", None),) * self.m, ("U",) * len(self.act))

    def _col(self, j: int, lo: float, hi: float) -> None:
        j = int(j)
        if self.lb[j] != lo or self.ub[j] != hi:
            self.lb[j], self.ub[j] = lo, hi
            self.h.changeColBounds(j, lo, hi)

    def _row(self, r: int, lo: float, hi: float) -> None:
        if self.rlo[r] != lo or self.rhi[r] != hi:
            self.rlo[r], self.rhi[r] = lo, hi
            self.h.changeRowBounds(r, lo, hi)

    def _coef(self, r: int, j: int, v: float) -> None:
        j = int(j)
        if self.A[r, j] != v:
            self.A[r, j] = v
            self.h.changeCoeff(r, j, v)

    def _set_normal(self, i: int, st: str) -> None:
        p = self.prob
        cn, u = int(p.c[i, 0]), int(p.u[i])
        self._col(cn, 0.0, 0.0 if st == "O" else self.ub0[cn])
        self._col(u, 0.0, 0.0 if st == "C" else self.ub0[u])

    def _set_tan(self, i: int, st: tuple[str, tuple[float, float] | None]) -> None:
        ex = self.ex
        kind, arc = st
        for j in ex.dt[i]:
            j = int(j)
            if kind in ("S", "I"):
                self._col(j, 0.0, 0.0)
            else:
                self._col(j, self.lb0[j], self.ub0[j])
        r0 = self.arc0 + 8 * i
        if arc is None:
            for k in range(8):
                self._row(r0 + k, -HINF, HINF)
            return
        a, w = arc
        b = a + w
        mid = a + 0.5 * w
        na, nb = (-math.sin(a), math.cos(a)), (math.sin(b), -math.cos(b))
        mm = (math.cos(mid), math.sin(mid))
        ea, eb = (math.cos(a), math.sin(a)), (math.cos(b), math.sin(b))
        mu = float(self.mu[i])
        p = self.prob
        ci, ti = int(p.c[i, 0]), p.c[i, 1:]
        di = ex.dt[i]
        # rows: n_a.c_t >= 0, n_b.c_t >= 0, n_a.(-d_t) >= 0, n_b.(-d_t) >= 0,
        # m.c_t - mu cos(w/2) c_n >= 0 (the chord), m.c_t, e_a.c_t, e_b.c_t <= mu c_n
        spec = [(ti, na, None), (ti, nb, None), (di, (-na[0], -na[1]), None),
                (di, (-nb[0], -nb[1]), None), (ti, mm, -mu * math.cos(0.5 * w)),
                (ti, mm, -mu), (ti, ea, -mu), (ti, eb, -mu)]  # fmt: skip
        if kind == "I":  # inscribed: c_t within the chord, m.c_t <= mu cos(w/2) c_n
            spec[5] = (ti, mm, -mu * math.cos(0.5 * w))
        if w == 0.0:  # one direction: rows 2 and 3 would both state the line; -d_t . e_a >= 0
            spec[3] = (di, (-ea[0], -ea[1]), None)
        for k, (vv, vec, ccn) in enumerate(spec):
            self._coef(r0 + k, vv[0], vec[0])
            self._coef(r0 + k, vv[1], vec[1])
            if ccn is not None:
                self._coef(r0 + k, ci, ccn)
        ge = (0, 1, 2, 3, 4) if kind == "A" else (0, 1)
        le = (5,) if kind == "I" else (5, 6, 7)
        for k in range(8):
            if k in ge:
                self._row(r0 + k, 0.0, HINF)
            elif k in le:
                self._row(r0 + k, -HINF, 0.0)
            else:
                self._row(r0 + k, -HINF, HINF)

    def _set_act(self, k: int, st: str) -> None:
        p, a = self.prob, self.act[k]
        v = int(p.v[a])
        self._col(v, self.lb0[v], 0.0 if st == "L" else self.ub0[v])
        if p.fc is None:
            f = int(p.f[a])
            self._col(f, self.lb0[f], self.lb0[f] if st == "M" else self.ub0[f])
        else:
            r = self.excess_row[a]
            self._row(r, 0.0, 0.0 if st == "M" else float(p.bounds.excess[a]))

    def apply(self, node: Node) -> None:
        normal, tan, act = node
        cn, ct, ca = self.cur
        for i in range(self.m):
            if normal[i] != cn[i]:
                self._set_normal(i, normal[i])
            if tan[i] != ct[i]:
                self._set_tan(i, tan[i])
        for k in range(len(self.act)):
            if act[k] != ca[k]:
                self._set_act(k, act[k])
        self.cur = node

    # ---------------------------------------------------------------- solve

    def solve(self, node: Node) -> NodeResult:
        """The node's LP: a safe bound and its point, or a certified infeasibility."""
        self.apply(node)
        h = self.h
        t0 = time.perf_counter()
        h.run()
        self.lp_time += time.perf_counter() - t0
        self.lp_count += 1
        self.iterations += int(h.getInfo().simplex_iteration_count)
        status = h.getModelStatus()
        if status == _OPT:
            sol = h.getSolution()
            x = np.asarray(sol.col_value)
            bound = self.safe_bound(np.asarray(sol.row_dual))
            return NodeResult(bound, x)
        if status in _INFEASIBLE and self.infeasible_certified():
            return NodeResult(None, None)
        # numerical trouble, or an infeasibility its ray does not prove: once more, cold
        h.clearSolver()
        h.run()
        self.lp_count += 1
        status = h.getModelStatus()
        if status == _OPT:
            sol = h.getSolution()
            return NodeResult(self.safe_bound(np.asarray(sol.row_dual)),
                              np.asarray(sol.col_value))  # fmt: skip
        if status in _INFEASIBLE and self.infeasible_certified():
            return NodeResult(None, None)
        return NodeResult(None, None, certified=False)

    def safe_bound(self, y: NDArray[np.float64]) -> float:
        """``max cost.x`` over the node's LP is at most this (module docstring, "Round-off")
        for HiGHS's row duals ``y`` (its sign convention: ``cost - A^T y`` are the reduced
        costs), plus the round-off of the sums themselves."""
        y = np.where(((y > 0) & (self.rhi >= HINF)) | ((y < 0) & (self.rlo <= -HINF)), 0.0, y)
        z = self.cost - self.A.T @ y
        cols = z * np.where(z > 0, self.ub, np.where(z < 0, self.lb, 0.0))
        rows = y * np.where(y > 0, self.rhi, np.where(y < 0, self.rlo, 0.0))
        if not np.all(np.isfinite(cols)):
            return math.inf
        total = float(np.sum(rows) + np.sum(cols))
        return total + 1e-12 * (1.0 + float(np.sum(np.abs(rows)) + np.sum(np.abs(cols))))

    def infeasible_certified(self) -> bool:
        """HiGHS's dual ray ``y`` proves the node infeasible: ``y . (A x)`` over the box
        cannot reach ``y . r`` for any row activity ``r`` in ``[L, U]`` (either sign of
        ``y``)."""
        try:
            _, has, ray = self.h.getDualRay()
        except Exception:  # noqa: BLE001  (no ray available: unproven)
            return False
        if not has:
            return False
        ray = np.asarray(ray, dtype=float)
        for s in (1.0, -1.0):
            y = s * ray  # a multiplier towards a row's infinite side proves nothing: 0
            y = np.where(((y > 0) & (self.rlo <= -HINF)) | ((y < 0) & (self.rhi >= HINF)), 0.0, y)
            z = self.A.T @ y  # y.(A x) = z.x
            hi_x = float(np.sum(z * np.where(z > 0, self.ub, self.lb)))
            lo_r = float(np.sum(y * np.where(y > 0, self.rlo, np.where(y < 0, self.rhi, 0.0))))
            # the round-off of these sums in floating point: well below 1e-12 of the sums of
            # the magnitudes that enter them
            box = np.maximum(np.abs(self.lb), np.abs(self.ub))
            err = 1e-12 * float(np.abs(self.A).T @ np.abs(y) @ box + np.abs(lo_r))
            if math.isfinite(lo_r) and hi_x < lo_r - err:
                return True
        return False


class Search:
    """The branch-and-bound of one query (module docstring) on a :class:`NodeLP`."""

    def __init__(self, lp: NodeLP, opts: ModeSearchOptions, data: QueryData, qvar: int | None,
                 deadline: float | None, abs_tol: float) -> None:  # fmt: skip
        self.lp, self.opts, self.data, self.qvar = lp, opts, data, qvar
        self.deadline, self.abs_tol = deadline, abs_tol
        self.ex = lp.ex
        self.exact_tol = 1e-7 * (1.0 + lp.prob.bounds.force)  # slide_search's
        self.rtol = 1e-7  # complementarity, relative to the point's largest force
        self.best: tuple[NDArray[np.float64], float] | None = None  # (point, objective)
        self.unresolved: list[float] = []
        self.pruned = -math.inf  # the largest bound of a node pruned by the incumbent
        self.nodes = self.popped = self.polishes = self.polish_found = self.quicks = 0
        self.polish_time = self.quick_time = 0.0
        self.first_exact_node: int | None = None
        self.t0 = time.perf_counter()

    # ------------------------------------------------------------ incumbent

    def threshold(self) -> float:
        """Nodes whose bound is at most this are pruned (the incumbent within the gaps)."""
        if self.best is None:
            return -math.inf
        v = self.best[1]
        return v + max(self.opts.gap * abs(v), self.abs_tol)

    def offer(self, x: NDArray[np.float64]) -> None:
        """An exact point (already checked): the incumbent when better."""
        val = float(self.lp.cost @ x) if np.any(self.lp.cost) else 0.0
        if self.best is None or val > self.best[1]:
            self.best = (x, val)
            if self.first_exact_node is None:
                self.first_exact_node = self.nodes

    def polish(self, x: NDArray[np.float64], node: Node, target: float | None) -> bool:
        """Exact points with ``x``'s modes, their slide angles optimised
        (:func:`slide_search`, module docstring): the incumbent when better. True if one
        was found."""
        t0 = time.perf_counter()
        self.polishes += 1
        y = self.model_point(x, node)
        tgt = None if target is None else target * self.lp.sign
        got = None
        for promote, source in CERTIFY_TRIES:
            got = slide_search(self.ex, y, tgt, self.opts.gap, 8, promote=promote,
                               source=source)  # fmt: skip
            if got is not None:
                self.polish_found += 1
                self.offer(got)
                break
        self.polish_time += time.perf_counter() - t0
        return got is not None

    def quick(self, x: NDArray[np.float64], node: Node) -> bool:
        """The exact mode LP of ``x`` on the node LP itself (:meth:`mode_node`): an exact
        point when it has one, the incumbent when better. True if one was found."""
        t0 = time.perf_counter()
        self.quicks += 1
        mode = self.mode_node(x, node)
        res = self.lp.solve(mode)
        found = False
        if res.x is not None:
            y = self.model_point(res.x, mode)
            if max(self.ex.violations(y, box=False).values()) <= self.exact_tol:
                self.offer(y)
                found = True
        self.quick_time += time.perf_counter() - t0
        return found

    def mode_node(self, x: NDArray[np.float64], node: Node) -> Node:
        """Every state decided from ``x``: open where unloaded, else closed; a contact that
        moves tangentially slides along one fixed direction (an arc of width 0: ``-d_t``'s,
        or friction's when friction is near the cone), one whose friction is on the cone
        slides along it, the others stick with friction in an inscribed wedge of
        :data:`WEDGE` rad about its direction; undecided actuators as their point. Every
        point of this node's LP is exact."""
        p, ex = self.lp.prob, self.ex
        tol = self.rtol * (1.0 + float(np.abs(x[p.c]).max(initial=0.0)))
        dtol = 1e-9 * (1.0 + float(np.abs(x[ex.dt]).max(initial=0.0)))
        normal, tan, act = [], [], []
        for i in range(self.lp.m):
            cn = float(x[p.c[i, 0]])
            if node[0][i] == "O" or (node[0][i] == "U" and cn <= tol):
                normal.append("O")
                tan.append(("U", None))
                continue
            normal.append("C")
            ct, dt = x[p.c[i, 1:]], x[ex.dt[i]]
            nt, nd = float(np.linalg.norm(ct)), float(np.linalg.norm(dt))
            lim = float(self.lp.mu[i]) * cn
            if nd > dtol:
                phi = math.atan2(-dt[1], -dt[0]) if nt < 0.9 * lim else math.atan2(ct[1], ct[0])
                tan.append(("A", (phi % TWO_PI, 0.0)))
            elif nt >= (1.0 - 1e-3) * lim:
                tan.append(("A", (math.atan2(ct[1], ct[0]) % TWO_PI, 0.0)))
            else:
                phi = math.atan2(ct[1], ct[0]) if nt > tol else 0.0
                w = min(WEDGE, 2.0 * math.acos(min(1.0, nt / lim)))  # x's friction inside
                tan.append(("I", ((phi - 0.5 * w) % TWO_PI, w)))
        for k, a in enumerate(self.lp.act):
            st = node[2][k]
            if st == "U":
                fc = p.hand[1][a] if p.fc is None else x[p.fc[a]]
                fe = float(x[p.f[a]] - fc) / float(p.bounds.excess[a])
                v = float(x[p.v[a]]) / float(p.bounds.motion[a])
                st = "M" if v > fe else "L"
            act.append(st)
        return (tuple(normal), tuple(tan), tuple(act))

    def model_point(self, x: NDArray[np.float64], node: Node) -> NDArray[np.float64]:
        """``x`` with the binaries of the exact model set from the node's states (or, where
        undecided, from the point) and the slide bounds ``s = |d_t|``: the input of
        :func:`slide_search`, which reads the modes from it."""
        p, ex = self.lp.prob, self.ex
        tol = self.rtol * (1.0 + float(np.abs(x[p.c]).max(initial=0.0)))
        y = x.copy()
        normal, _, act = node
        for i in range(self.lp.m):
            cn, u = x[p.c[i, 0]], x[p.u[i]]
            closed = normal[i] == "C" or (normal[i] == "U" and (cn > tol or u <= tol))
            y[p.y[i]] = 1.0 if closed else 0.0
            if not closed:
                y[p.c[i]] = 0.0
        if p.z is not None:
            y[p.z] = 0.0
            for k, a in enumerate(self.lp.act):
                fc = p.hand[1][a] if p.fc is None else x[p.fc[a]]
                moving = act[k] == "M" or (act[k] == "U" and x[p.f[a]] - fc <= tol
                                           and x[p.v[a]] > tol)  # fmt: skip
                y[p.z[a]] = 0.0 if moving else 1.0
        y[ex.slide] = np.linalg.norm(x[ex.dt], axis=1)
        return y

    # ------------------------------------------------------------ branching

    def violations(self, x: NDArray[np.float64], node: Node) -> list[tuple[float, str, int]]:
        """The complementarities ``x`` violates beyond ``tol``: (size, kind, index), kind
        ``"n"`` normal, ``"a"`` actuator, ``"t"`` tangential."""
        p, ex = self.lp.prob, self.ex
        tol = self.rtol * (1.0 + float(np.abs(x[p.c]).max(initial=0.0)))
        normal, _, act = node
        out = []
        dscale = 1e-9 * (1.0 + float(np.abs(x[ex.dt]).max(initial=0.0)))
        for i in range(self.lp.m):
            cn, u = float(x[p.c[i, 0]]), float(x[p.u[i]])
            if normal[i] == "U" and cn > tol and u > tol:
                out.append((min(cn, u), "n", i))
            if cn <= tol:
                continue
            ct, dt = x[p.c[i, 1:]], x[ex.dt[i]]
            nd = float(np.linalg.norm(dt))
            lim = float(self.lp.mu[i]) * cn
            if nd > dscale:
                miss = float(np.linalg.norm(ct + lim * dt / nd))
                if miss > tol:
                    out.append((miss, "t", i))
                    continue
            excess = float(np.linalg.norm(ct)) - lim
            if excess > tol:
                out.append((excess, "t", i))
        for k, a in enumerate(self.lp.act):
            if act[k] != "U":
                continue
            fc = p.hand[1][a] if p.fc is None else x[p.fc[a]]
            fe, v = float(x[p.f[a]] - fc), float(x[p.v[a]])
            V = float(p.bounds.motion[a])
            if fe > tol and v > 1e-9 * V:
                out.append((min(fe, v * p.bounds.force / V), "a", k))
        return out

    def children(self, node: Node, kind: str, i: int, x: NDArray[np.float64]) -> list[Node] | None:
        """The node's children on complementarity ``(kind, i)``; None when an arc is already
        narrower than ``min_width``."""
        normal, tan, act = node
        if kind == "n":
            return [(normal[:i] + (s,) + normal[i + 1 :], tan, act) for s in ("C", "O")]
        if kind == "a":
            return [(normal, tan, act[:i] + (s,) + act[i + 1 :]) for s in ("L", "M")]
        p, ex = self.lp.prob, self.ex
        ct, dt = x[p.c[i, 1:]], x[ex.dt[i]]
        pc = math.atan2(ct[1], ct[0]) if np.linalg.norm(ct) > 1e-12 else None
        moving = np.linalg.norm(dt) > 1e-12
        pd = math.atan2(-dt[1], -dt[0]) if moving else pc

        def rep(s: tuple[str, tuple[float, float] | None]) -> Node:
            return (normal, tan[:i] + (s,) + tan[i + 1 :], act)

        kind_i, arc = tan[i]
        if kind_i == "U":
            if pc is None and pd is None:
                a0 = 0.0
            elif pc is None or pd is None:
                a0 = (pc if pd is None else pd) - math.pi / 2
            else:  # the boundary between friction's and the slide's directions
                a0 = pd + math.remainder(pc - pd, TWO_PI) / 2
            return [rep(("S", None)), rep(("A", (a0 % TWO_PI, math.pi))),
                    rep(("A", ((a0 + math.pi) % TWO_PI, math.pi)))]  # fmt: skip
        if kind_i == "S" and arc is None:  # friction outside the cone: halve the circle
            a0 = (pc if pc is not None else 0.0) - math.pi / 2
            return [rep(("S", (a0 % TWO_PI, math.pi))),
                    rep(("S", ((a0 + math.pi) % TWO_PI, math.pi)))]  # fmt: skip
        a, w = arc
        if w <= self.opts.min_width:
            return None
        w1 = 0.5 * w
        oc = None if pc is None else (pc - a) % TWO_PI
        od = None if pd is None else (pd - a) % TWO_PI
        if kind_i == "A" and oc is not None and od is not None and oc <= w and od <= w:
            w1 = min(max(0.5 * (oc + od), 0.1 * w), 0.9 * w)
        elif kind_i == "S" and oc is not None and oc <= w:
            w1 = min(max(oc, 0.1 * w), 0.9 * w)
        return [rep((kind_i, (a, w1))), rep((kind_i, ((a + w1) % TWO_PI, w - w1)))]

    # ------------------------------------------------------------ the search

    def run(self, feasibility: bool) -> str:
        """Search the tree; ``"done"`` (exhausted or closed), ``"timeout"`` or
        ``"node_limit"``. ``feasibility``: stop at the first exact point (Existence)."""
        lp = self.lp
        root = lp.root()
        res = lp.solve(root)
        self.nodes = 1
        self.heap: list[tuple[float, int, int, Node, NodeResult]] = []
        count = itertools.count()
        if res.x is None and res.certified:
            self.root_bound = None
            return "done"
        self.root_bound = res.bound
        if not res.certified:
            self.unresolved.append(math.inf)
            return "done"
        heapq.heappush(self.heap, (-res.bound, 0, next(count), root, res))
        while self.heap:
            negb, negd, _, node, res = heapq.heappop(self.heap)
            bound = -negb
            self.popped += 1
            if bound <= self.threshold():
                self.pruned = max(self.pruned, bound, *(-h[0] for h in self.heap))
                self.heap.clear()
                break
            x = res.x
            vio = self.violations(x, node)
            if not vio:
                if not self.quick(x, node):
                    self.polish(x, node, bound)
            elif self.popped % DIVE_EVERY == 0 and not self.quick(x, node) and self.dive_due():
                self.polish(x, node, bound)
            if not vio or self.popped % DIVE_EVERY == 0:
                if feasibility and self.best is not None:
                    heapq.heappush(self.heap, (negb, negd, next(count), node, res))
                    return "done"
                if bound <= self.threshold():
                    self.pruned = max(self.pruned, bound)
                    continue
            if not vio:  # every complementarity holds within tol, yet no exact point nearby
                vio = self.violations_tight(x, node)
            if not vio:
                self.unresolved.append(bound)
                continue
            vio.sort(reverse=True)
            first = [v for v in vio if v[1] in ("n", "a")] or vio
            _, kind, i = first[0]
            kids = self.children(node, kind, i, x)
            if kids is None:
                if not self.quick(x, node):
                    self.polish(x, node, bound)
                if bound > self.threshold():
                    self.unresolved.append(bound)
                continue
            for kid in kids:
                self.nodes += 1
                r = lp.solve(kid)
                if r.x is None:
                    if not r.certified:
                        self.unresolved.append(bound)
                    continue
                b = min(r.bound, bound)  # a child is contained in its parent
                if b <= self.threshold():
                    self.pruned = max(self.pruned, b)
                    continue
                heapq.heappush(self.heap, (-b, negd - 1, next(count), kid, r))
            if self.deadline is not None and time.perf_counter() > self.deadline:
                return "timeout"
            if self.nodes >= self.opts.node_limit:
                return "node_limit"
        return "done"

    def dive_due(self) -> bool:
        """A full polish (:func:`slide_search`) of a node's point is due: at most one per
        :data:`POLISH_EVERY` nodes taken (a polish costs about as much as that many node
        LPs; counted, not timed, so that a query's answer does not depend on the
        machine's load)."""
        return self.polishes * POLISH_EVERY <= self.popped

    def finish(self) -> None:
        """The incumbent made tidy (least virtual motion) and its slide angles optimised
        towards the proven bound (:func:`slide_search`); kept when no worse."""
        if self.best is None:
            return
        x, val = self.best
        up = self.upper()
        self.best = None
        node = self.lp.root()
        if not self.polish(x, node, up) or self.best[1] < val - 1e-8 * (1.0 + abs(val)):
            self.best = (x, val)
            tidy = self.tidy(x, val)
            if tidy is not None:
                self.best = (tidy, val)

    def tidy(self, x: NDArray[np.float64], val: float) -> NDArray[np.float64] | None:
        """The least-motion exact point with ``x``'s modes (:meth:`mode_node`) and objective
        within ``1e-10`` relative of ``val``: the weighted 1-norm of the object and joint
        motions (rotations times ``L``, joints times their lever ``|J_j|``, as
        :meth:`ExactProblem.tidy`) minimised on a copy of the node LP. None if that fails
        or its point is not exact. (A vertex of the search's LP puts motions that load no
        spring anywhere in the box.)"""
        lp, p = self.lp, self.lp.prob
        mode = self.mode_node(x, lp.root())
        lp.apply(mode)
        h = quiet_highs()
        for opt, v in (("presolve", "off"), ("primal_feasibility_tolerance", 1e-9),
                       ("dual_feasibility_tolerance", 1e-9)):  # fmt: skip
            h.setOptionValue(opt, v)
        h.passModel(lp.h.getLp())
        n = lp.n
        g = self.ex.grasp
        L = length_scale(g)
        motion = list(p.r)
        weight = [1.0] * 3 + [L] * (len(p.r) - 3)
        if p.q is not None:
            cols = np.linalg.norm(p.J, axis=0)
            motion += list(p.q)
            weight += list(np.where(cols > 0, cols, 1.0))
        k = len(motion)
        h.addVars(k, np.zeros(k), np.full(k, HINF))
        h.changeColsCost(n, np.arange(n, dtype=np.int32), np.zeros(n))
        h.changeColsCost(k, np.arange(n, n + k, dtype=np.int32), np.asarray(weight, dtype=float))
        h.changeObjectiveSense(highspy.ObjSense.kMinimize)
        for t, (j, _) in enumerate(zip(motion, weight, strict=True)):  # t >= |x_j|
            for sgn in (1.0, -1.0):
                h.addRow(0.0, HINF, 2, np.array([n + t, int(j)], dtype=np.int32),
                         np.array([1.0, -sgn]))  # fmt: skip
        nz = np.flatnonzero(lp.cost)
        if nz.size:
            slack = 1e-10 * max(1.0, abs(val))
            h.addRow(val - slack, HINF, nz.size, nz.astype(np.int32), lp.cost[nz])
        h.run()
        if h.getModelStatus() != _OPT:
            return None
        y = self.model_point(np.asarray(h.getSolution().col_value)[:n], mode)
        if max(self.ex.violations(y, box=False).values()) > self.exact_tol:
            return None
        return y

    def violations_tight(self, x: NDArray[np.float64], node: Node) -> list:
        """The violations at a thousandth of the tolerance: where a node's point looks exact
        but no exact point was found with its modes, branching goes on there."""
        keep = self.rtol
        self.rtol = 1e-3 * keep
        try:
            return self.violations(x, node)
        finally:
            self.rtol = keep

    def upper(self) -> float | None:
        """The proven bound on the (maximised) objective: the largest bound of any open,
        unresolved or pruned node, at least the incumbent's value; None if no node is
        feasible (the query has no exact point in the box)."""
        vals = [-h[0] for h in self.heap] + self.unresolved
        if self.pruned > -math.inf:
            vals.append(self.pruned)
        if self.best is not None:
            vals.append(self.best[1])
        return max(vals) if vals else None


def _abs_tol(data: QueryData, bounds: ExactBounds, grasp: Grasp, opts: ModeSearchOptions) -> float:
    """``abs_gap`` in the value's units (ModeSearchOptions)."""
    S = bounds.scale
    if data.direction is not None:
        d = np.asarray(data.direction, dtype=float)
        L = length_scale(grasp)
        force = max(float(np.abs(d[:3]).max()), float(np.abs(d[3:]).max()) / L)
        return opts.abs_gap * S / max(force, 1e-300)
    return opts.abs_gap * S


def _box_reached(ex: CoulombModel, x: NDArray[np.float64]) -> bool:
    """An exact point at 99 % of the box (module docstring, "The box"), or beyond: forces,
    separations, excess actuator forces, transmission motions, object, joint and tangential
    motions."""
    p = ex.prob
    M = p.model
    B = p.bounds.force
    if np.any(x[p.c[:, 0]] >= 0.99 * B) or np.any(x[p.u] >= 0.99 * B):
        return True
    motion = np.r_[ex.dt.reshape(-1), p.r, [] if p.q is None else p.q].astype(int)
    box = np.array([M.ub[j] for j in motion])
    if np.any(np.abs(x[motion]) >= 0.99 * box):
        return True
    if p.hand is not None:
        live = ~p.backdrivable
        fc = p.hand[1] if p.fc is None else x[p.fc]
        if np.any((x[p.f] - fc)[live] >= 0.99 * p.bounds.excess[live]):
            return True
        if np.any(x[p.v][live] >= 0.99 * p.bounds.motion[live]):
            return True
    return False


class _BoxCut(Exception):
    """The best exact point lies at or beyond the box: the bound may not hold."""


def _solve_once(grasp: Grasp, query: Any, opts: ModeSearchOptions, t0: float,
                last: bool) -> Solution:  # fmt: skip
    """One search in the box of ``opts.bound_factor``; :class:`_BoxCut` when the box may
    have cut the optimum off, unless ``last``: then the answer keeps its exact point and
    has no proven bound (``stats["box_reached"]``)."""
    data = QueryData.of(grasp, query, 100.0)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"bound_factor": opts.bound_factor}
    bounds_stats(bounds, stats)
    conditions = exact_conditions(0.0)
    tb = time.perf_counter()
    ex = CoulombModel(grasp, data, bounds, 0.0, opts.motion_bound)
    qvar = add_query(ex.prob, data)
    lp = NodeLP(ex, data)
    stats["build_time_s"] = time.perf_counter() - tb
    deadline = None if opts.time_limit is None else t0 + float(opts.time_limit)
    search = Search(lp, opts, data, qvar, deadline, _abs_tol(data, bounds, grasp, opts))
    existence = data.direction is None and data.command_range is None
    # a first exact point: every contact sticking, every actuator locked (one LP)
    tp = time.perf_counter()
    stuck = stuck_point(grasp, data, bounds, 0.0, opts.motion_bound)
    search.polish_time += time.perf_counter() - tp
    if stuck is not None:
        search.offer(stuck[1].x)
    outcome = "done"
    if not (existence and search.best is not None):
        outcome = search.run(feasibility=existence)
    search.finish()
    stats.update({"nodes": search.nodes, "quick_polishes": search.quicks,
                  "quick_time_s": search.quick_time, "lps": lp.lp_count, "lp_time_s": lp.lp_time,
                  "lp_ms": 1e3 * lp.lp_time / max(1, lp.lp_count),
                  "simplex_iterations": lp.iterations, "polishes": search.polishes,
                  "polish_time_s": search.polish_time, "unresolved": len(search.unresolved),
                  "first_exact_node": search.first_exact_node,
                  "root_bound": None if search.root_bound is None
                  else search.root_bound * lp.sign})  # fmt: skip
    upper = search.upper()
    best = search.best
    cut = None
    if best is not None and not existence and _box_reached(ex, best[0]):
        cut = "the best exact point reaches the box"
    if best is not None and upper is not None and best[1] > upper + 1e-7 * (1 + abs(upper)):
        cut = f"exact value {best[1]} beyond the proven bound {upper}"
    if cut is not None and not last:
        raise _BoxCut(cut)
    if cut is not None:  # the bound holds only within the box, which the answer reaches
        stats["box_reached"] = cut
        upper = None
    closed = outcome == "done" and not search.unresolved
    if existence:
        if best is not None:
            return _answer(grasp, query, stats, ex, best[0], qvar, data, conditions, True)
        if closed:
            stats["reason"] = "every node of the tree is infeasible: no equilibrium"
            return solution("modesearch", grasp, query, False, stats, conditions=conditions)
        return _open(grasp, query, stats, outcome, search, None)
    if best is None:
        if closed:  # no exact point anywhere in the box
            stats["reason"] = "every node of the tree is infeasible: no equilibrium"
            if data.direction is not None:
                stats["capped"] = False
            return solution("modesearch", grasp, query, False, stats, conditions=conditions)
        return _bracketed(_open(grasp, query, stats, outcome, search, None), upper, lp.sign)
    value = best[1]
    certified = upper is not None and upper - value <= max(opts.gap * abs(upper), search.abs_tol)
    sol = _answer(grasp, query, stats, ex, best[0], qvar, data, conditions, certified)
    if outcome != "done":
        sol.status, sol.stable = outcome if outcome == "timeout" else "not_converged", None
        sol.stats["message"] = _message(outcome, opts)
    return _bracketed(sol, upper, lp.sign)


def _message(outcome: str, opts: ModeSearchOptions) -> str:
    if outcome == "timeout":
        return f"time_limit {opts.time_limit} s reached; the bracket reached is returned"
    return f"node_limit {opts.node_limit} reached; the bracket reached is returned"


def _open(grasp: Grasp, query: Any, stats: dict[str, Any], outcome: str, search: Search,
          _: Any) -> Solution:  # fmt: skip
    """No exact point: a time-out, a node limit, or unresolved leaves."""
    if outcome == "done":
        stats["reason"] = (f"{len(search.unresolved)} leaves with arcs narrower than "
                           "min_width and no exact point: neither answer is proven")  # fmt: skip
        status = "not_converged"
    else:
        status = "timeout" if outcome == "timeout" else "not_converged"
        stats["message"] = _message(outcome, search.opts)
    return Solution(None, "modesearch", grasp, query, stats=stats, status=status)


def _bracketed(sol: Solution, upper: float | None, sign: float) -> Solution:
    """``lower``/``upper`` in the query's terms: the exact point's value (``sol.value``)
    on the feasible side, the proven bound ``upper`` of the search (which maximises ``sign *
    objective``) on the other."""
    if not isinstance(sol.query, MaxDisturbance | OptimalCommands):
        return sol
    hi = None if upper is None or not math.isfinite(upper) else upper
    if sign > 0:
        sol.lower, sol.upper = sol.value, hi
        if hi is not None and sol.value is not None:
            sol.upper = max(hi, sol.value)
    else:
        sol.lower = None if hi is None else -hi
        if hi is not None and sol.value is not None:
            sol.lower = min(-hi, sol.value)
        sol.upper = sol.value
    sol.stats["certified"] = bool(sol.stats.get("certified"))
    return sol


def _answer(grasp: Grasp, query: Any, stats: dict[str, Any], ex: CoulombModel,
            x: NDArray[np.float64], qvar: int | None, data: QueryData,
            conditions: tuple[str, ...], certified: bool) -> Solution:  # fmt: skip
    pt = ex.prob.point(x)
    value = query_value(ex, pt, qvar, data)
    stats["certified"] = certified
    stats["exact_value"] = value
    if data.direction is not None:
        stats["capped"] = value is not None and value >= data.cap * (1 - 1e-8)
    sol = solution("modesearch", grasp, query, True, stats, ex.prob, pt, value,
                   conditions=conditions)  # fmt: skip
    if data.command_range is not None:
        sol.commands = pt.x[ex.prob.fc]
    return sol


@register(
    "modesearch",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    hand=True,
    summary="Coulomb friction with maximum dissipation by one branch-and-bound tree over "
    "contact modes and slide arcs, one LP per node (exact points, proven brackets)",
)
def _solve_modesearch(grasp: Grasp, query: Any, **options: Any) -> Solution:
    if options.get("normal_uncertainty"):
        raise GraspError("modesearch has no normal_uncertainty: use method='refinement'")
    options.pop("normal_uncertainty", None)
    opts = ModeSearchOptions.of(options)
    t0 = time.perf_counter()
    factor = opts.bound_factor
    cuts: list[str] = []
    for k in range(BOX_RETRIES + 1):
        left = None if opts.time_limit is None else opts.time_limit - (time.perf_counter() - t0)
        limit = None if left is None else max(0.0, left)
        o = ModeSearchOptions(**{**opts.__dict__, "bound_factor": factor, "time_limit": limit})
        try:
            sol = _solve_once(grasp, query, o, time.perf_counter(), k == BOX_RETRIES)
        except _BoxCut as e:
            cuts.append(f"bound_factor {factor:g}: {e}")
            factor *= 10.0
            continue
        if cuts:
            sol.stats["box_enlarged"] = cuts
        return sol
    raise AssertionError("unreachable: the last box returns its answer")
