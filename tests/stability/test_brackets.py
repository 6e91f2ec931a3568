"""Brackets of the 3D optimisation answers (issue 27): ``refinement`` returns the value of
an exact point (``lower`` for MaxDisturbance, ``upper`` for OptimalCommands) beside the
relaxation's proven bound, and "solved" always carries a value.

The grasps are the benchmark's (``python -m stability.bench grasps``: grasp (a), 3
contacts, balanced commands); the "landed path" is the relaxation alone
(``certify=False``: the refinement loop to the finest level, as before the brackets),
whose answer is within its cone excess of the exact optimum.
"""

from __future__ import annotations

import numpy as np
import pytest

from stability import Existence, MaxDisturbance, OptimalCommands, solve
from stability import examples as ex
from stability.bench.grasps import grasps, queries_of

GAP = 1e-4  # refinement's default certify_gap


@pytest.fixture(scope="module")
def bench_a():
    label, g, f = grasps()[0]
    dirs = [q.direction for t, _, q in queries_of(label, f, 3, 0) if t == "max_disturbance"]
    return g, f, dirs


def _in_bracket(sol) -> None:
    lo, hi = sol.lower, sol.upper
    assert lo is not None and hi is not None
    assert lo <= sol.value <= hi
    if sol.stats["certified"]:
        assert hi - lo <= GAP * max(abs(lo), abs(hi)) + 1e-12


@pytest.mark.parametrize("k", range(2))
def test_max_disturbance_bracket_holds_the_landed_answer(bench_a, k) -> None:
    g, f, dirs = bench_a
    q = MaxDisturbance(dirs[k], commands=f, cap=100.0)
    new = solve(g, q, method="refinement")
    old = solve(g, q, method="refinement", certify=False)
    assert new.status == "solved" and new.stable
    _in_bracket(new)
    # the landed answer (the relaxation) bounds the exact optimum from above, within its
    # cone excess: the new value lies below it and within 1 %
    assert new.value <= old.value * (1 + 1e-6)
    assert new.value == pytest.approx(old.value, rel=0.01)
    # the returned point is the exact one: every condition, dissipation as alignment too
    assert new.value == new.lower
    res = new.residuals()
    assert max(res.values()) < 1e-6, res


def test_optimal_commands_bracket(bench_a) -> None:
    g, f, _ = bench_a
    rng = np.random.default_rng(3)
    q = OptimalCommands(ex.random_wrench(rng))
    new = solve(g, q, method="refinement")
    old = solve(g, q, method="refinement", certify=False)
    assert new.status == "solved" and new.stable
    _in_bracket(new)
    assert new.value == pytest.approx(old.value, rel=0.01)
    # the relaxation's cost bounds the exact optimum from below *within its box*: here the
    # exact optimum moves a joint by 7e4 (force units), beyond the box of bound_factor 100,
    # so the landed answer (0.60753) is above an exact point (0.60735); the new path found
    # that point, saw it beat its relaxation and enlarged the box
    if new.value < old.value * (1 - 1e-6):
        assert new.stats["box_enlarged"]
        assert new.stats["force_bound"] > old.stats["force_bound"]
    assert new.value == new.upper
    assert new.commands.max() == pytest.approx(new.value, rel=1e-9)
    assert max(new.residuals().values()) < 1e-6


def test_existence_answers_only_with_a_point_or_a_proof(bench_a) -> None:
    g, f, dirs = bench_a
    stable = solve(g, Existence(0.1 * dirs[0], commands=f), method="refinement")
    assert stable.status == "solved" and stable.stable
    assert max(stable.residuals().values()) < 1e-6  # an exact point
    unstable = solve(g, Existence(100.0 * dirs[0], commands=f), method="refinement")
    assert unstable.status == "solved" and unstable.stable is False
    assert "infeasible" in unstable.stats["reason"]  # a proof: an infeasible relaxation


def test_timeout_keeps_the_bracket_reached() -> None:
    """A time limit that ends the loop after its first rounds: status "timeout", no value,
    the relaxation's bound so far (and an exact value where one was found)."""
    label, g, f = grasps()[4]  # (e): 4 contacts, its max disturbance takes seconds
    q = queries_of(label, f, 1, 0)[1][2]  # its first max disturbance
    sol = solve(g, q, method="refinement", time_limit=0.6)
    if sol.status == "solved":  # a fast machine: then the bracket is closed
        _in_bracket(sol)
        return
    assert sol.status == "timeout" and sol.value is None and sol.stable is None
    rounds = sol.stats["rounds"]
    if rounds:  # at least one round finished: its bound is kept
        assert sol.upper == pytest.approx(rounds[-1]["value"])
        assert sol.lower is None or sol.lower <= sol.upper


