"""``method="refinement"``: Coulomb friction with maximum dissipation by hierarchical
refinement of a convex relaxation (thesis ch. 6, Algorithm refinement).

Per spatial contact ``i`` the tangent plane is spanned by an ordered, cyclic list of
friction edges ``e_s = (cos th_s, sin th_s)`` (in the contact's ``(t1, t2)`` frame) of
lengths ``l_s``. Friction and the *negative* tangential motion are positive combinations
of the same edges (eqs. betas, alphas)::

    c_t = sum_s beta_s l_s e_s,     -d_t = sum_s alpha_s l_s e_s,     beta, alpha >= 0

and one SOS2 ``z_i`` (``K + 1`` members, the last one edge 1 again: the list is cyclic)
lets only two neighbouring edges carry either (eqs. sos_beta, sos_alpha): friction lies in
the sector of the negative motion. The magnitude (eq. fric_refine, indicator ``w_i``)::

    sum_s beta_s <= mu c_n                        (inside the outer polygon, always)
    w_i = 0  =>  sum_s alpha_s = 0                (no sliding)
    w_i = 1  =>  sum_s l_s beta_s >= mu c_n       (sliding: outside the inscribed chord)

Edge lengths (eqs. l1, length): the initial ``K0`` edges (angle ``gamma = 2 pi / K0``
between neighbours, ``initial_edges`` 4 or 8) are sectors of level 1, and a sector of
level ``p`` (angle ``gamma / 2^(p-1)``) has edges of length

    l_p = prod_{r=p}^{q+1} sec(gamma / 2^r),

so the outer polygon of a sector contains those of its two halves (the bisecting edge of
length ``l_{p+1}`` ends on the parent's outer side) and the chords of the halves lie
outside the parent's chord: every relaxation contains every finer one and, at every level,
the exact cone with maximum dissipation. Hence **infeasible at any level means unstable**
(reported at once), and an optimum never improves with refinement. (Relaxations built for
different ``q`` are not nested: the uniform tangent polygon of 16 edges sticks out of that
of 8 edges at the latter's tangent points, by ``sec(pi / 16) - 1``.) At level ``q + 1``
(angle ``gamma / 2^q``) the outer sides are tangent to the cone (``l_{q+1} = sec(gamma /
2^(q+1))``).

Refinement (Algorithm refinement): after each MIP, a contact's sector is halved (three
edges of length ``l_{p+1}`` along its two edges and its bisector, redundant edges removed)
where the answer needs it: the sector of a sliding contact's motion and friction, and of
a sticking contact's friction when it lies outside the exact cone (``|c_t| > mu c_n``).
Refinement stops when no such sector is coarser than ``gamma / 2^q``. The answer then
satisfies the relaxation at uniform resolution ``K0 2^q`` (``refine=False`` solves that
one MIP from the start: the thesis' "full resolution"; ``start_level=p`` starts from the
uniform level-``p`` relaxation, all of them nested for one ``q``), with friction at most
``l_{q+1} - 1`` times ``mu c_n`` outside the cone (``stats["cone_excess"]``).

Robustness to contact-normal error ``eta`` (``normal_uncertainty``, radians; sec. robust,
eq. uncertainty): the spring law uses the worst normal within ``eta``,
``d_n' = d_n cos(eta) - |d_t| sin(eta)``, with ``|d_t|`` estimated by ``sum_s alpha_s``.
That estimate is ``<= |d_t|`` (the edges' outer polygon contains the unit circle) and exact
at a finest sector's bisector (where the thesis' ``sum l_{p+1} alpha_s`` is the same); at
coarse levels it is smaller than the thesis' (``1/l_p`` vs ``l_{p+1}/l_p`` at an edge)
because the thesis' estimate is not monotone under refinement (at the parent's bisector its
children estimate ``cos(gamma/2^(p+1)) < 1``), which would break the guarantee above.
With ``eta > 0`` the spring law of the *nominal* normals is not what is solved, so it is
not among the enforced ``Solution.conditions``.

Queries, all by the same loop: ``Existence`` (feasibility), ``MaxDisturbance`` (maximise
``s``, one MIP per level, no bisection), ``OptimalCommands`` (minimise the largest command,
or ``weights . f_c``; per-actuator ``lower``/``upper``; ``max_normal_force``).

Brackets and certificates (``certify=True``, default): every optimisation answer carries
``Solution.lower <= optimum <= Solution.upper``. The feasible side (MaxDisturbance
``lower``, OptimalCommands ``upper``) is the value of an exact point: the relaxed answer's
contact modes (open, sticking, sliding) with the slide directions optimised by sequential
LP (:func:`stability.model.slides.certify`); it satisfies every condition, the circular
cone and maximum dissipation included, and is the point returned. The other side is the
last round's MIP dual bound (containment: it bounds every finer level). A first exact
point has every contact sticking and every actuator locked (one LP). ``Existence``
answers "stable" only with an exact point and "unstable" only with an infeasible
relaxation (a proof); a feasible finest relaxation without an exact point is
``status="not_converged"``. An optimisation query whose rounds end with no exact point
probes (:func:`_probe`): a MaxDisturbance asks ``Existence`` at its bound (the cap when
the bound reaches it) and just below; without an exact point from them it is
``status="not_converged"`` with no value and only the relaxation's side of the bracket
(``stats["relaxed_value"]``), never the relaxation's value as "solved" (``certify=False``
asks for exactly that: the relaxation's answer, ``certified`` False). The loop stops
once the bracket is closed to ``certify_gap``
(default 1e-4 relative, ``stats["certified"]``) or at the finest level; a time-out keeps
the bracket reached. Each round searches only the window between the best exact value
and the last bound, and stops within ``ROUND_GAP * certify_gap`` of its optimum.

The box (``bound_factor``, default :data:`REFINEMENT_BOUND_FACTOR` = 1e3 here, 100 for the
other methods): forces, separations, transmission motions and slide weights are bounded
by it times the query's force scale. An exact point beyond the relaxation's bound shows
that the box cut the optimum off: the box grows tenfold and the query is solved again
(``stats["box_enlarged"]``, at most :data:`~stability.options.BOX_RETRIES` times:
:func:`~stability.options.enlarge_box`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import register
from .grasp import Grasp
from .mip import INF
from .mip.model import Row
from .model.coulomb import exact_conditions
from .model.edges import TWO_PI, EdgeSet, edge_length
from .model.problem import ExactBounds, ExactPoint, ExactProblem, scale_bounds
from .model.query import QueryData, add_query, query_value
from .model.run import CONDITIONS, MipOptions, Stop, bounds_stats, run, solution, stopped
from .model.slides import certify, stuck_point
from .options import Deadline, check_ranges, enlarge_box, finite
from .queries import Existence, MaxDisturbance, OptimalCommands
from .solution import Solution

__all__ = ["EdgeSet", "RefinementOptions", "edge_length"]

ROUND_GAP = 0.25  # a round's MIP stops within this fraction of certify_gap (relative)
WINDOW_SLACK = 1e-7  # relative widening of the value window a round searches
REFINEMENT_BOUND_FACTOR = 1e3  # the default box (bound_factor), see _solve_refinement
REFINE_STEP = 2  # levels a needed sector is refined by per round (measured: 2 beats 1, 3)


@dataclass(frozen=True)
class RefinementOptions(MipOptions):
    """Options of ``method="refinement"``: :class:`~stability.model.run.MipOptions`
    (``bound_factor`` default :data:`REFINEMENT_BOUND_FACTOR`) and ``initial_edges`` (4 or
    8 edges per contact at level 1), ``levels`` (``q``: the finest level, ``4 2^q``
    equivalent edges), ``refine`` (refine the needed sectors; False: uniform edges at
    ``start_level``), ``normal_uncertainty`` [rad], ``max_rounds``, ``motion_bound`` (the
    tangential motion bound per edge weight, times ``2 B / min k``), ``start_level`` (uniform edges
    of this level first; default 1, ``levels + 1`` without refinement), ``certify`` (try
    each round's answer as an exact solution), ``certify_gap`` (stop when the certified
    value meets the relaxation's bound within this, relative)."""

    backend: str | None = None
    bound_factor: float = REFINEMENT_BOUND_FACTOR
    initial_edges: int = 4
    levels: int = 9  # 4 * 2^9 = 2048 equivalent edges (thesis protocol), or a closed bracket
    refine: bool = True
    normal_uncertainty: float = 0.0
    max_rounds: int = 200
    motion_bound: float = 4.0
    start_level: int | None = None
    certify: bool = True
    certify_gap: float = 1e-4

    def check(self) -> None:
        super().check()
        eta = self.normal_uncertainty
        check_ranges(self, {
            "initial_edges": (self.initial_edges in (4, 8), "4 or 8"),
            "levels": (0 <= self.levels <= 12, "an integer in [0, 12]"),
            "normal_uncertainty": (finite(eta) and 0.0 <= eta < math.pi / 2, "in [0, pi/2) rad"),
            "max_rounds": (self.max_rounds >= 1, "a positive integer"),
            "motion_bound": (finite(self.motion_bound) and self.motion_bound >= 1.0,
                             "a finite number >= 1"),
            "certify_gap": (finite(self.certify_gap) and 0.0 <= self.certify_gap < 1.0,
                            "in [0, 1)"),
            "start_level": (1 <= self.start <= self.levels + 1,
                            "an integer in [1, levels + 1]"),
        })  # fmt: skip

    @property
    def start(self) -> int:
        """The level of the first round's uniform edges."""
        if self.start_level is not None:
            return self.start_level
        return 1 if self.refine else self.levels + 1

    @property
    def gamma(self) -> float:
        return TWO_PI / self.initial_edges

    @property
    def equivalent_edges(self) -> int:
        return self.initial_edges * 2**self.levels


class _Relaxation:
    """The exact model of ch. 5 with the friction relaxation of :class:`EdgeSet` s."""

    def __init__(
        self,
        grasp: Grasp,
        data: QueryData,
        bounds: ExactBounds,
        edges: list[EdgeSet],
        eta: float,
        motion_bound: float,
    ) -> None:
        self.grasp, self.edges, self.eta = grasp, edges, eta
        prob = ExactProblem(grasp, data.preload, data.hand, bounds, friction=False,
                            name="refinement", command_range=data.command_range)  # fmt: skip
        self.prob = prob
        M, B = prob.model, bounds.force
        lmax = max(es.length(s) for es in edges for s in range(len(es)))
        for i in range(grasp.m):  # friction up to the outer polygon: widen c_t's bounds
            for j in prob.c[i, 1:]:
                M.lb[j], M.ub[j] = -grasp.mu[i] * B * lmax, grasp.mu[i] * B * lmax
        if data.max_normal_force is not None:
            for j in prob.c[:, 0]:
                M.ub[j] = min(M.ub[j], data.max_normal_force)
        A = motion_bound * bounds.displacement
        self.A = A
        Gt = prob.G.T.reshape(grasp.m, 3, -1)
        Jt = None if prob.J is None else prob.J.reshape(grasp.m, 3, -1)
        self.alpha: list[NDArray[np.int64]] = []
        self.beta: list[NDArray[np.int64]] = []
        self.w = M.add_vars(grasp.m, 0, 1, "B", "w")
        for i, es in enumerate(edges):
            k, mu = len(es), float(grasp.mu[i])
            lens = np.array([es.length(s) for s in range(k)])
            dirs = np.array([[math.cos(t), math.sin(t)] for t in es.theta])
            beta = M.add_vars(k, 0.0, mu * B, "C", f"beta{i}")
            alpha = M.add_vars(k, 0.0, A, "C", f"alpha{i}")
            z = M.add_vars(k + 1, 0.0, 1.0, "C", f"z{i}")
            M.add_sos2(z, name=f"sector{i}")
            # sum z = 1: the chosen sector carries all of z (a big-M answer's polish LP,
            # MipModel.fixed, keeps the pair with the most z)
            M.add_row(z, np.ones(k + 1), 1.0, 1.0, f"sector{i}.sum")
            for s in range(k):  # beta_s, alpha_s <= bound * (z_s [+ z_{K+1} for s = 0])
                zs = [int(z[s])] + ([int(z[k])] if s == 0 else [])
                M.add_row([beta[s], *zs], [1.0] + [-mu * B] * len(zs), -INF, 0.0)
                M.add_row([alpha[s], *zs], [1.0] + [-A] * len(zs), -INF, 0.0)
            for t in range(2):
                # c_t = sum beta_s l_s e_s
                coef = lens * dirs[:, t]
                M.add_row([int(prob.c[i, 1 + t]), *beta], [1.0, *(-coef)], 0.0, 0.0)
                # sum alpha_s l_s e_s + d_t = 0,  d_t = G_t^T r - J_t q
                idx, val = list(alpha), list(coef)
                idx, val = prob.extend(idx, val, prob.r, Gt[i, 1 + t])
                if Jt is not None:
                    idx, val = prob.extend(idx, val, prob.q, -Jt[i, 1 + t])
                M.add_row(idx, val, 0.0, 0.0, f"slide{i}.{t}")
            cn = int(prob.c[i, 0])
            M.add_row([*beta, cn], [1.0] * k + [-mu], -INF, 0.0, f"outer{i}")
            M.add_indicator(self.w[i], alpha, np.ones(k), "<=", 0.0, 0, f"stick{i}")
            M.add_indicator(self.w[i], [*beta, cn], [*lens, -mu], ">=", 0.0, 1, f"slip{i}")
            self.alpha.append(alpha)
            self.beta.append(beta)
        if eta > 0.0:  # d_n' = d_n cos(eta) + sin(eta) sum alpha (eq. uncertainty, unloading)
            for i, r in enumerate(prob.spring_rows):
                row = M.rows[r]
                cols = set(prob.r.tolist()) | (set() if prob.q is None else set(prob.q.tolist()))
                val = np.array([v * math.cos(eta) if j in cols else v
                                for j, v in zip(row.idx, row.val, strict=True)])  # fmt: skip
                idx = np.r_[row.idx, self.alpha[i]]
                val = np.r_[val, np.full(len(self.alpha[i]), math.sin(eta) * grasp.stiffness[i])]
                M.rows[r] = Row(idx.astype(np.int64), val, row.lo, row.hi, row.name)

    def refine(self, pt: ExactPoint, tol: float = 1e-9, exact: ExactPoint | None = None,
               depth: int = 1) -> int:  # fmt: skip
        """Halve the sectors the answer ``pt`` needs finer (see the module docstring); the
        number of sectors halved. With ``exact`` (a certified exact point), also the
        sectors of its friction on the cone's boundary, ``depth`` levels at once: the
        relaxation's bound is then tight where the exact optimum's friction lies."""
        g, x = self.grasp, pt.x
        scale = 1.0 + float(np.abs(pt.forces).max(initial=0.0))
        wants: list[list[float]] = []
        for i, es in enumerate(self.edges):
            lens = np.array([es.length(s) for s in range(len(es))])
            dirs = np.array([[math.cos(t), math.sin(t)] for t in es.theta])
            mdt = (x[self.alpha[i]] * lens) @ dirs  # -d_t
            ct = pt.forces[i, 1:]
            cn = pt.forces[i, 0]
            want = []
            slides = np.linalg.norm(mdt) > tol * (1.0 + float(np.abs(pt.motion).max(initial=0.0)))
            outside = np.linalg.norm(ct) > g.mu[i] * cn * (1.0 + 1e-9) + tol * scale
            if slides and (pt.closed[i] or self.eta > 0):  # an open contact's slide is free
                want.append(mdt)
            if (slides or outside) and np.linalg.norm(ct) > tol * scale:
                want.append(ct)
            wants.append([math.atan2(v[1], v[0]) % TWO_PI for v in want])
        n = 0
        for i, es in enumerate(self.edges):
            for phi in wants[i]:
                n += es.refine_at(phi, REFINE_STEP)
            if exact is not None:
                ct, lim = exact.forces[i, 1:], float(g.mu[i] * exact.forces[i, 0])
                if lim > 0 and np.linalg.norm(ct) >= (1.0 - 1e-6) * lim:
                    n += es.refine_at(math.atan2(ct[1], ct[0]) % TWO_PI, depth)
        return n

    def cone_excess(self, pt: ExactPoint) -> float:
        """Largest ``(|c_t| - mu c_n) / (mu c_n)`` over the closed contacts (0 inside)."""
        c = pt.forces
        lim = self.grasp.mu * c[:, 0]
        ex = np.where(lim > 0, (np.linalg.norm(c[:, 1:], axis=1) - lim) / np.where(lim > 0, lim, 1),
                      0.0)  # fmt: skip
        return float(max(0.0, ex.max(initial=0.0)))


def _round(
    grasp: Grasp, data: QueryData, bounds: ExactBounds, edges: list[EdgeSet],
    opts: RefinementOptions, deadline: Deadline, stats: dict[str, Any],
    window: tuple[float | None, float | None] = (None, None),
) -> tuple[_Relaxation, ExactPoint | None, int | None]:  # fmt: skip
    """One MIP of the loop: the relaxation, its answer (None: infeasible), the index of
    ``s`` (MaxDisturbance) or of the cost variable (OptimalCommands). ``window``: bounds
    ``(lo, hi)`` on the query's value known to hold for this relaxation's optimum (the best
    exact value on one side, the previous round's bound on the other): the search skips
    every node outside them."""
    t0 = time.perf_counter()
    rel = _Relaxation(grasp, data, bounds, edges, opts.normal_uncertainty, opts.motion_bound)
    var = add_query(rel.prob, data)
    M = rel.prob.model
    lo, hi = window
    if var is not None and (lo is not None or hi is not None):
        lo = -INF if lo is None else lo - WINDOW_SLACK * (1.0 + abs(lo))
        hi = INF if hi is None else hi + WINDOW_SLACK * (1.0 + abs(hi))
        if var >= 0:
            M.lb[var], M.ub[var] = max(M.lb[var], lo), min(M.ub[var], hi)
        else:  # the weighted commands
            M.add_row(rel.prob.fc, data.weights, lo, hi, "window")
    M.many_small = True
    M.gap = ROUND_GAP * opts.certify_gap
    _clock(stats, "build_time_s", t0)
    t0 = time.perf_counter()
    pt = run(
        rel.prob, opts, deadline, stats
    )  # the MIP (stats["mip_time_s"]) and its least-motion LP
    _clock(stats, "round_time_s", t0)
    return rel, pt, var


def _clock(stats: dict[str, Any], key: str, t0: float) -> None:
    """Add the seconds since ``t0`` to ``stats[key]`` (the profile of a query)."""
    stats[key] = stats.get(key, 0.0) + time.perf_counter() - t0


def _solve(grasp: Grasp, query: Any, opts: RefinementOptions, deadline: Deadline) -> Solution:
    """One run of Algorithm refinement in the box of ``opts.bound_factor``; :class:`_BoxCut`
    where an exact point shows the box cut the optimum off."""
    method = "refinement"
    data = QueryData.of(grasp, query, opts.bound_factor)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"backend": opts.backend, "initial_edges": opts.initial_edges,
                             "levels": opts.levels, "equivalent_edges": opts.equivalent_edges,
                             "normal_uncertainty": opts.normal_uncertainty}  # fmt: skip
    bounds_stats(bounds, stats)
    g, q = opts.gamma, opts.levels
    k0 = opts.initial_edges * 2 ** (opts.start - 1)
    edges = [EdgeSet.uniform(k0, opts.start, g, q) for _ in range(grasp.m)]
    conditions = _relaxed_conditions(opts)
    trace: list[dict[str, Any]] = []
    stats["rounds"] = trace
    cap0 = data.cap
    full = dataclasses.replace(data)  # the query as asked (the loop tightens data.cap)
    best = None  # the best certified exact solution so far (certify)
    relaxed: float | None = None  # the relaxation's bound (MaxDisturbance: upper)
    if opts.certify:  # every contact sticking, every actuator locked: one LP
        t0 = time.perf_counter()
        best = stuck_point(grasp, full, bounds, opts.normal_uncertainty, opts.motion_bound)
        _clock(stats, "certify_time_s", t0)
        stats["stuck"] = None if best is None else best[2]
        if best is not None and data.direction is None and data.command_range is None:
            return _answer(method, grasp, query, stats, best, None, opts, data, cap0, True)
    try:
        for _ in range(opts.max_rounds):
            exact = None if best is None else best[2]
            window = (exact, None) if data.direction is not None else (relaxed, exact)
            rel, pt, var = _round(grasp, data, bounds, edges, opts, deadline, stats, window)
            row: dict[str, Any] = {"edges": [len(e) for e in edges], "feasible": pt is not None}
            trace.append(row)
            if pt is None and best is not None:  # nothing in the window: the box cut it off
                raise _BoxCut(best[2], None)
            if pt is None:
                stats["reason"] = (f"infeasible with {max(len(e) for e in edges)} edges per "
                                   "contact: no equilibrium at any finer level either")  # fmt: skip
                if data.direction is not None:
                    stats["capped"] = False
                return solution(method, grasp, query, False, stats, conditions=conditions)
            row["value"] = query_value(rel, pt, var, data)
            # the round stops within ROUND_GAP of its optimum: its dual bound is the bound
            row["bound"] = relaxed = _dual_bound(row["value"], stats.pop("dual_bound", None),
                                                 data)  # fmt: skip
            if data.direction is not None and relaxed < data.cap:
                # no finer level can do better (containment): tighten the cap, and with it
                # the model's bounds (big-M), to this level's bound
                data.cap = min(data.cap, relaxed * (1 + 1e-6) + 1e-12 * cap0)
                # (the box, from the force scale at the cap, shrinks with it: a box kept at
                # the first cap's scale lets the relaxation gain through large, slightly
                # misaligned slides that no exact point reaches)
                bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand,
                                      opts.bound_factor)  # fmt: skip
                bounds_stats(bounds, stats)
            cert = None
            if opts.certify:
                # the relaxation's bounds (the cap may have been tightened since), the
                # query's own cap: an exact point beyond them shows that they cut it off
                t0 = time.perf_counter()
                cert = certify(grasp, full, rel.prob.bounds, rel.prob, pt.x, var,
                               opts.normal_uncertainty, opts.motion_bound, row["value"],
                               opts.certify_gap)  # fmt: skip
                _clock(stats, "certify_time_s", t0)
                row["exact"] = None if cert is None else cert[2]
                if cert is not None and (best is None or _better(cert[2], best[2], data)):
                    best = cert
                if best is not None and _beyond(best[2], relaxed, data):
                    raise _BoxCut(best[2], relaxed)
                if best is not None and _closed(best[2], relaxed, data, opts.certify_gap):
                    return _answer(method, grasp, query, stats, best, relaxed, opts, data, cap0,
                                   True)  # fmt: skip
            n = 0
            if opts.refine:
                n = rel.refine(pt, exact=None if cert is None else cert[1], depth=opts.levels + 1)
            row["refined"] = n
            if n == 0:
                break
        else:
            stats["reason"] = f"max_rounds {opts.max_rounds} reached before the finest level"
            return _bracket(solution(method, grasp, query, None, stats, status="not_converged",
                                     conditions=conditions), best, relaxed, data)  # fmt: skip
    except Stop as e:
        return _bracket(stopped(method, grasp, query, stats, e), best, relaxed, data)
    stats["mip_rounds"] = len(trace)
    stats["cone_excess_bound"] = edge_length(q + 1, g, q) - 1.0
    if best is not None:  # the finest level reached, the bracket still open: the exact point
        return _answer(method, grasp, query, stats, best, relaxed, opts, data, cap0, False)
    return _unproven(grasp, query, opts, deadline, stats, data, (rel, pt, var), relaxed, cap0)


