"""method="modesearch": one branch-and-bound tree over contact modes and slide arcs. Known
answers (the planar solver on an embedded grasp, the pinch's analytic limit), a brute force
over modes on two contacts, agreement with ``refinement`` and ``exact``, the status
semantics and the bound of the benchmark query that once got a wrong one."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog

from stability import (
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    OptimalCommands,
    examples,
    solve,
)
from stability.bench import grasps as bench_grasps
from stability.bench.hands import queries as hand_queries


def _exact(sol, tol: float = 1e-6) -> None:
    """A solved answer carries an exact point: every condition the method enforces (the
    circular cone and friction aligned against each slide included) within ``tol`` times
    the force scale. (``max_dissipation`` is a force times a motion: its size follows the
    virtual motion, so the force form ``slide_alignment`` is the one held to ``tol``.)"""
    assert sol.status == "solved" and sol.stable
    scale = 1.0 + float(np.abs(sol.forces).max())
    res = sol.residuals()
    keys = [k for k in sol.conditions if k != "max_dissipation" and k in res]
    assert max(res[k] for k in keys) <= tol * scale, res


def _inside(value: float, other, gap: float = 1e-4) -> None:
    """``value`` (an exact point's) lies in the other method's bracket: never above its
    proven upper bound, and below its exact lower bound by at most the brackets' gap."""
    assert value <= other.upper * (1 + 1e-7) + 1e-9
    assert value >= other.lower - gap * abs(other.upper) - 1e-9


@pytest.fixture(scope="module")
def bench():
    return {label: (g, f) for label, g, f in bench_grasps.grasps()}


def _bench_query(bench, label: str, task: str, k: int):
    g, f = bench[label]
    q = next(q for t, kk, q in bench_grasps.queries_of(label, f) if t == task and kk == k)
    return g, q


# ------------------------------------------------------------------ known answers


@pytest.mark.parametrize("direction", [(0, 1, 0), (1, 1, 0.02), (-1, 0.5, 0), (0, 0, 1)])
def test_planar_grasp_embedded_in_3d_gives_planar_answer(direction) -> None:
    """The thesis' planar three-contact grasp in z = 0: the spatial tree's max disturbance
    equals the exact planar solver's to 1e-9 (relative), bracket closed."""
    planar = solve(examples.three_planar(), MaxDisturbance(direction, preload=1.0, cap=100.0),
                   method="planar")  # fmt: skip
    q = MaxDisturbance(examples.embed_wrench(direction), preload=1.0, cap=100.0)
    sol = solve(examples.three_embedded(), q, method="modesearch")
    _exact(sol)
    assert sol.value == pytest.approx(planar.value, rel=1e-9)
    assert sol.lower <= planar.value * (1 + 1e-9) and sol.upper >= planar.value * (1 - 1e-9)
    assert sol.stats["certified"]


def test_pinch_analytic_limit() -> None:
    """The pinch (a hand: nonbackdrivable fingers) along z: 2 mu tau / lever exactly."""
    q = MaxDisturbance([0, 0, 1, 0, 0, 0], commands=examples.PINCH_TORQUE, cap=100.0)
    sol = solve(examples.pinch(), q, method="modesearch")
    _exact(sol)
    assert sol.value == pytest.approx(examples.PINCH_MAX_Z, rel=1e-6)
    assert sol.upper == pytest.approx(examples.PINCH_MAX_Z, rel=1e-4)


@pytest.mark.parametrize("gap", [1e-4, 0.05])
def test_capped_within_the_gap_and_not_below_it(gap: float) -> None:
    """The pinch's limit just above the cap: capped, the exact point within ``gap`` of the
    cap; the cap just above the limit: not capped, the limit itself."""
    g = examples.pinch()
    below = MaxDisturbance([0, 0, 1, 0, 0, 0], commands=examples.PINCH_TORQUE,
                           cap=examples.PINCH_MAX_Z * (1 - 1e-3))  # fmt: skip
    sol = solve(g, below, method="modesearch", gap=gap)
    _exact(sol)
    assert sol.stats["capped"] and sol.value >= below.cap * (1 - gap) - 1e-9
    above = MaxDisturbance([0, 0, 1, 0, 0, 0], commands=examples.PINCH_TORQUE,
                           cap=examples.PINCH_MAX_Z * (1 + 1e-3))  # fmt: skip
    sol = solve(g, above, method="modesearch", gap=gap)
    _exact(sol)
    assert not sol.stats["capped"] and sol.value <= above.cap * (1 - 5e-4)
    assert sol.upper >= examples.PINCH_MAX_Z * (1 - 1e-6)


# ------------------------------------------------------------------ brute force, 2 contacts


def _brute_force(g: Grasp, direction, preload: float, angles: int) -> float:
    """The largest ``s`` over every mode of two contacts (open; sticking, friction in an
    inscribed 64-gon; sliding against one of ``angles`` directions), one LP each with scipy
    (variables ``r`` (6), ``c`` (6), ``s``, one slide size per contact): a lower bound on
    the optimum from exact points only, written here independently of the package."""
    m = g.m
    G = g.G  # (6, 3m): G c is the contact forces' wrench
    A = G.T  # contact motion d = G^T r, rows (n, t1, t2) per contact
    d = np.asarray(direction, dtype=float)
    th = 2 * np.pi * np.arange(angles) / angles
    modes = ["open", "stick"] + [float(t) for t in th]
    poly = 2 * np.pi * (np.arange(64) + 0.5) / 64
    best = -math.inf
    n = 6 + 3 * m + 1 + m  # r, c, s, sigma
    c0, s0, g0 = 6, 6 + 3 * m, 7 + 3 * m
    for combo in itertools.product(modes, repeat=m):
        eq, beq, ub, bub = [], [], [], []
        bounds = [(None, None)] * 6 + [(None, None)] * (3 * m) + [(0, 100.0)] + [(0, None)] * m
        for row in range(6):  # G c + s d = 0
            a = np.zeros(n)
            a[c0 : c0 + 3 * m] = G[row]
            a[s0] = d[row]
            eq.append(a)
            beq.append(0.0)
        for i, mode in enumerate(combo):
            cn, ct = c0 + 3 * i, [c0 + 3 * i + 1, c0 + 3 * i + 2]
            an = np.zeros(n)
            an[:6] = A[3 * i]
            mu = float(g.mu[i])
            if mode == "open":  # c = 0, d_n >= p
                for j in (cn, *ct):
                    bounds[j] = (0.0, 0.0)
                ub.append(-an)
                bub.append(-preload)
                continue
            a = an.copy()  # c_n + d_n = p, c_n >= 0
            a[cn] = 1.0
            eq.append(a)
            beq.append(preload)
            bounds[cn] = (0.0, None)
            if mode == "stick":  # d_t = 0; c_t in the inscribed polygon
                for t in (1, 2):
                    a = np.zeros(n)
                    a[:6] = A[3 * i + t]
                    eq.append(a)
                    beq.append(0.0)
                for p in poly:
                    a = np.zeros(n)
                    a[ct[0]], a[ct[1]], a[cn] = math.cos(p), math.sin(p), -mu * math.cos(np.pi / 64)
                    ub.append(a)
                    bub.append(0.0)
                continue
            e = (math.cos(mode), math.sin(mode))  # friction along e, -d_t = sigma e
            for t in (0, 1):
                a = np.zeros(n)
                a[ct[t]], a[cn] = 1.0, -mu * e[t]
                eq.append(a)
                beq.append(0.0)
                a = np.zeros(n)
                a[:6] = A[3 * i + 1 + t]
                a[g0 + i] = e[t]
                eq.append(a)
                beq.append(0.0)
        cost = np.zeros(n)
        cost[s0] = -1.0
        res = linprog(cost, A_ub=np.array(ub) if ub else None, b_ub=bub or None,
                      A_eq=np.array(eq), b_eq=beq, bounds=bounds, method="highs")  # fmt: skip
        if res.status == 0:
            best = max(best, -res.fun)
    return best


@pytest.mark.parametrize("direction", [(0, 1, 0, 0, 0, 0), (0.3, 1, 0.4, 0, 0, 0)])
def test_two_contacts_against_brute_force(direction) -> None:
    """The wedge (two offset walls, where dropping maximum dissipation creates energy) with
    a preload of 1 N: the brute force over modes on a 10-degree grid of slide directions is
    at most the tree's proven bound, and the tree's exact value is at least the brute
    force's (every grid point is an exact point) and within the grid's loss of it."""
    g = examples.wedge()
    d = np.asarray(direction, dtype=float)
    d /= np.linalg.norm(d)
    brute = _brute_force(g, d, 1.0, 36)
    sol = solve(g, MaxDisturbance(d, preload=1.0, cap=100.0), method="modesearch")
    _exact(sol)
    assert brute <= sol.upper * (1 + 1e-7)
    assert sol.value >= brute * (1 - 1e-6)
    assert sol.value <= brute * 1.02


# ------------------------------------------------------------------ agreement


@pytest.mark.parametrize("task, k", [("max_disturbance", 0), ("max_disturbance", 1),
                                     ("optimal_commands", 0)])  # fmt: skip
def test_agrees_with_refinement_on_the_benchmark(bench, task, k) -> None:
    """Benchmark grasp (a): each method's exact value lies in the other's bracket."""
    g, q = _bench_query(bench, "a", task, k)
    ms = solve(g, q, method="modesearch")
    ref = solve(g, q, method="refinement")
    _exact(ms)
    assert ms.stats["certified"] and ref.stats["certified"]
    _inside(ms.value, ref) if task == "max_disturbance" else _inside_min(ms.value, ref)
    _inside(ref.value, ms) if task == "max_disturbance" else _inside_min(ref.value, ms)


def _inside_min(value: float, other, gap: float = 1e-4) -> None:
    """OptimalCommands: never below the other's proven lower bound, at most its exact
    upper bound plus the gap."""
    assert value >= other.lower * (1 - 1e-7) - 1e-9
    assert value <= other.upper + gap * abs(other.lower) + 1e-9


def test_check_agrees_with_refinement(bench) -> None:
    """Benchmark grasp (a)'s check: both say unstable (the tree exhausted, the relaxation
    infeasible); a stable Existence comes with an exact point."""
    g, q = _bench_query(bench, "a", "check", 0)
    assert solve(g, q, method="modesearch").stable is solve(g, q, method="refinement").stable
    ok = Existence(np.zeros(6), commands=bench["a"][1])  # balanced commands, no load
    sol = solve(g, ok, method="modesearch")
    _exact(sol)


def test_tendon_finger_agrees_with_exact_and_refinement() -> None:
    """The underactuated tendon finger pushed along +y: the tree, refinement and exact (the
    exact problem solved globally by SCIP) agree, each value inside the others' brackets."""
    g = examples.tendon_finger()
    q = MaxDisturbance([0, 1, 0, 0, 0, 0], commands=examples.TENDON_FORCE)
    ms = solve(g, q, method="modesearch")
    _exact(ms)
    _agree([ms, solve(g, q, method="refinement"), solve(g, q, method="exact", time_limit=60)])


def _agree(sols: list) -> None:
    for a, b in itertools.permutations(sols, 2):
        assert a.status == "solved" and b.status == "solved"
        if b.upper is not None:
            _inside(a.value, b)


def test_random_hand_grasp_agrees_with_refinement() -> None:
    """A random hand grasp of ``python -m stability.bench hands`` (3 contacts, the third of
    seed 0, compliant fingers): the tree and refinement agree within their brackets."""
    _, _, g, q = hand_queries(3, [3], 0)[2]
    ms = solve(g, q, method="modesearch")
    _exact(ms)
    _agree([ms, solve(g, q, method="refinement")])


@pytest.mark.slow
@pytest.mark.parametrize("index", [2, 8])
def test_random_hand_grasp_agrees_with_exact(index) -> None:
    """Random hand grasps (3 contacts, seed 0) against exact, which needs minutes on them."""
    _, _, g, q = hand_queries(index + 1, [3], 0)[index]
    ms = solve(g, q, method="modesearch")
    ex = solve(g, q, method="exact", time_limit=600)
    _agree([ms, ex])


# ------------------------------------------------------------------ status semantics


def test_timeout_returns_the_bracket_reached(bench) -> None:
    """A 6-contact query stopped after 0.2 s: status "timeout", no answer, a proven upper
    bound, and an exact lower bound below it where one was found."""
    g, q = _bench_query(bench, "l", "max_disturbance", 8)
    sol = solve(g, q, method="modesearch", time_limit=0.2)
    assert sol.status == "timeout" and sol.stable is None
    assert sol.upper is not None and sol.upper <= q.cap * (1 + 1e-9)
    assert sol.lower is None or sol.lower <= sol.upper
    assert sol.stats["nodes"] > 1 and not sol.stats["certified"]


def test_an_answer_at_the_box_has_no_bound_and_stops_growing_it(bench, monkeypatch) -> None:
    """Grasp (a), max disturbance 2: its best exact point slides without limit (a mechanism:
    the value grows towards a limit with the box). In the first box the point reaches the
    box; one tenfold box moves the value by less than the bracket's tolerance, so the
    enlargement stops there, and the answer, at the box, carries no proven bound."""
    import stability.modesearch as ms

    g, q = _bench_query(bench, "a", "max_disturbance", 2)
    with monkeypatch.context() as mp:
        mp.setattr(ms, "BOX_RETRIES", 0)
        small = solve(g, q, method="modesearch")
    assert small.stats.get("box_reached") and small.upper is None
    sol = solve(g, q, method="modesearch")
    _exact(sol)
    assert sol.stats["box_reached"] and sol.upper is None and not sol.stats["certified"]
    assert len(sol.stats["box_enlarged"]) == 1  # 1e3 -> 1e4, converged
    tol = max(1e-4 * abs(sol.value), sol.stats["abs_tol"])
    assert abs(sol.value - small.stats["exact_value"]) <= tol  # each closed to the gap


def test_a_larger_box_that_stalls_keeps_the_smaller_answer(bench, monkeypatch) -> None:
    """A search in an enlarged box limited to few nodes (as one whose LPs stop resolving
    forces against huge motions) is dropped for the smaller box's complete answer."""
    import stability.modesearch as ms

    g, q = _bench_query(bench, "a", "max_disturbance", 2)
    with monkeypatch.context() as mp:
        mp.setattr(ms, "BOX_RETRIES", 0)
        first = solve(g, q, method="modesearch")
    monkeypatch.setattr(ms, "RETRY_NODE_FACTOR", 0)
    monkeypatch.setattr(ms, "RETRY_NODE_SLACK", 2)
    sol = solve(g, q, method="modesearch")
    assert sol.value == first.value and sol.stats["bound_factor"] == 1e3
    assert "is kept" in sol.stats["box_enlarged"][-1]


def test_optimal_commands_hold_and_a_smaller_one_does_not() -> None:
    """The pinch holding 1 N along z: the cheapest equal commands hold (an exact point), and
    95 % of them do not (Existence: the tree exhausted)."""
    g = examples.pinch()
    w = [0, 0, -1.0, 0, 0, 0]
    sol = solve(g, OptimalCommands(w), method="modesearch")
    _exact(sol)
    cmd = sol.commands
    assert solve(g, Existence(w, commands=cmd * (1 + 1e-6)), method="modesearch").stable
    low = solve(g, Existence(w, commands=0.95 * cmd), method="modesearch")
    assert low.status == "solved" and low.stable is False


def test_default_for_spatial_grasps_and_bad_options_are_named() -> None:
    g = examples.pinch()
    q = MaxDisturbance([0, 0, 1, 0, 0, 0], commands=0.1)
    assert solve(g, q).method == "modesearch"
    with pytest.raises(GraspError, match="levels"):
        solve(g, q, method="modesearch", levels=3)
    with pytest.raises(GraspError, match="gap"):
        solve(g, q, method="modesearch", gap=2.0)
    with pytest.raises(GraspError, match="normal_uncertainty"):
        solve(g, q, method="modesearch", normal_uncertainty=0.1)


# ------------------------------------------------------------------ a wrong bound, once


def test_grasp_k_query_1_bound_holds_the_exact_point(bench) -> None:
    """Benchmark grasp (k), max disturbance 1 (6 contacts): an exact point holds 99.876 (every
    contact sliding; the load checked by Existence here), so no method may bound the
    optimum below it (refinement with SCIP once reported 10.011). The tree reaches the cap
    with its bracket closed."""
    g, q = _bench_query(bench, "k", "max_disturbance", 1)
    sol = solve(g, q, method="modesearch")
    _exact(sol)
    assert sol.value >= 99.876 and sol.upper >= sol.value
    assert sol.upper <= q.cap * (1 + 1e-9) and sol.stats["certified"]
    held = solve(g, Existence(99.876 * np.asarray(q.direction), commands=q.commands),
                 method="modesearch")  # fmt: skip
    _exact(held)


def test_existence_answered_by_the_first_stuck_point():
    """A preloaded pinch under no load: the first point (every contact sticking) is exact,
    so the tree is never searched; the answer still has its statistics."""
    g = Grasp([[-0.05, 0, 0], [0.05, 0, 0]], [[1, 0, 0], [-1, 0, 0]], 0.5)
    sol = solve(g, Existence(np.zeros(6), preload=[1.0, 1.0]), method="modesearch")
    assert sol.status == "solved" and sol.stable
    assert sol.stats["nodes"] == 0 and sol.stats["root_bound"] is None
    assert sol.max_residual() < 1e-9


# ------------------------------------------------------------------ contacts at one point


def _split(seed: int, step: bool) -> tuple[Grasp, np.ndarray, Grasp, np.ndarray, np.ndarray]:
    """A random three-finger grasp with contact 0 split into two contacts at its point
    (stiffness and preload shared 40/60: the same law) and, with ``step``, a contact at
    contact 1's point that engages after a gap (preload ``-k g``); the grasp whole; a
    random load direction."""
    rng = np.random.default_rng(seed)
    g = examples.random_fingers(rng, 3)
    k, pre = rng.uniform(0.5, 2.0, 3), rng.uniform(0.2, 1.0, 3)
    rows = np.array([0, 1, 2, 0, 1] if step else [0, 1, 2, 0])
    J = g.J.reshape(3, 3, -1)[rows].reshape(3 * len(rows), -1)
    ks = [0.4 * k[0], k[1], k[2], 0.6 * k[0], 2.0][: len(rows)]
    ps = [0.4 * pre[0], pre[1], pre[2], 0.6 * pre[0], -2.0 * 0.1][: len(rows)]
    parts = Grasp(g.points[rows], g.normals[rows], g.mu[rows], tangents=g.tangents[rows], J=J,
                  R=g.R, stiffness=ks)  # fmt: skip
    whole = Grasp(g.points, g.normals, g.mu, tangents=g.tangents, J=g.J, R=g.R, stiffness=k)
    return parts, np.array(ps), whole, pre, examples.random_wrench(rng)


@pytest.mark.parametrize("seed", [2, 11])
def test_a_contact_split_at_its_point_answers_as_the_whole(seed) -> None:
    """Two contacts at one point whose springs share a contact's stiffness and preload are
    that contact: each answer lies in the other's bracket."""
    parts, ps, whole, pre, d = _split(seed, step=False)
    a = solve(parts, MaxDisturbance(d, preload=ps, commands=0.01, cap=100.0),
              method="modesearch", time_limit=30)  # fmt: skip
    b = solve(whole, MaxDisturbance(d, preload=pre, commands=0.01, cap=100.0),
              method="modesearch", time_limit=30)  # fmt: skip
    for x, y in ((a, b), (b, a)):
        assert x.value is not None and y.upper is not None
        _inside(x.value, y, gap=1e-3)


@pytest.mark.parametrize("seed", [2, 11])
def test_contacts_at_one_point_are_decided_together(seed, monkeypatch) -> None:
    """The tree decides a contact together with the contacts at its point (some child
    changes more than one state), and that changes no answer: with the ties switched off
    the tree's answer lies in the tied one's bracket and the other way round."""
    from stability.modesearch import search

    parts, ps, _, _, d = _split(seed, step=True)
    q = MaxDisturbance(d, preload=ps, commands=0.01, cap=100.0)
    real, fired = search.Search.children, []

    def counting(self, node, kind, i, x):
        kids = real(self, node, kind, i, x)
        for kid in kids or []:
            changed = sum(a != b for a, b in zip(kid[0] + kid[1], node[0] + node[1], strict=True))
            fired.append(changed > 1)
        return kids

    monkeypatch.setattr(search.Search, "children", counting)
    tied = solve(parts, q, method="modesearch", time_limit=30)
    assert any(fired)
    monkeypatch.setattr(search, "colocated", lambda lp: [() for _ in range(lp.m)])
    untied = solve(parts, q, method="modesearch", time_limit=30)
    for x, y in ((tied, untied), (untied, tied)):
        assert x.value is not None and y.upper is not None
        _inside(x.value, y, gap=1e-3)
