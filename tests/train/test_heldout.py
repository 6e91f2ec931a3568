"""Held-out evaluation (train.heldout) and the seeds command (train.seeds): distinct test
grasps, the intervals, and the CSV and chart."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from train.heldout import evaluate_heldout, summarize
from train.stats import wilson_interval


def test_heldout_episodes_start_from_distinct_test_grasps() -> None:
    """Each episode starts from its own test grasp; with the setpoints held (zero actions)
    the verified grasps neither drop nor turn in 1 s, and net and summed turn agree."""
    zero = lambda obs: np.zeros((len(obs), 12), np.float32)  # noqa: E731
    r = evaluate_heldout(zero, {"object": "sphere"}, episodes=7, seconds=1.0, n_envs=3)
    assert sorted(r["grasps"]) == list(range(7))
    assert r["episodes"] == 7 and r["drops"] == 0
    assert abs(r["speed_rad_s"]) < 0.1 and r["summed_rad_s"] == pytest.approx(
        r["speed_rad_s"], abs=0.02
    )
    with pytest.raises(ValueError, match="episodes"):
        evaluate_heldout(zero, {}, episodes=101)


def test_screened_start_grasps_are_the_ones_that_hold_still() -> None:
    """Under half the friction, twice the mass and weak servos some test grasps drop with the
    hand still. Screening (zero actions for the episode's length) and an unscreened
    zero-action evaluation are two independent paths: the grasps the unscreened run drops
    are exactly the ones screening skips, and from the screened ones a zero policy never
    drops."""
    from envs.four_finger import PhysicsSample

    worst = PhysicsSample(friction=0.5, mass=2.0, gain=0.8)
    zero = lambda obs: np.zeros((len(obs), 12), np.float32)  # noqa: E731
    kw = {"object": "sphere"}
    plain = evaluate_heldout(zero, kw, episodes=12, seconds=2.0, physics=worst, n_envs=4)
    scr = evaluate_heldout(zero, kw, 12, 2.0, physics=worst, n_envs=4, screen=True)
    assert scr["drops"] == 0 and scr["episodes"] == 12
    held = set(scr["grasps"])
    skipped = set(range(max(held) + 1)) - held
    assert scr["unheld_starts"] == len(skipped) > 0
    assert plain["drops"] == len(set(range(12)) - held) > 0
    assert plain["dropped_grasps"] == sorted(set(range(12)) - held)  # the two paths agree
    assert len(plain["drop_seconds"]) == plain["drops"]
    assert all(0.0 < t <= 2.0 for t in plain["drop_seconds"])
    assert scr["dropped_grasps"] == []
    assert "unheld_starts" not in plain


def test_summary_intervals() -> None:
    eps = [
        {"speed_rad_s": v, "summed_rad_s": v + 0.1, "dropped": d}
        for v, d in zip([0.4, 0.6, 0.5, 0.7, 0.3], [False, True, False, False, False], strict=True)
    ]
    s = summarize(eps)
    half = 1.96 * np.std([0.4, 0.6, 0.5, 0.7, 0.3], ddof=1) / math.sqrt(5)
    assert s["speed_rad_s"] == pytest.approx(0.5)
    assert s["speed_ci95"] == pytest.approx([0.5 - half, 0.5 + half])
    assert s["drops"] == 1 and s["drop_ci95"] == pytest.approx(list(wilson_interval(1, 5)))
    assert s["summed_rad_s"] == pytest.approx(0.6)


def test_seeds_command_evaluates_runs(tmp_path) -> None:
    """``python -m train.ppo seeds --runs DIR`` evaluates a policy on held-out grasps and
    writes seeds.csv and seeds.png."""
    from train.policy import SHIPPED
    from train.ppo import main

    rows = main(["seeds", "--runs", str(SHIPPED), "--episodes", "2", "--out", str(tmp_path)])[
        "seeds"
    ]
    assert len(rows) == 1 and rows[0]["episodes"] == 2
    with (tmp_path / "seeds.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert float(row["speed_lo"]) <= float(row["speed_rad_s"]) <= float(row["speed_hi"])
    assert float(row["drop_lo"]) <= float(row["drop_rate"]) <= float(row["drop_hi"])
    assert (tmp_path / "seeds.png").stat().st_size > 10_000


def test_factors_change_one_thing_at_a_time() -> None:
    from envs.four_finger import PhysicsSample, Randomization
    from train.heldout import factors

    nominal = PhysicsSample()
    f = factors(Randomization())
    assert len(f) == 10
    for s in f:
        changed = [k for k in ("friction", "torsional", "mass", "gain", "latency", "noise")
                   if getattr(s, k) != getattr(nominal, k)]  # fmt: skip
        assert len(changed) == 1, s


@pytest.mark.slow
def test_still_hand_counts_the_start_grasps_own_drops(tmp_path) -> None:
    """``--still``: zero actions instead of the policy; the object does not turn, the nominal
    grip's first test grasps drop at the worst corners (grasp 0 within 0.1 s), the firm grip's
    hold at all 16 (``--grip firm``), and ``--still`` without ``--out`` is refused."""
    from train.heldout import main
    from train.policy import SHIPPED

    common = ["--still", "--corners", "--corner-episodes", "3", "--episodes", "3"]
    common += ["--seconds", "2", "--workers", "1"]
    res = main([str(SHIPPED), *common, "--out", str(tmp_path / "n")])
    assert abs(res["nominal"]["speed_rad_s"]) < 0.05
    worst = [
        r for r in res["corners"] if "friction x0.5" in r["corner"] and "mass x2" in r["corner"]
    ]
    assert len(worst) == 4 and all(r["drops"] >= 1 for r in worst if "gain x0.8" in r["corner"])
    firm = main([str(SHIPPED), *common, "--grip", "firm", "--out", str(tmp_path / "f")])
    assert [r["drops"] for r in firm["corners"]] == [0] * 16
    assert (tmp_path / "f" / "robustness.csv").is_file()
    with (tmp_path / "n" / "robustness.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [len(r["dropped_grasps"].split()) for r in rows] == [int(r["drops"]) for r in rows]
    assert {g for r in rows for g in r["dropped_grasps"].split()} <= {"0", "1", "2"}
    short = ["--still", "--corners", "--corner-episodes", "1", "--episodes", "1"]
    short += ["--seconds", "0.2", "--workers", "1", "--range-scale", "0.5"]
    half = main([str(SHIPPED), *short, "--out", str(tmp_path / "h")])
    labels = [r["corner"] for r in half["corners"]]
    assert len(labels) == 16 and all("friction x0.75" in c or "friction x1.25" in c for c in labels)
    assert (tmp_path / "h" / "robustness_x0.5.csv").is_file()
    assert not (tmp_path / "h" / "robustness.csv").exists()
    with pytest.raises(SystemExit):
        main([str(SHIPPED), "--range-scale", "2"])
    with pytest.raises(SystemExit):
        main([str(SHIPPED), "--still"])


def test_a_directory_without_a_policy_is_refused_and_nothing_is_created(tmp_path, capsys) -> None:
    """``python -m train.heldout DIR`` where DIR does not exist or holds no policy: exit 2
    with one line naming what is missing; no directory or file is left behind."""
    from train.heldout import main

    nope = tmp_path / "nope"
    with pytest.raises(SystemExit) as e:
        main([str(nope)])
    assert e.value.code == 2 and f"{nope}: no such directory" in capsys.readouterr().err
    assert not nope.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(SystemExit) as e:
        main([str(empty)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "missing policy.pt or model.zip" in err
    assert list(empty.iterdir()) == []