def _relaxed_conditions(opts: RefinementOptions) -> tuple[str, ...]:
    """The model conditions a relaxation's answer meets: not the exact friction cone (its
    polygon is outside it by at most ``cone_excess_bound``), nor the spring law under
    normal uncertainty."""
    conditions = tuple(c for c in CONDITIONS if c != "friction_cone")
    if opts.normal_uncertainty > 0:
        conditions = tuple(c for c in conditions if c != "spring_law")
    return conditions


def _unproven(grasp: Grasp, query: Any, opts: RefinementOptions, deadline: Deadline,
              stats: dict[str, Any], data: QueryData, last: tuple, relaxed: float | None,
              cap0: float) -> Solution:  # fmt: skip
    """The finest level reached without an exact point: Existence has no answer; an
    optimisation query probes (MaxDisturbance, :func:`_probe`) or is bracketed on one side;
    with ``certify=False``, the last round's relaxed answer (``last``: its relaxation,
    point and query variable), flagged uncertified."""
    method = "refinement"
    rel, pt, var = last
    conditions = _relaxed_conditions(opts)
    if data.direction is None and data.command_range is None:  # Existence
        stats["certified"] = False
        stats["reason"] = ("the relaxation is feasible at the finest level, but no exact "
                           "solution was found with its contact modes: neither stable "
                           "(no exact point) nor unstable (no proof)")  # fmt: skip
        return solution(method, grasp, query, None, stats, status="not_converged",
                        conditions=conditions)  # fmt: skip
    stats["cone_excess"] = rel.cone_excess(pt)
    stats["certified"] = False
    value = query_value(rel, pt, var, data)
    if opts.certify:  # an optimisation query without an exact point: probe, or no answer
        stats["relaxed_value"] = value
        if data.direction is not None:
            got = _probe(grasp, query, data, relaxed, cap0, opts, deadline, stats)
            if got is not None:
                return got
        stats["reason"] = (
            "the relaxation is solved at the finest level, but no exact solution was found "
            "with its contact modes" + (" nor by Existence probes at and below its bound"
                                        if data.direction is not None else "")
            + f": the optimum is bracketed on one side only (relaxation {value:.9g}, "
            "stats['relaxed_value'])")  # fmt: skip
        return _bracket(solution(method, grasp, query, None, stats, status="not_converged",
                                 conditions=conditions), None, relaxed, data)  # fmt: skip
    # certify=False: the relaxation's answer as asked, flagged uncertified
    if data.direction is not None:
        stats["capped"] = value >= cap0 * (1 - 1e-8)
    sol = solution(method, grasp, query, True, stats, rel.prob, pt, value, conditions=conditions)
    if data.command_range is not None:
        sol.commands = pt.x[rel.prob.fc]
        stats["at_bound"] = stats.get("at_bound") or bool(
            np.any(sol.commands >= 0.99 * data.command_range[1]) and query.upper is None
        )
    return _bracket(sol, None, relaxed, data)


