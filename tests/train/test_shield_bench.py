"""train.bench shield: the QP shield's measurements (accuracy, latency, effect) on tiny sizes.

Each subcommand writes its CSV, summary CSV and PNG, and its numbers satisfy checks that a
wrong measurement would fail: the linearisation's error on settled grasps, positive times in
the alternating backend order, interventions only with the shield, paired start grasps, and
a slip detector that is silent on a hand holding still."""

from __future__ import annotations

import csv
from pathlib import Path

import mujoco
import numpy as np
import pytest

from envs.four_finger import FourFingerRotate
from shields.qp import BACKENDS, STATUSES
from train.bench import (
    shield_accuracy,
    shield_common,
    shield_effect,
    shield_latency,
    shield_models,
)
from train.bench.__main__ import main as bench_main

PNG = b"\x89PNG\r\n\x1a\n"


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def check_files(out: Path, name: str, n_rows: int) -> list[dict[str, str]]:
    rows = read_csv(out / f"shield_{name}.csv")
    assert len(rows) == n_rows
    assert read_csv(out / f"shield_{name}_summary.csv")
    assert (out / f"shield_{name}.png").read_bytes()[:8] == PNG
    return rows


def test_accuracy_on_settled_grasps(tmp_path: Path) -> None:
    rows = shield_accuracy.run_accuracy(
        tmp_path, seed=0, states=2, deltas=(0.01,), sources=("settled",), actions=1,
        progress=False,
    )  # fmt: skip
    check_files(tmp_path, "accuracy", len(rows))
    servo = [r for r in rows if r["kind"] == "servo"]
    action = [r for r in rows if r["kind"] == "action"]
    # every servo of every touching finger (>= 2 fingers), and one whole action per state
    assert len(servo) >= 2 * 2 * 3 and len(servo) % 3 == 0 and len(action) == 2
    assert all(r["delta_rad"] == 0.01 and r["dq_norm_rad"] == pytest.approx(0.01) for r in servo)
    # a settled grasp keeps its contacts after 0.01 rad, and MuJoCo answers mostly linearly
    assert all(r["same_contacts"] for r in servo)
    assert np.mean([r["linear"] for r in servo]) > 0.3
    # the linearisation predicts MuJoCo's change (tests/shields/test_compliance.py: 0.14 / 0.19)
    assert np.median([r["err_force"] for r in servo]) < 0.5
    assert np.median([r["err_pos"] for r in servo]) < 0.5
    assert np.median([r["err_rot"] for r in servo]) < 0.5
    assert all(r["dc_norm"] > 0 and r["dp_norm_m"] > 0 for r in servo)
    summary = shield_accuracy.summarize_accuracy(rows)
    assert {s["perturbation"] for s in summary} == {"servo 0.01 rad", "action 0.05 a"}
    # deterministic for a seed
    again = shield_accuracy.run_accuracy(
        tmp_path / "again", seed=0, states=2, deltas=(0.01,), sources=("settled",), actions=1,
        progress=False,
    )  # fmt: skip
    assert [r["err_force"] for r in again] == [r["err_force"] for r in rows]


def test_rotation_is_in_world_axes() -> None:
    """The object's measured rotation is the world rotation vector taking q0 to q1 (what F
    predicts), not mju_subQuat's body-frame one."""
    q0 = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q0, np.array([0.0, 0.0, 1.0]), np.pi / 2)
    dq = np.zeros(4)
    mujoco.mju_axisAngle2Quat(dq, np.array([1.0, 0.0, 0.0]), 0.01)
    q1 = np.zeros(4)
    mujoco.mju_mulQuat(q1, dq, q0)  # a world-x rotation after q0
    np.testing.assert_allclose(shield_accuracy._rot(q1, q0), [0.01, 0.0, 0.0], atol=1e-12)


def test_latency_alternates_backends_at_the_same_state(tmp_path: Path) -> None:
    rows = shield_latency.run_latency(
        tmp_path, seed=0, episodes=1, steps=6, repeats=2, sources=("random",), progress=False
    )
    check_files(tmp_path, "latency", len(rows))
    states = sorted({r["state"] for r in rows})
    assert len(rows) == 4 * len(states) and len(states) >= 3
    for k in states:
        calls = sorted((r for r in rows if r["state"] == k), key=lambda r: r["call"])
        first, second = BACKENDS[k % 2], BACKENDS[1 - k % 2]
        assert [r["backend"] for r in calls] == [first, second, second, first]
        # the same state for both backends: the same touching links and contacts
        assert len({(r["links"], r["contacts"]) for r in calls}) == 1
    assert all(r["solve_time_s"] > 0 and r["status"] in STATUSES for r in rows)
    summary = shield_latency.summarize_latency(rows)
    ratio = next(s for s in summary if s["by"] == "ratio" and s["group"] == "all states")
    assert ratio["calls"] == len(states) and ratio["median_ms"] > 0
    for b in BACKENDS:
        total = next(s for s in summary if s["backend"] == b and s["group"] == "all")
        assert total["calls"] == 2 * len(states) and total["p95_ms"] >= total["median_ms"] > 0


