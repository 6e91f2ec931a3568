"""The branch-and-bound of :mod:`stability.modesearch` over a :class:`~.node.NodeLP`:
best-first, branching on the most violated complementarity, exact points from polishing
only (the package docstring)."""

from __future__ import annotations

import heapq
import itertools
import math
import time
from fractions import Fraction
from typing import TYPE_CHECKING

import highspy
import numpy as np
from numpy.typing import NDArray

from .._lp import quiet_highs
from ..model.problem import length_scale
from ..model.query import QueryData
from ..model.slides import CERTIFY_TRIES, slide_search
from ..solution import slide_alignment
from .node import HINF, OPTIMAL, TWO_PI, Node, NodeLP, NodeResult

if TYPE_CHECKING:
    from . import ModeSearchOptions

__all__ = ["Search"]

WEDGE = 0.3  # [rad] a sticking contact's friction wedge in a quick mode LP (Search.mode_node)
POLISH_EVERY = 30  # at most one dive's full polish per this many nodes taken
EXACT_RTOL = 1e-6  # force conditions of an exact point, relative to 1 + its largest force
DIVE_TRIES = 1  # slide_search's tries at a dive (CERTIFY_TRIES' first: the node's own slides)
DIVE_STEPS = 1  # slide_search's steps at a dive
POLISH_STEPS = 8  # slide_search's steps elsewhere (leaves that finish or narrow the search)
DIVE_EVERY = 10  # polish the node's point every this many nodes (an early incumbent)


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
        self.heap: list[tuple[float, int, int, Node, NodeResult]] = []  # the open nodes
        self.root_bound: float | None = None  # the root LP's bound (None: not solved)
        self.pruned = -math.inf  # the largest bound of a node pruned by the incumbent
        self.rejected = 0  # exact points refused by exact_enough
        self.nodes = self.popped = self.polishes = self.quicks = 0
        self.polish_time = self.quick_time = 0.0
        self.first_exact_node: int | None = None
        self.together = colocated(lp)  # per contact, the others at its point
        # closed iff d_n <= p / k; compared exactly, so that round-off never ties two contacts
        # whose thresholds differ
        k = np.asarray(lp.prob.grasp.stiffness, dtype=float).tolist()
        pre = np.asarray(lp.prob.preload, dtype=float).tolist()  # the spring rows' own
        self.closes_below = [Fraction(p) / Fraction(kk) for p, kk in zip(pre, k, strict=True)]

    # ------------------------------------------------------------ incumbent

    def threshold(self) -> float:
        """Nodes whose bound is at most this are pruned (the incumbent within the gaps)."""
        if self.best is None:
            return -math.inf
        v = self.best[1]
        return v + max(self.opts.gap * abs(v), self.abs_tol)

    def offer(self, x: NDArray[np.float64]) -> bool:
        """An exact point (checked by its maker against the model's rows): the incumbent
        when better; False when it fails :meth:`exact_enough` (not an exact point)."""
        if not self.exact_enough(x):
            self.rejected += 1
            return False
        val = float(self.lp.cost @ x) if np.any(self.lp.cost) else 0.0
        if self.best is None or val > self.best[1]:
            self.best = (x, val)
            if self.first_exact_node is None:
                self.first_exact_node = self.nodes
        return True

    def exact_enough(self, x: NDArray[np.float64]) -> bool:
        """The force conditions at the point's own scale: the circular cone, friction
        against each slide at full magnitude (``slide_alignment``) and the spring law within
        :data:`EXACT_RTOL` of ``1 + max |c|`` (the model's rows are checked at the box's
        scale, ``1e-7 (1 + B)``, which a grown box makes loose)."""
        p, g = self.lp.prob, self.ex.grasp
        pt = p.point(x)
        c = pt.forces
        # the motion as the model states it (round-off entries of G and J zeroed: a joint
        # moved far by a free transmission would otherwise turn 1e-9 m/rad into slides)
        d = p.G.T @ pt.motion
        if p.J is not None:
            d = d - p.J @ pt.hand_motion
        d = d.reshape(g.m, 3)
        tol = EXACT_RTOL * (1.0 + float(np.abs(c).max(initial=0.0)))
        cone = float(np.max(np.linalg.norm(c[:, 1:], axis=1) - g.mu * c[:, 0], initial=0.0))
        spring_force = g.spring_force(d[:, 0], self.data.preload)
        spring = float(np.max(np.abs(c[:, 0] - spring_force), initial=0.0))
        return max(cone, spring, slide_alignment(g.mu, c, d)) <= tol

    def polish(self, x: NDArray[np.float64], node: Node, target: float | None,
               tries: int = len(CERTIFY_TRIES), steps: int = POLISH_STEPS) -> bool:  # fmt: skip
        """Exact points with ``x``'s modes, their slide angles optimised
        (:func:`slide_search`, module docstring): the incumbent when better. True if one
        was found."""
        t0 = time.perf_counter()
        self.polishes += 1
        y = self.model_point(x, node)
        tgt = None if target is None else target * self.lp.sign
        got = None
        for promote, source in CERTIFY_TRIES[:tries]:
            got = slide_search(self.ex, y, tgt, self.opts.gap, steps, promote=promote,
                               source=source)  # fmt: skip
            if got is not None and self.offer(got):
                self.polish_time += time.perf_counter() - t0
                return True
        self.polish_time += time.perf_counter() - t0
        return False

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
                found = self.offer(y)
        self.quick_time += time.perf_counter() - t0
        return found

    def stuck(self) -> None:
        """A first exact point: every contact closed and sticking (friction in the inscribed
        octagon), every nonbackdrivable actuator locked; one node LP. The incumbent when it
        has one (a grasp that holds without slipping needs no tree to say "stable").
        Contacts at a gap (preload ``p < 0``) or kept open by the motion limit are open
        here: closed, a gapped contact would have to have crossed its gap."""
        lp = self.lp
        shut = self.data.preload < 0
        if self.data.motion_limit is not None:
            shut = shut | self.data.motion_limit.open
        normal = tuple("O" if s else "C" for s in shut)
        tan = tuple(("U", None) if s else ("S", None) for s in shut)
        node = (normal, tan, ("L",) * len(lp.act))
        lp.inscribe(True)
        try:
            res = lp.solve(node)
        finally:
            lp.inscribe(False)
        if res.x is not None:
            y = self.model_point(res.x, node)
            if max(self.ex.violations(y, box=False).values()) <= self.exact_tol:
                self.offer(y)

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
        cs, us, ds = x[p.c].tolist(), x[p.u].tolist(), x[ex.dt].tolist()
        mus = self.lp.mu.tolist()
        for i in range(self.lp.m):
            (cn, c1, c2), u, (d1, d2) = cs[i], us[i], ds[i]
            if normal[i] == "U" and cn > tol and u > tol:
                out.append((min(cn, u), "n", i))
            if cn <= tol:
                continue
            nd = math.hypot(d1, d2)
            lim = mus[i] * cn
            if nd > dscale:
                miss = math.hypot(c1 + lim * d1 / nd, c2 + lim * d2 / nd)
                if miss > tol:
                    out.append((miss, "t", i))
                    continue
            excess = math.hypot(c1, c2) - lim
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
            return [(self.tie_normal(normal, i, s), tan, act) for s in ("C", "O")]
        if kind == "a":
            return [(normal, tan, act[:i] + (s,) + act[i + 1 :]) for s in ("L", "M")]
        p, ex = self.lp.prob, self.ex
        ct, dt = x[p.c[i, 1:]], x[ex.dt[i]]
        pc = math.atan2(ct[1], ct[0]) if np.linalg.norm(ct) > 1e-12 else None
        moving = np.linalg.norm(dt) > 1e-12
        pd = math.atan2(-dt[1], -dt[0]) if moving else pc

        kind_i, arc = tan[i]

        def rep(s: tuple[str, tuple[float, float] | None]) -> Node:
            # co-located contacts share d_t, so those in i's state take its child's state
            # (package docstring); a sticking contact's friction arc is its own: not tied
            tied = [] if kind_i == "S" else [j for j in self.together[i] if tan[j] == tan[i]]
            new = list(tan)
            for j in (i, *tied):
                new[j] = s
            return (normal, tuple(new), act)

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

    def tie_normal(self, normal: tuple[str, ...], i: int, s: str) -> tuple[str, ...]:
        """``normal`` with contact ``i`` in state ``s`` and its undecided co-located contacts
        in the state that implies: closed (``d_n <= p_i / k_i``), every one that closes at a
        larger ``d_n`` is closed too; open, every one that closes at a smaller one is open."""
        new = list(normal)
        new[i] = s
        t = self.closes_below
        for j in self.together[i]:
            if new[j] == "U" and (t[j] >= t[i] if s == "C" else t[j] <= t[i]):
                new[j] = s
        return tuple(new)

    # ------------------------------------------------------------ the search

    def run(self, feasibility: bool) -> str:
        """Search the tree; ``"done"`` (exhausted or closed), ``"timeout"`` or
        ``"node_limit"``. ``feasibility``: stop at the first exact point (Existence)."""
        lp = self.lp
        root = lp.root()
        res = lp.solve(root)
        self.nodes = 1
        self.heap = []
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
            dive = not vio or self.popped % DIVE_EVERY == 0
            if dive and not self.quick(x, node) and self.dive_due():
                self.polish(x, node, bound, DIVE_TRIES, DIVE_STEPS)
            if dive:
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
        machine's load). A fixed rate, not doubling intervals (nodes 10, 20, 40, ...): the
        incumbents that close a bracket come from polishes late in the search."""
        return self.polishes * POLISH_EVERY <= self.popped

    def finish(self) -> None:
        """The incumbent made tidy (least virtual motion, :meth:`tidy`); where its bracket is
        still open, first its slide angles optimised towards the proven bound
        (:func:`slide_search`, which tidies too), kept when no worse."""
        if self.best is None:
            return
        x, val = self.best
        up = self.upper()
        closed = up is not None and up - val <= max(self.opts.gap * abs(up), self.abs_tol)
        if closed:  # no better point is needed: the least motion only
            tidy = self.tidy(x, val)
            if tidy is not None:
                self.best = (tidy, val)
                return
        self.best = None
        if not self.polish(x, self.lp.root(), up) or self.best[1] < val - 1e-8 * (1 + abs(val)):
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
        if h.getModelStatus() != OPTIMAL:
            return None
        y = self.model_point(np.asarray(h.getSolution().col_value)[:n], mode)
        if max(self.ex.violations(y, box=False).values()) > self.exact_tol:
            return None
        return y if self.exact_enough(y) else None

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


def colocated(lp: NodeLP) -> list[tuple[int, ...]]:
    """Per contact, the other contacts at the same point: the same columns of ``G`` and the
    same rows of ``J`` (a piecewise-linear contact law's steps, or a contact listed twice).
    Their normal and tangential motions ``d_n``, ``d_t`` are one, whatever their ``mu``."""
    p, m = lp.prob, lp.m
    Gt = p.G.T.reshape(m, 3, -1)
    Jt = None if p.J is None else p.J.reshape(m, 3, -1)
    keys = [(Gt[i].tobytes(), b"" if Jt is None else Jt[i].tobytes()) for i in range(m)]
    return [tuple(j for j in range(m) if j != i and keys[j] == keys[i]) for i in range(m)]