PROBE_BACKOFF = (0.5, 10.0, 100.0)  # Existence probes at bound * (1 - k * certify_gap)
PROBE_GAP_FLOOR = 1e-6  # the probes' relative back-off when certify_gap is 0
_PROFILE_KEYS = (
    "build_time_s",
    "mip_time_s",
    "round_time_s",
    "certify_time_s",
    "nodes",
    "mips",
)  # the probes' work, added to the query's profile


def _probe(grasp: Grasp, query: MaxDisturbance, data: QueryData, relaxed: float | None,
           cap0: float, opts: RefinementOptions, deadline: Deadline,
           stats: dict[str, Any]) -> Solution | None:  # fmt: skip
    """A MaxDisturbance whose rounds found no exact point (the relaxation's modes admit
    none): ``Existence`` of the load ``base + s direction`` at the cap (when the bound
    reaches it), then at ``s = bound (1 - k gap)`` for ``k`` in :data:`PROBE_BACKOFF`.
    The first one answered "stable" (with its exact point) is the answer: ``value =
    lower = s``, ``upper`` the relaxation's bound, certified when ``s`` is within
    ``certify_gap`` of it. None when no probe holds within the time left.

    An Existence query is solved by rounds of its own, whose modes can admit an exact point
    at or just below the bound where the MaxDisturbance rounds' modes admit none; a larger
    back-off can find one where a smaller does not."""
    if relaxed is None:
        return None
    base = np.zeros_like(data.direction) if data.base is None else data.base
    gap = max(opts.certify_gap, PROBE_GAP_FLOOR)
    top = min(relaxed, cap0)
    loads = [cap0] if relaxed >= cap0 * (1 - 1e-8) else []
    loads += [top * (1.0 - k * gap) for k in PROBE_BACKOFF if top * (1.0 - k * gap) > 0]
    tried: list[dict[str, Any]] = []
    stats["probes"] = tried
    for s in loads:
        if deadline.expired():
            break
        check = Existence(base + s * data.direction, preload=query.preload,
                          commands=query.commands)  # fmt: skip
        t0 = time.perf_counter()
        esol = _solve(
            grasp, check, replace(opts, certify=True), deadline
        )  # (an Existence never cuts its box:
        # its first exact point answers it)
        tried.append({"load": s, "status": esol.status, "stable": esol.stable,
                      "time_s": time.perf_counter() - t0})  # fmt: skip
        for k in _PROFILE_KEYS:
            if isinstance(esol.stats.get(k), int | float):
                stats[k] = stats.get(k, 0) + esol.stats[k]
        if esol.stable:
            stats["certified"] = _closed(s, relaxed, data, opts.certify_gap)
            stats["cone_excess"] = 0.0
            stats["exact_value"] = s
            stats["capped"] = s >= cap0 * (1 - 1e-8)
            stats["at_bound"] = esol.stats.get("at_bound")
            stats.pop("reason", None)
            sol = dataclasses.replace(esol, query=query, value=s, stats=stats)
            return _bracket(sol, (None, None, s), relaxed, data)
    return None