def test_effect_pairs_episodes_and_counts_interventions(tmp_path: Path) -> None:
    rows = shield_effect.run_effect(tmp_path, seed=3, episodes=2, steps=25, agents=("random",),
                            progress=False)  # fmt: skip
    check_files(tmp_path, "effect", 4)
    for ep in range(2):
        none, qp = (next(r for r in rows if r["episode"] == ep and r["shield"] == s)
                    for s in ("none", "qp"))  # fmt: skip
        assert none["grasp"] == qp["grasp"] and none["seed"] == qp["seed"] == 3 + ep
        assert none["interventions"] == 0 and sum(none[s] for s in STATUSES) == 0
        assert sum(qp[s] for s in STATUSES) == qp["steps"]
        assert qp["interventions"] == qp["corrected"] + qp["fallback"]
    summary = {s["shield"]: s for s in shield_effect.summarize_effect(rows)}
    assert summary["qp"]["intervention_rate"] > 0 and summary["qp"]["mean_correction"] > 0
    assert summary["none"]["intervention_rate"] == 0
    assert 0 <= summary["none"]["drop_lo"] <= summary["none"]["drop_rate"] <= 1
    # random actions make contacts slide
    assert sum(r["slip_events"] for r in rows) > 0


def test_slip_detector_is_silent_on_a_still_hand() -> None:
    env = FourFingerRotate()
    zero = np.zeros(12, dtype=np.float32)
    for seed in range(3):
        row = shield_effect.run_episode(
            env, lambda obs: zero, seed=seed, action_seed=(0,), steps=10
        )
        assert row["slip_events"] == row["contact_losses"] == 0 and not row["dropped"]
    # MuJoCo's forces lie in the elliptic cone (ratio <= 1), some of them on it (ratio = 1)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    links = shield_common.Links(env.model)
    ratios = []
    for _ in range(5):
        env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        ratios += shield_common.cone_ratios(
            env.data, [i for _, i in links.contacts(env.data)]
        ).tolist()
    assert ratios and max(ratios) <= 1 + 1e-9 and max(ratios) >= shield_common.SLIP_RATIO


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--out", str(tmp_path), "--no-progress", "--seed", "1"]
    bench_main(["shield", "effect", *args, "--episodes", "1", "--steps", "3", "--agents", "random"])
    text = capsys.readouterr().out
    assert "paired speed difference" in text and "shield_effect.png" in text
    with pytest.raises(SystemExit) as exc:
        bench_main(["shield", "effect", *args, "--agents", "robot"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        bench_main(["shield", "latency", *args, "--steps", "0"])
    assert exc.value.code == 2


def test_models_pairs_start_grasps_across_shields(tmp_path: Path) -> None:
    names = ("none", "qp-thesis", "lookahead-thesis", "lookahead-drop")
    rows = shield_models.run_models(tmp_path, seed=2, episodes=2, steps=30, agents=("random",),
                                    variants=names, progress=False)  # fmt: skip
    check_files(tmp_path, "models", 2 * len(names))
    for ep in range(2):
        sel = {r["shield"]: r for r in rows if r["episode"] == ep}
        assert sel["none"]["interventions"] == 0 and sel["none"]["ms"] == []
        for name in names[1:]:
            r = sel[name]
            assert len(r["ms"]) == r["steps"] and min(r["ms"]) > 0
            assert sum(r["statuses"].values()) == r["steps"]
            assert r["interventions"] == r["steps"] - r["statuses"].get("safe", 0) - r[
                "statuses"
            ].get("no_closure", 0)
    summary = {s["shield"]: s for s in shield_models.summarize_models(rows)}
    # the thesis' criteria reject random actions almost always, with either model; the
    # drop criteria let most of them through in 30 steps
    assert summary["qp-thesis"]["interventions_per_step"] > 0.5
    assert summary["lookahead-thesis"]["interventions_per_step"] > 0.5
    assert summary["lookahead-drop"]["interventions_per_step"] < 0.5
    assert summary["lookahead-thesis"]["ms_median"] > summary["qp-thesis"]["ms_median"] > 0