def test_solved_always_has_a_value(bench_a) -> None:
    """Grasp (a)'s first three directions hold a load below the cap by every method: each
    answer is solved and stable with a value in ``(0, cap]``."""
    g, f, dirs = bench_a
    for d in dirs:
        for method in ("refinement", "iterative", "no_mdp"):
            sol = solve(g, MaxDisturbance(d, commands=f, cap=100.0), method=method)
            assert sol.status == "solved" and sol.stable, (method, sol.status, sol.stats)
            assert sol.value is not None and 0.0 < sol.value <= 100.0, (method, sol.stats)


def test_exact_brackets_its_answer() -> None:
    """``exact``: its polished point on the feasible side, SCIP's dual bound on the other,
    closed within its gap (the pinch's 2 mu tau / lever and the smallest commands)."""
    g = ex.pinch()
    up = [0, 0, 1, 0, 0, 0]
    s = solve(g, MaxDisturbance(up, commands=[0.1, 0.1]), method="exact")
    assert s.lower == s.value == pytest.approx(ex.PINCH_MAX_Z, rel=1e-6)
    assert s.lower <= s.upper <= s.lower * (1 + 1e-4) and s.stats["certified"]
    s = solve(g, OptimalCommands([0, 0, 2.0, 0, 0, 0]), method="exact")
    assert s.lower <= s.value == s.upper and s.stats["certified"]


def _bench_direction(label: str, k: int):
    """The benchmark's grasp ``label``, its commands and its ``k``-th max-disturbance
    direction (as ``python -m stability.bench grasps`` draws them)."""
    g, f = next((g, f) for lab, g, f in grasps() if lab == label)
    return g, f, queries_of(label, f, k + 1, 0)[-1][2].direction


def test_probe_finds_an_exact_point_the_rounds_missed() -> None:
    """Bench grasp (b), direction 7: the relaxation reaches the cap at every level and its
    modes admit no exact point; the Existence probe at the cap holds (an exact point), so
    the answer is the cap, bracketed on both sides, and its point passes residuals()."""
    g, f, d = _bench_direction("b", 7)
    sol = solve(g, MaxDisturbance(d, commands=f, cap=100.0), method="refinement")
    assert sol.status == "solved" and sol.stats["probes"], sol.stats.get("reason")
    assert sol.stats["probes"][-1]["stable"] is True
    assert sol.lower == sol.value == pytest.approx(100.0) and sol.upper == pytest.approx(100.0)
    assert sol.stats["capped"] and sol.stats["certified"]
    # the point is exact for the wrench s * d: every condition, alignment included
    assert sol.max_residual() < 1e-6 * (1.0 + sol.stats["force_bound"])
    check = solve(g, Existence(sol.value * np.asarray(d), commands=f), method="refinement")
    assert check.stable is True


def test_no_exact_point_is_not_a_solved_answer() -> None:
    """Bench grasp (d), direction 3: the relaxation reaches the cap at every level, but no
    exact point is found, by the rounds or by the probes: not converged, no value, the
    relaxation's bound kept as ``upper``. ``exact`` answers 100 there with a point whose
    friction is 28 N off its slide: it keeps its value but withdraws ``lower``."""
    g, f, d = _bench_direction("d", 3)
    q = MaxDisturbance(d, commands=f, cap=100.0)
    sol = solve(g, q, method="refinement")
    assert sol.status == "not_converged" and sol.value is None and sol.stable is None
    assert sol.lower is None and sol.upper == pytest.approx(100.0)
    assert sol.stats["relaxed_value"] == pytest.approx(100.0)
    assert all(p["stable"] is not True for p in sol.stats["probes"])
    # the relaxation alone, as asked (certify=False), still answers with its value
    rel = solve(g, q, method="refinement", certify=False)
    assert rel.status == "solved" and rel.value == pytest.approx(100.0)
    assert rel.stats["certified"] is False
    s = solve(g, q, method="exact")
    assert s.status == "solved" and s.value == pytest.approx(100.0)
    assert s.max_residual() > 1.0  # slide_alignment
    assert s.lower is None and s.stats["certified"] is False and s.stats["inexact_point"]


def test_a_map_marks_unanswered_directions() -> None:
    """``stability.maps.resistible_forces``: a direction the method did not answer (here a
    time limit of 0 s) is NaN, not 0 N ("not resisted")."""
    from stability.maps import resistible_forces

    g = ex.pinch()
    rmap = resistible_forces(g, "refinement", plane="xz", directions=2, commands=[0.1, 0.1],
                             cap=10.0, time_limit=0.0)  # fmt: skip
    assert np.isnan(rmap.magnitudes).all()
    ok = resistible_forces(g, "refinement", plane="xz", directions=2, commands=[0.1, 0.1],
                           cap=10.0)  # fmt: skip
    assert np.isfinite(ok.magnitudes).all()
