"""method="exact" (the exact problem by SCIP's spatial branch-and-bound; formerly "spatial")
and refinement's certificates: known answers, residuals of the exact conditions (maximum
dissipation included), agreement with planar and refinement, bad input, the old name."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from stability import (
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    MethodError,
    OptimalCommands,
    available_methods,
    examples,
    solve,
)

Z = [0, 0, 1, 0, 0, 0]


def _exact_check(sol, tol=1e-7) -> None:
    """Every condition of the exact problem holds, maximum dissipation and the circular
    cone included (refinement only bounds the cone's excess)."""
    assert sol.status == "solved" and sol.stable
    assert "max_dissipation" in sol.conditions and "friction_cone" in sol.conditions
    scale = 1.0 + float(np.abs(sol.forces).max())
    assert sol.max_residual() <= tol * scale, sol.residuals()


def test_pinch_spot_checks() -> None:
    """The thesis' pinch: 2 mu tau / lever = 2.22 N along z exactly; 1 N unstable with no
    commands; 2.2 N stable and 2.5 N unstable with 0.1 N m."""
    g = examples.pinch()
    sol = solve(g, MaxDisturbance(Z, commands=0.1, cap=100.0), method="exact")
    _exact_check(sol)
    assert sol.value == pytest.approx(examples.PINCH_MAX_Z, rel=1e-6)
    assert sol.stats["polished"]  # the exact LP of SCIP's modes took over: residuals ~ 0
    w = np.array(Z, dtype=float)
    assert solve(g, Existence(-1.0 * w), method="exact").stable is False
    assert solve(g, Existence(-2.2 * w, commands=0.1), method="exact").stable is True
    assert solve(g, Existence(-2.5 * w, commands=0.1), method="exact").stable is False


@pytest.mark.parametrize("direction", [(0, 1, 0), (1, 1, 0.02), (-1, 0.5, 0)])
def test_agrees_with_planar_on_the_embedded_grasp(direction) -> None:
    """Two independent exact methods: planar's slip-state enumeration on the thesis'
    three-contact grasp and exact on the same grasp embedded in z = 0."""
    planar = solve(examples.three_planar(), MaxDisturbance(direction, preload=1.0, cap=100.0),
                   method="planar")  # fmt: skip
    q = MaxDisturbance(examples.embed_wrench(direction), preload=1.0, cap=100.0)
    sol = solve(examples.three_embedded(), q, method="exact")
    _exact_check(sol)
    assert sol.value == pytest.approx(planar.value, rel=1e-5)


def test_tendon_finger_agrees_with_refinement_and_its_certificate() -> None:
    """The tendon finger pushed along +y (where a coarse relaxation and no_mdp hold 100 N):
    exact's optimum, refinement's converged bound (above it, within 1e-4) and
    refinement's certified exact point (stats exact_value) agree."""
    g = examples.tendon_finger()
    q = MaxDisturbance([0, 1, 0, 0, 0, 0], commands=examples.TENDON_FORCE, cap=100.0)
    ex = solve(g, q, method="exact")
    _exact_check(ex)
    ref = solve(g, q, method="refinement")
    assert ex.value <= ref.value * (1 + 1e-9)  # the relaxation contains the exact problem
    assert ref.value == pytest.approx(ex.value, rel=1e-4)
    assert ref.stats["exact_value"] == pytest.approx(ex.value, rel=1e-6)


def test_optimal_commands_and_robustness() -> None:
    """Pinch holding 1 N along -z: the least largest command is mu c_n = 1/2 per contact,
    i.e. lever / (2 mu) = 0.045 N m on both fingers (exact and refinement agree); a
    normal uncertainty never raises the max disturbance."""
    g = examples.pinch()
    w = [0, 0, -1.0, 0, 0, 0]
    want = examples.PINCH_LEVER / (2 * examples.PINCH_MU)
    sp = solve(g, OptimalCommands(w), method="exact")
    _exact_check(sp)
    assert sp.value == pytest.approx(want, rel=1e-5)
    assert sp.commands.max() == pytest.approx(want, rel=1e-5)
    ref = solve(g, OptimalCommands(w), method="refinement")
    assert ref.value == pytest.approx(sp.value, rel=1e-3)
    q = MaxDisturbance([0, 0.3, 1, 0, 0, 0], commands=0.1, cap=100.0)
    nominal = solve(g, q, method="exact").value
    robust = solve(g, q, method="exact", normal_uncertainty=math.radians(2.5)).value
    assert robust <= nominal * (1 + 1e-6)


def test_robust_spring_law_uses_the_true_slide() -> None:
    """With eta > 0 the slide bound s enters the spring law, so it must equal |d_t| (a
    free s would unload any contact): on the preloaded embedded grasp the robust answer
    never exceeds the nominal one and its s equals |d_t| (stats violations "slide")."""
    g = examples.three_embedded()
    q = MaxDisturbance(examples.embed_wrench((1, 1, 0.02)), preload=1.0, cap=100.0)
    nominal = solve(g, q, method="exact")
    robust = solve(g, q, method="exact", normal_uncertainty=0.2)
    assert robust.status == "solved" and robust.value <= nominal.value * (1 + 1e-6)
    assert robust.stats["violations"]["slide"] <= 1e-7


def test_refinement_existence_certificate_is_exact() -> None:
    """A stable refinement answer whose relaxed point survives the exact LP with its
    modes is returned as that exact point: every condition, maximum dissipation and the
    circular cone included."""
    g = examples.tendon_finger()
    sol = solve(g, Existence([0, 1.0, 0, 0, 0, 0], commands=examples.TENDON_FORCE),
                method="refinement")  # fmt: skip
    assert sol.stats["certified"]
    _exact_check(sol)


def test_bad_input_and_time_out() -> None:
    g = examples.pinch()
    q = MaxDisturbance(Z, commands=0.1)
    with pytest.raises(MethodError, match="SCIP"):
        solve(g, q, method="exact", backend="highs")
    with pytest.raises(GraspError):
        solve(examples.three_planar(), MaxDisturbance((0, 1, 0)), method="exact")
    for bad in ({"feastol": 0.0}, {"gap": 1.0}, {"normal_uncertainty": -0.1},
                {"motion_bound": 0.5}, {"frobnicate": 1}, {"recheck": 1},
                {"presolve": "no"}):  # fmt: skip
        with pytest.raises(GraspError):
            solve(g, q, method="exact", **bad)
    t = solve(examples.tendon_finger(), MaxDisturbance([0, 0, 1, 0, 0, 0], commands=1.0),
              method="exact", time_limit=0.01)  # fmt: skip
    assert t.status == "timeout" and t.stable is None


def test_old_name_spatial_still_works_and_warns() -> None:
    """``method="spatial"`` is the old name of ``exact``: the same answer, a
    DeprecationWarning that names the new one, and ``exact`` itself does not warn."""
    g = examples.pinch()
    q = MaxDisturbance(Z, commands=0.1, cap=100.0)
    with pytest.warns(DeprecationWarning, match="'exact'"):
        old = solve(g, q, method="spatial")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = solve(g, q, method="exact")
    assert old.method == new.method == "exact"
    assert old.value == new.value
    assert "spatial" not in available_methods() and "exact" in available_methods()


# ------------------------------------------------- SCIP's wrong prunes (stability/exact.py)


def _fingers(points, normals, mu, levers) -> Grasp:
    """A grasp of ``examples.random_fingers``' kind: one single-joint finger per contact."""
    J = np.zeros((9, 3))
    for i, lever in enumerate(levers):
        J[3 * i : 3 * i + 3, i] = lever
    return Grasp(points, normals, mu, J=J, R=np.eye(3))


# random_fingers(default_rng(seed), 3) with bench.grasps.balanced_commands and a random unit
# direction (bench.grasps._unit), seeds 51 and 84 of the survey in stability/exact.py
SEED51 = (
    _fingers(
        [[0.04891669947508782, 0.010296667558739736, 0.001065434018952121],
         [-0.04490577466676112, -0.020697403566700353, -0.007422188839905293],
         [0.01075578479699545, -0.007150608662909929, 0.048303021532308296]],
        [[-0.9428530424797131, -0.3318813186134584, -0.029714148854383577],
         [0.9811532935189333, 0.17397892254937103, -0.08408061087735876],
         [0.060905101242216035, 0.01880169565583467, -0.9979664648088837]],
        [0.3623995965807076, 0.5970913381790997, 0.7431007504863134],
        [[0.06234971396472068, -0.011406374432192161, 0.0007833101235698216],
         [0.06565606592290175, -0.0020809896000716847, -0.003918152278812096],
         [0.06715409879058887, -0.004830233990936503, 0.01105681862478324]],
    ),
    [0.2350450873160939, 0.21194660889320044, 0.07070243522400624],
    [0.15223919403998099, 0.10868732223935709, -0.5079890101123636, 0.22031783179299097,
     -0.7629364866617758, 0.2763067673832427],
)  # fmt: skip
SEED84 = (
    _fingers(
        [[0.00238595254290835, -0.028522526256567805, -0.04099722827712124],
         [0.022456945970720704, -0.042739057942113086, 0.013002249954866695],
         [-0.024202356454755148, 0.035335797729581626, -0.025799754666489868]],
        [[-0.13602953189842373, 0.5217239844187341, 0.8421995313070034],
         [-0.3442955956304093, 0.9374397747820293, -0.05164505287169151],
         [0.5042203179192828, -0.6252278482617243, 0.595694559951148]],
        [0.4549088262145846, 0.9368131302634164, 0.8814972907967951],
        [[0.08109892500653598, 0.011793353636406661, 0.003040896178602222],
         [0.05139280401878206, 0.0025992538690703787, -0.0060818843364027495],
         [0.08743723560807908, -0.003527289771611666, 4.784781376106911e-05]],
    ),
    [0.07845512407096299, 1.4318137067806473, 2.415645323298019],
    [0.2794287957635127, 0.7658919934053585, -0.5760372309312399, -0.016486938194279287,
     0.05633966015437904, -0.008008413042282482],
)  # fmt: skip


def test_presolve_infeasibility_is_rechecked() -> None:
    """Seed 51: the commands hold (s = 0, 0.1, 0.14 are stable, 0.05 s each) and
    refinement finds 0.141744, but SCIP's presolved model of the MaxDisturbance with cap 10
    was "infeasible" in 0.07 s (1 node): the answer was "unstable" for every s. Rechecked
    without presolve it is 0.141744 after about 40 s; here only that the wrong "unstable"
    is gone within 5 s (a time-out, with SCIP's incumbent at the answer when it has one: on
    a loaded machine it may have none yet)."""
    g, f, d = SEED51
    assert solve(g, Existence(0.1 * np.asarray(d), commands=f), method="exact").stable
    sol = solve(g, MaxDisturbance(d, commands=f, cap=10.0), method="exact", time_limit=5.0)
    assert sol.stable is not False
    if sol.status == "timeout":
        inc = sol.stats["incumbent"]
        assert inc is None or inc == pytest.approx(0.141744, rel=1e-4)
        assert sol.upper is None or sol.upper >= 0.141744 * (1 - 1e-4)
    else:
        assert sol.status == "solved" and sol.value == pytest.approx(0.141744, rel=1e-4)


@pytest.mark.slow
def test_an_optimum_pruned_too_low_is_refuted_in_a_fitted_box() -> None:
    """Seed 84 without presolve: SCIP's optimum in the query's box (cap 100) is 0.250946,
    with its dual bound equal to it, where the exact optimum is 0.362424 (refinement and
    exact with presolve): 31 % low, the failure issue 27 reports (0.37744 for 0.46300).
    The recheck in a box fitted to it (cap 0.50) finds 0.362431 and says so. (Its point
    is SCIP's, unpolished: every contact slides by 1e-4 with friction inside the cone,
    which the slide_alignment residual shows.)"""
    g, f, d = SEED84
    q = MaxDisturbance(d, commands=f, cap=100.0)
    sol = solve(g, q, method="exact", presolve=False, time_limit=600)  # 120 s: cut under load
    assert sol.status == "solved" and sol.value == pytest.approx(0.362424, rel=1e-4)
    assert sol.stats["recheck"]["first"] == pytest.approx(0.250946, rel=1e-4)
    assert sol.stats["recheck"]["disagreement"] and "refuted" in sol.stats["message"]
    # the first solve's dual bound (0.250946) is refuted: no upper bound is claimed
    assert sol.lower == sol.value and sol.upper is None and not sol.stats["certified"]
    res = sol.residuals()
    assert max(v for k, v in res.items() if k != "slide_alignment") <= 1e-6 * 1e4
    assert sol.stats["violations"]["alignment"] == pytest.approx(res["slide_alignment"])


def test_a_disagreement_withdraws_the_upper_bound() -> None:
    """The bracket after a recheck (stability/exact.py, "Brackets"): SCIP's dual bound in
    the query's box is the upper bound, unless a recheck disagreed: then SCIP pruned wrongly
    on this query and no upper bound is claimed."""
    from stability.exact import _bracket
    from stability.model.query import QueryData
    from stability.solution import Solution

    g = examples.pinch()
    q = MaxDisturbance(Z, commands=[0.1, 0.1], cap=10.0)
    data = QueryData.of(g, q)

    def bracket(recheck):
        stats = {"gap": 1e-4, "dual_bound": 0.25, "recheck": recheck}
        return _bracket(Solution(True, "exact", g, q, value=0.25, stats=stats), data, 0.25)

    agreed = bracket({"first": 0.25, "solves": [], "disagreement": False})
    assert (agreed.lower, agreed.upper, agreed.stats["certified"]) == (0.25, 0.25, True)
    refuted = bracket({"first": 0.2, "solves": [], "disagreement": True})
    assert (refuted.lower, refuted.upper, refuted.stats["certified"]) == (0.25, None, False)


# ------------------------------------------------------- the box (stability/exact.py)


@pytest.mark.slow
def test_an_answer_at_the_box_is_solved_again_in_a_larger_one() -> None:
    """The tendon finger along +z with a box of 1 (bound_factor) times the force scale: the
    answer's slide reaches the box, so the query is solved again in a box of 10, where
    the optimum lies inside (0.48917, as with bound_factor 3 and refinement) and SCIP's
    bound closes the bracket."""
    g = examples.tendon_finger()
    q = MaxDisturbance(Z, commands=1.0)
    sol = solve(g, q, method="exact", bound_factor=1.0, time_limit=120)
    assert sol.status == "solved"
    assert len(sol.stats["box_enlarged"]) == 1 and "bound_factor 1:" in sol.stats["box_enlarged"][0]
    assert not sol.stats["box_reached"] and sol.stats["certified"]
    assert sol.lower == sol.value <= sol.upper
    ref = solve(g, q, method="refinement")
    assert sol.value == pytest.approx(ref.value, rel=1e-4)
    _exact_check(sol, tol=1e-6)


def test_the_box_loop_keeps_its_answer_and_withdraws_the_bound(monkeypatch) -> None:
    """The loop of stability/exact.py ("The box") on scripted solves: a first answer at its
    box is solved again tenfold larger; a time-out there leaves the first answer, which
    (still at its box) gets no upper bound and is not certified."""
    import stability.exact as exact_mod
    from stability.solution import Solution

    g = examples.pinch()
    q = MaxDisturbance(Z, commands=[0.1, 0.1])
    factors = []

    def once(grasp, query, opts, deadline):
        factors.append(opts.bound_factor)
        if len(factors) == 1:
            stats = {"box_reached": True, "certified": True, "gap": 1e-4}
            return Solution(True, "exact", grasp, query, value=1.0, stats=stats, lower=1.0,
                            upper=1.0)  # fmt: skip
        return Solution(None, "exact", grasp, query, status="timeout", stats={})

    monkeypatch.setattr(exact_mod, "_solve_once", once)
    sol = solve(g, q, method="exact", time_limit=5.0)
    assert factors == [100.0, 1000.0]
    assert sol.status == "solved" and sol.value == 1.0
    assert sol.upper is None and sol.lower == 1.0 and sol.stats["certified"] is False
    assert "bound_factor 1000: timeout" in sol.stats["box_enlarged"][-1]
    assert "is kept" in sol.stats["box_enlarged"][-1]


@pytest.mark.slow
def test_a_recheck_stopped_by_the_time_limit_leaves_the_answer_uncertified(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Seed 84 with presolve (SCIP's optimum 0.362424 is right): the fitted box's solve is
    made to stop as a time-out would. The first answer stands, but not certified, and the
    message says the recheck did not run (before: certified, as if confirmed)."""
    import stability.exact as exact

    real, calls = exact._Run.attempt, []

    def attempt(self, *args, **kwargs):
        calls.append(1)
        if len(calls) > 1:
            raise exact.Stop("timeout", "time_limit 120 s reached")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(exact._Run, "attempt", attempt)
    g, f, d = SEED84
    sol = solve(g, MaxDisturbance(d, commands=f, cap=100.0), method="exact")
    assert len(calls) == 2  # the first solve and the stopped recheck
    assert sol.status == "solved" and sol.value == pytest.approx(0.362424, rel=1e-4)
    assert sol.stats["recheck"]["stopped"] == "timeout"
    assert not sol.stats["certified"] and "unconfirmed" in sol.stats["message"]
    assert sol.stats["recheck"]["solves"][0]["status"] == "timeout"


def test_a_time_outs_incumbent_is_the_value_of_its_checked_point(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A time-out keeps SCIP's incumbent on the feasible side only as the value of its
    polished, checked point: here SCIP's optimum of the pinch reported as a time-out whose
    objective is 1 % above its point's (SCIP's incumbent value and point can differ by its
    tolerances). The bracket's lower side is the point's value, the pinch's limit."""
    import dataclasses

    import stability.exact as exact

    real = exact._scip

    def timed_out(ex, opts, time_limit, stats):
        res = real(ex, opts, time_limit, stats)
        return dataclasses.replace(res, status="timeout", objective=1.01 * res.objective)

    monkeypatch.setattr(exact, "_scip", timed_out)
    q = MaxDisturbance(Z, commands=examples.PINCH_TORQUE, cap=100.0)
    sol = solve(examples.pinch(), q, method="exact")
    assert sol.status == "timeout" and sol.stats["incumbent_checked"]
    assert sol.lower == pytest.approx(examples.PINCH_MAX_Z, rel=1e-6)
    assert sol.upper >= sol.lower
