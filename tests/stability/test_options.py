"""Typed method options (stability.options): checked once by solve(), one deadline, one box
enlargement; the typed common stats (stability.Stats)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from stability import (
    Deadline,
    Existence,
    Grasp,
    GraspError,
    MaxDisturbance,
    MethodError,
    MethodOptions,
    Stats,
    available_methods,
    examples,
    method_info,
    solve,
)
from stability.options import BOX_RETRIES, enlarge_box

Z = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("method", available_methods())
def test_every_method_declares_frozen_options_with_valid_defaults(method: str) -> None:
    cls = method_info(method).options
    assert issubclass(cls, MethodOptions)
    opts = cls()  # the defaults pass the range checks
    with pytest.raises(AttributeError):
        opts.some_field = 1  # frozen


@pytest.mark.parametrize("method", ["modesearch", "refinement", "exact", "iterative", "no_mdp",
                                    "gws"])  # fmt: skip
def test_an_unknown_option_is_a_method_error_listing_the_valid_ones(method: str) -> None:
    g = examples.pinch()
    if method == "gws":  # a rigid-hand baseline
        g = Grasp(g.points, g.normals, g.mu)
    with pytest.raises(MethodError, match=r"unknown option\(s\) \['tim_limit'\]") as e:
        solve(g, Existence(Z), method=method, tim_limit=5)
    for f in ("time_limit",) if method != "gws" else ("edges",):
        assert f in str(e.value)


def test_a_wrongly_typed_option_is_a_method_error_naming_its_type() -> None:
    g = examples.pinch()
    with pytest.raises(MethodError, match="levels=2.5 .* must be int"):
        solve(g, Existence(Z), method="refinement", levels=2.5)
    with pytest.raises(MethodError, match="time_limit='5' .* must be float | None"):
        solve(g, Existence(Z), method="modesearch", time_limit="5")
    with pytest.raises(MethodError, match="certify=1 .* must be bool"):
        solve(g, Existence(Z), method="refinement", certify=1)
    # an integer is a float; numpy scalars are numbers
    assert solve(g, Existence(Z), method="modesearch", time_limit=np.int64(30)).status == "solved"


def test_an_option_out_of_range_is_a_grasp_error_naming_the_range() -> None:
    g = examples.pinch()
    for method, kw, where in [
        ("modesearch", {"gap": 1.5}, "gap must be in"),
        ("refinement", {"initial_edges": 5}, "initial_edges must be 4 or 8"),
        ("exact", {"feastol": 0.1}, "feastol must be in"),
        ("iterative", {"epsilon": 1e-2}, "net_tol must be finite and above epsilon"),
        ("no_mdp", {"edges": 2}, "edges must be an integer >= 3"),
        ("modesearch", {"time_limit": -1.0}, "time_limit must be finite and >= 0"),
    ]:
        with pytest.raises(GraspError, match=where) as e:
            solve(g, Existence(Z), method=method, **kw)
        assert not isinstance(e.value, MethodError)
    with pytest.raises(MethodError, match="needs SCIP"):
        solve(g, Existence(Z), method="exact", backend="highs")


def test_a_deadline_counts_down_from_its_start() -> None:
    assert Deadline(None).remaining() is None and not Deadline(None).expired()
    d = Deadline(10.0)
    assert 9.0 < d.remaining() <= 10.0 and not d.expired()
    past = Deadline(1.0, start=time.perf_counter() - 2.0)
    assert past.remaining() == 0.0 and past.expired()
    assert d.at() == pytest.approx(d.start + 10.0)


def test_enlarge_box_grows_while_cut_and_keeps_an_answer_a_larger_box_lost() -> None:
    """Scripted attempts: cut at 1 and 10, solved at 100; and a time-out at 10 that keeps
    the answer of 1."""
    seen: list[float] = []

    def attempt(factor: float, prev: str | None) -> tuple[str, str | None]:
        seen.append(factor)
        return f"answer {factor:g}", "at the box" if factor < 100 else None

    sol, notes = enlarge_box(attempt, 1.0, Deadline(None), lambda p, s: None)
    assert seen == [1.0, 10.0, 100.0] and sol == "answer 100" and len(notes) == 2
    assert notes[0].startswith("bound_factor 1: at the box")

    seen.clear()
    sol, notes = enlarge_box(attempt, 1e-3, Deadline(None), lambda p, s: None)
    assert len(seen) == BOX_RETRIES + 1  # at most BOX_RETRIES enlargements

    def timeout_at_10(factor: float, prev: str | None) -> tuple[str, str | None]:
        return ("timeout" if factor == 10 else "answer"), "at the box"

    sol, notes = enlarge_box(timeout_at_10, 1.0, Deadline(None),
                             lambda p, s: "timed out" if s == "timeout" else None)  # fmt: skip
    assert sol == "answer" and "is kept" in notes[-1]

    expired = Deadline(0.0, start=time.perf_counter() - 1.0)
    sol, notes = enlarge_box(attempt, 1.0, expired, lambda p, s: None)
    assert sol == "answer 1" and notes[-1].endswith("no time left")


def test_stats_reads_the_common_keys_as_typed_attributes_of_the_methods_dict() -> None:
    g = examples.pinch()
    sol = solve(g, MaxDisturbance(Z, commands=[0.1, 0.1]), method="modesearch")
    st = sol.stats
    assert isinstance(st, Stats)
    assert st.time_s == st["time_s"] > 0 and st.certified is st["certified"] is True
    assert st.nodes == st["nodes"] >= 1 and st.box_enlarged is None
    raw = {"backend": "scip"}
    wrapped = Stats(raw)
    raw["nodes"] = 7  # a wrapped dict is the method's own, not a copy
    assert wrapped.nodes == 7 and wrapped.backend == "scip" and dict(wrapped) == raw
