"""The node LP of :mod:`stability.modesearch`: one persistent HiGHS model of the relaxation,
its bounds and arc rows set per node, with a safe bound from the duals and a checked proof
of infeasibility (the package docstring states the relaxation)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import highspy
import numpy as np
from numpy.typing import NDArray

from .._lp import quiet_highs
from ..model.coulomb import CoulombModel
from ..model.query import QueryData

__all__ = ["HINF", "INFEASIBLE", "OPTIMAL", "Node", "NodeLP", "NodeResult", "TWO_PI"]

# HiGHS's dual simplex pricing: Devex (1); its default, steepest edge, costs more per call
# than it saves on LPs of a few hundred rows that change by a few bounds per node
EDGE_WEIGHTS = 1
OCTAGON = 8  # sides of the outer friction polygon at every node
HINF = highspy.kHighsInf
OPTIMAL = highspy.HighsModelStatus.kOptimal
INFEASIBLE = (highspy.HighsModelStatus.kInfeasible,)
TWO_PI = 2.0 * math.pi
# A bound on the relative round-off of a floating-point sum of n terms, n u / (1 - n u) with
# u = 2^-53 (Higham, Accuracy and Stability of Numerical Algorithms, 2002, eq. 3.5), for
# n <= 900 terms: z = A^T y and the bounds' sums over rows and columns of a node LP (a 6-contact
# hand has about 200 rows and 120 columns)
ROUNDOFF = 1e-13


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
        self.absA = np.abs(A)  # kept with A: the round-off terms of the bounds
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
                         ("simplex_dual_edge_weight_strategy", EDGE_WEIGHTS),
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
        # per contact: the (row, column) of each arc-row coefficient (:meth:`_set_arc`'s
        # order), the values last set and the rows' bound pattern
        self.dt_cols = [[int(j) for j in ex.dt[i]] for i in range(self.m)]
        self.arc_pos: list[tuple[list[int], list[int]]] = []
        for i in range(self.m):
            r0, ci = self.arc0 + 8 * i, int(prob.c[i, 0])
            t0, t1 = (int(j) for j in prob.c[i, 1:])
            d0, d1 = self.dt_cols[i]
            pos = [(r0, t0), (r0, t1), (r0 + 1, t0), (r0 + 1, t1), (r0 + 2, d0), (r0 + 2, d1),
                   (r0 + 3, d0), (r0 + 3, d1)]  # fmt: skip
            for k in range(4, 8):
                pos += [(r0 + k, t0), (r0 + k, t1), (r0 + k, ci)]
            self.arc_pos.append(([r for r, _ in pos], [c for _, c in pos]))
        self.arc_vals: list[tuple[float, ...] | None] = [None] * self.m
        self.arc_pattern: list[str | None] = [None] * self.m
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
            self.A[r, j], self.absA[r, j] = v, abs(v)
            self.h.changeCoeff(r, j, v)

    def _set_normal(self, i: int, st: str) -> None:
        p = self.prob
        cn, u = int(p.c[i, 0]), int(p.u[i])
        self._col(cn, 0.0, 0.0 if st == "O" else self.ub0[cn])
        self._col(u, 0.0, 0.0 if st == "C" else self.ub0[u])

    def _set_tan(self, i: int, st: tuple[str, tuple[float, float] | None]) -> None:
        kind, arc = st
        for j in self.dt_cols[i]:
            if kind in ("S", "I"):
                self._col(j, 0.0, 0.0)
            else:
                self._col(j, self.lb0[j], self.ub0[j])
        r0 = self.arc0 + 8 * i
        pattern = None if arc is None else kind
        if arc is not None:
            self._set_arc(i, kind, arc)
        if pattern == self.arc_pattern[i]:
            return
        self.arc_pattern[i] = pattern
        ge = () if arc is None else (0, 1, 2, 3, 4) if kind == "A" else (0, 1)
        le = () if arc is None else (5,) if kind == "I" else (5, 6, 7)
        for k in range(8):
            if k in ge:
                self._row(r0 + k, 0.0, HINF)
            elif k in le:
                self._row(r0 + k, -HINF, 0.0)
            else:
                self._row(r0 + k, -HINF, HINF)

    def _set_arc(self, i: int, kind: str, arc: tuple[float, float]) -> None:
        """The coefficients of contact ``i``'s eight arc rows for the arc ``(a, w)``: with
        ``n_a = (-sin a, cos a)``, ``n_b = (sin b, -cos b)`` (``b = a + w``), ``m`` the mid
        direction and ``e_a``, ``e_b`` the ends, the rows ``n_a.c_t >= 0``,
        ``n_b.c_t >= 0``, ``n_a.(-d_t) >= 0``, ``n_b.(-d_t) >= 0``,
        ``m.c_t - mu cos(w/2) c_n >= 0`` (the chord), ``m.c_t``, ``e_a.c_t``,
        ``e_b.c_t <= mu c_n`` (the tangents). Inscribed (``"I"``): ``m.c_t <= mu cos(w/2)
        c_n``. Width 0: row 3 is ``-d_t.e_a >= 0`` (rows 2 and 3 would both state the
        line)."""
        a, w = arc
        b = a + w
        mid = a + 0.5 * w
        sa, ca, sb, cb = math.sin(a), math.cos(a), math.sin(b), math.cos(b)
        sm, cm = math.sin(mid), math.cos(mid)
        mu = float(self.mu[i])
        chord = -mu * math.cos(0.5 * w)
        row3 = (-ca, -sa) if w == 0.0 else (-sb, cb)
        vals = (-sa, ca, sb, -cb, sa, -ca, row3[0], row3[1], cm, sm, chord,
                cm, sm, chord if kind == "I" else -mu, ca, sa, -mu, cb, sb, -mu)  # fmt: skip
        old = self.arc_vals[i]
        if vals == old:
            return
        rows, cols = self.arc_pos[i]
        ch = self.h.changeCoeff
        for k, v in enumerate(vals):
            if old is None or old[k] != v:
                ch(rows[k], cols[k], v)
        self.arc_vals[i] = vals
        self.A[rows, cols] = vals
        self.absA[rows, cols] = np.abs(vals)

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

    def inscribe(self, on: bool) -> None:
        """The octagon rows of every cone scaled to the inscribed octagon (``mu cos(pi/8)
        c_n``: its vertices on the cone) with ``on``, back to the outer one without: a
        sticking contact's friction in it is in the cone."""
        scale = math.cos(math.pi / OCTAGON) if on else 1.0
        for i in range(self.m):
            ci = int(self.prob.c[i, 0])
            for k in range(OCTAGON):
                self._coef(self.cone0 + OCTAGON * i + k, ci, -float(self.mu[i]) * scale)

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
        self.iterations += _iterations(h)
        status = h.getModelStatus()
        if status == OPTIMAL:
            sol = h.getSolution()
            x = np.asarray(sol.col_value)
            bound = self.safe_bound(np.asarray(sol.row_dual))
            return NodeResult(bound, x)
        if status in INFEASIBLE and self.infeasible_certified():
            return NodeResult(None, None)
        # numerical trouble, or an infeasibility its ray does not prove: once more, cold
        h.clearSolver()
        h.run()
        self.lp_count += 1
        status = h.getModelStatus()
        if status == OPTIMAL:
            sol = h.getSolution()
            return NodeResult(self.safe_bound(np.asarray(sol.row_dual)),
                              np.asarray(sol.col_value))  # fmt: skip
        if status in INFEASIBLE and self.infeasible_certified():
            return NodeResult(None, None)
        return NodeResult(None, None, certified=False)

    def safe_bound(self, y: NDArray[np.float64]) -> float:
        """``max cost.x`` over the node's LP is at most this (package docstring, "Round-off")
        for HiGHS's row duals ``y`` (its sign convention: ``cost - A^T y`` are the reduced
        costs), plus the round-off of the sums themselves."""
        y = y.copy()
        y[(y > 0) & (self.rhi >= HINF)] = 0.0
        y[(y < 0) & (self.rlo <= -HINF)] = 0.0
        z = self.cost - self.A.T @ y
        cols = z * np.where(z > 0, self.ub, np.where(z < 0, self.lb, 0.0))
        rows = y * np.where(y > 0, self.rhi, np.where(y < 0, self.rlo, 0.0))
        total = float(rows.sum() + cols.sum())
        if not math.isfinite(total):
            return math.inf
        box = np.maximum(np.abs(self.lb), np.abs(self.ub))
        mag = float(np.abs(rows).sum() + np.abs(cols).sum() + np.abs(y) @ (self.absA @ box))
        return total + ROUNDOFF * (1.0 + mag)

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
        box = np.maximum(np.abs(self.lb), np.abs(self.ub))
        reach = self.absA @ box  # the largest |A_i x| over the box, per row
        for s in (1.0, -1.0):
            y = s * ray  # a multiplier towards a row's infinite side proves nothing: 0
            y = np.where(((y > 0) & (self.rlo <= -HINF)) | ((y < 0) & (self.rhi >= HINF)), 0.0, y)
            z = self.A.T @ y  # y.(A x) = z.x
            hi_x = float(np.sum(z * np.where(z > 0, self.ub, self.lb)))
            lo_r = float(np.sum(y * np.where(y > 0, self.rlo, np.where(y < 0, self.rhi, 0.0))))
            # the round-off of z and of these sums: at most ROUNDOFF of the magnitudes that
            # enter them
            err = ROUNDOFF * float(np.abs(y) @ reach + abs(lo_r))
            if math.isfinite(lo_r) and hi_x < lo_r - err:
                return True
        return False


def _iterations(h: highspy.Highs) -> int:
    """The simplex iterations of ``h``'s last run; 0 where HiGHS marks its info invalid
    (``getInfoValue`` then answers ``kWarning`` with whatever the run left there, and summing
    it overflows the count)."""
    status, value = h.getInfoValue("simplex_iteration_count")
    ok = status == highspy.HighsStatus.kOk
    return int(value) if ok and 0 <= int(value) < 2**31 else 0