def _dual_bound(value: float | None, bound: float | None, data: QueryData) -> float | None:
    """The round's proven bound: its MIP's dual bound (MaxDisturbance: ``>= value``, at most
    the cap; OptimalCommands: ``<= value``), or the value where the solver gave none."""
    if value is None or bound is None or not math.isfinite(bound):
        return value
    if data.direction is not None:
        return float(min(max(value, bound), data.cap))
    return float(min(value, bound))


class _BoxCut(Exception):
    """An exact point better than the relaxation's bound: the relaxation's box (force and
    motion bounds from ``bound_factor``) cut the optimum off."""

    def __init__(self, exact: float | None, relaxed: float | None) -> None:
        super().__init__(f"exact value {exact} beyond the relaxation's bound {relaxed}")
        self.exact, self.relaxed = exact, relaxed


def _beyond(exact: float | None, relaxed: float | None, data: QueryData) -> bool:
    """The exact value lies beyond the relaxation's bound (by more than round-off)."""
    if exact is None or relaxed is None:
        return False
    tol = 1e-7 * (1.0 + abs(relaxed))
    return exact > relaxed + tol if data.direction is not None else exact < relaxed - tol


def _bracket(sol: Solution, best: tuple | None, relaxed: float | None,
             data: QueryData) -> Solution:  # fmt: skip
    """``sol`` with its ``lower``/``upper``: the best exact value and the relaxation's."""
    exact = None if best is None else best[2]
    if data.direction is not None:
        sol.lower, sol.upper = exact, relaxed
    elif data.command_range is not None:
        sol.lower, sol.upper = relaxed, exact
    return sol


