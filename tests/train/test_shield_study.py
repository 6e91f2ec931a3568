"""python -m train.shield_study end to end at a tiny budget: it trains one run per shield,
measures it (training drops from the monitor files, held-out episodes under the shield)
and writes the per-run files, the CSVs and the chart; --report rebuilds them alone."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from train import shield_study

TINY = ["--n-envs", "2", "--n-steps", "256", "--batch-size", "256",
        "--checkpoint-every", "512", "--eval-episodes", "1", "--eval-seconds", "1",
        "--workers", "0", "--no-progress"]  # fmt: skip


@pytest.mark.slow
def test_study_runs_end_to_end(tmp_path: Path) -> None:
    out, runs = tmp_path / "out", tmp_path / "runs"
    args = ["--shields", "none,lookahead", "--seeds", "1", "--total-steps", "1024",
            "--episodes", "2", "--runs", str(runs), "--out", str(out), *TINY]  # fmt: skip
    summary = shield_study.main(args)
    assert [s["shield"] for s in summary] == ["none", "lookahead"]
    for name in ("shield_study.csv", "shield_study_summary.csv", "shield_study.png"):
        assert (out / name).stat().st_size > 0
    with (out / "shield_study.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["shield"] for r in rows] == ["none", "lookahead"]
    for r in rows:
        steps, drops = int(r["steps"]), int(r["train_drops"])
        assert steps >= 1024 and int(r["episodes"]) == 2
        assert int(r["train_episodes"]) >= 1024 // 64
        episodes, dropped, logged = _monitor_counts(runs, r)
        assert int(r["train_episodes"]) == episodes and drops == dropped
        assert float(r["drops_per_1000"]) == pytest.approx(1000 * drops / logged, abs=1e-3)
        assert r["first_target_steps"] == ""  # 1024 steps do not turn the sphere
    none, la = rows
    assert float(none["train_interventions_per_step"]) == 0.0 and none["shield_ms_median"] == ""
    assert float(none["train_shield_ms"]) == 0.0 and float(la["train_shield_ms"]) > 0
    assert float(la["shield_ms_median"]) > 0 and float(la["shield_ms_p95"]) >= float(
        la["shield_ms_median"]
    )
    m = json.loads((out / "runs" / "lookahead__1.json").read_text())
    assert m["row"]["run"] == la["run"] and len(m["drop_curve"]) == shield_study.CURVE_BINS
    cum = [c[1] for c in m["drop_curve"]]
    assert cum == sorted(cum) and cum[-1] == int(la["train_drops"])
    # a second call finds the measured runs and trains nothing; --report rebuilds the same
    before = (out / "shield_study.csv").read_text()
    (out / "shield_study.csv").unlink()
    shield_study.main([*args, "--report"])
    assert (out / "shield_study.csv").read_text() == before
    assert len(list(runs.glob("*/FourFingerRotate-*"))) == 2


def _monitor_counts(runs: Path, row: dict[str, str]) -> tuple[int, int, int]:
    """Episodes, dropped episodes and env steps in the run's monitor files, read with csv."""
    episodes = dropped = steps = 0
    for p in next(runs.glob(f"*/{row['run']}")).glob("monitor/*.monitor.csv"):
        lines = [ln for ln in p.read_text().splitlines() if not ln.startswith("#")]
        for r in csv.DictReader(lines):
            episodes += 1
            dropped += r["dropped"] == "True"
            steps += int(r["l"])
    return episodes, dropped, steps


def test_unknown_shield_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        shield_study.main(["--shields", "magic", "--out", str(tmp_path)])