def _better(a: float | None, b: float | None, data: QueryData) -> bool:
    if a is None or b is None:
        return False
    return a > b if data.direction is not None else a < b


def _closed(exact: float | None, relaxed: float | None, data: QueryData, gap: float) -> bool:
    """The certified exact value meets the relaxation's bound within ``gap`` relative
    (Existence: any certificate closes)."""
    if exact is None or relaxed is None:
        return True
    slack = gap * max(abs(exact), abs(relaxed)) + 1e-12
    if data.direction is not None:  # exact <= optimum <= relaxed
        return exact >= relaxed - slack
    return exact <= relaxed + slack  # relaxed <= optimum <= exact


def _answer(method: str, grasp: Grasp, query: Any, stats: dict[str, Any], best: tuple,
            relaxed: float | None, ro: RefinementOptions, data: QueryData, cap0: float,
            closed: bool) -> Solution:  # fmt: skip
    """The Solution of the best exact point (module docstring, "Certificates"); ``closed``:
    its value meets the relaxation's bound within ``certify_gap``."""
    ex, pt, value = best
    stats["certified"] = closed
    stats["mip_rounds"] = len(stats["rounds"])
    stats["cone_excess"] = 0.0
    stats["cone_excess_bound"] = edge_length(ro.levels + 1, ro.gamma, ro.levels) - 1.0
    stats["exact_value"] = value
    conditions = exact_conditions(ro.normal_uncertainty)
    if data.direction is not None:  # at the user's cap: "at least cap", not a maximum
        stats["capped"] = value >= cap0 * (1 - 1e-8)
    sol = solution(method, grasp, query, True, stats, ex.prob, pt, value, conditions=conditions)
    if data.command_range is not None:
        sol.commands = pt.x[ex.prob.fc]
    return _bracket(sol, best, relaxed, data)


@register(
    "refinement",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    options=RefinementOptions,
    hand=True,
    compliance=True,
    motion_limit=True,
    summary="thesis ch. 6: Coulomb friction with maximum dissipation, hierarchical refinement "
    "of a convex relaxation (infeasible at any level = unstable)",
)
def _solve_refinement(grasp: Grasp, query: Any, opts: RefinementOptions,
                      deadline: Deadline) -> Solution:  # fmt: skip
    # An exact point beyond the relaxation's bound means the model's box (force and motion
    # bounds, bound_factor times the force scale) cut the optimum off: it grows tenfold.
    # The default box, 1e3 times the force scale: motions that load no spring are virtual
    # and can be large, so a small box can cut the optimum off; a large one weakens the MIPs'
    # relaxations (docs/notebook/2026-11-28-exact-rechecks.md, "refinement's box").
    cuts: list[str] = []

    def attempt(factor: float, prev: Solution | None) -> tuple[Solution | None, str | None]:
        try:
            return _solve(grasp, query, replace(opts, bound_factor=factor), deadline), None
        except _BoxCut as e:
            cuts.append(f"bound_factor {factor:g}: {e}")
            return None, str(e)

    sol, notes = enlarge_box(attempt, opts.bound_factor, deadline, lambda prev, sol: None)
    if sol is None:  # every box tried cut the optimum off, or no time was left to enlarge
        return Solution(None, "refinement", grasp, query,
                        status="timeout" if deadline.expired() else "error",
                        stats={"message": "the model's box cut the optimum off at every bound "
                               f"tried: {cuts}", "box_enlarged": notes})  # fmt: skip
    if notes:
        sol.stats["box_enlarged"] = notes
    return sol
