"""The generalist's training pieces: automatic domain randomisation (:mod:`train.adr`), the
``--generalist`` preset, and a tiny run stopped and resumed against an uninterrupted one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from envs.four_finger import TRAIN_OBJECTS
from train.adr import MIN_EPISODES, AdrState, next_scale, object_weights
from train.rotation_config import GENERALIST, parse_config

ROOT = Path(__file__).resolve().parents[2]


def test_next_scale_widens_narrows_and_holds() -> None:
    """Up by the step at or below ``widen`` (capped at 1), down above ``narrow`` (not below
    the start), unchanged in between or with too few episodes."""
    n = MIN_EPISODES
    assert next_scale(0.25, 0, n, 0.125, 0.1, 0.25, 0.25) == 0.375
    assert next_scale(0.25, int(0.1 * 100), 100, 0.125, 0.1, 0.25, 0.25) == 0.375
    assert next_scale(0.5, 11, 100, 0.125, 0.1, 0.25, 0.25) == 0.5
    assert next_scale(0.5, 26, 100, 0.125, 0.1, 0.25, 0.25) == 0.375
    assert next_scale(0.25, 90, 100, 0.125, 0.1, 0.25, 0.25) == 0.25
    assert next_scale(0.9375, 0, 100, 0.125, 0.1, 0.25, 0.25) == 1.0
    assert next_scale(0.5, 0, n - 1, 0.125, 0.1, 0.25, 0.25) == 0.5


def test_object_weights_follow_the_drop_rates_with_a_floor() -> None:
    """Half the draw uniform, half in proportion to the drop rates; uniform without drops;
    an object without episodes counts as not dropping."""
    eps = {"sphere": 100, "cylinder": 50, "cube": 50}
    w = object_weights({"sphere": 0, "cylinder": 25, "cube": 50}, eps, 0.5)
    assert w == pytest.approx({"sphere": 1 / 6, "cylinder": 1 / 6 + 0.5 / 3, "cube": 1 / 6 + 1 / 3})
    assert sum(w.values()) == pytest.approx(1.0)
    assert object_weights({}, eps, 0.5) == pytest.approx(dict.fromkeys(eps, 1 / 3))
    w = object_weights({"cube": 5}, {"sphere": 0, "cube": 10}, 0.5)
    assert w == pytest.approx({"sphere": 0.25, "cube": 0.75})


def test_adr_state_drops_decisions_after_the_checkpoint(tmp_path) -> None:
    """A resumed run reads the schedule as it was at its checkpoint's step count."""
    rows = [{"steps": s, "scale_before": a, "scale": b, "episodes": 20, "drop_rate": 0.0}
            for s, a, b in ((100, 0.25, 0.375), (200, 0.375, 0.5), (300, 0.5, 0.625))]  # fmt: skip
    AdrState(0.625, rows).save(tmp_path / "adr.json")
    st = AdrState.load(tmp_path / "adr.json", 0.25, upto=250)
    assert st.scale == 0.5 and [r["steps"] for r in st.history] == [100, 200]
    assert AdrState.load(tmp_path / "adr.json", 0.25, upto=50).scale == 0.25
    assert AdrState.load(tmp_path / "nothing.json", 0.25, upto=50).history == []


def test_generalist_preset_and_its_checks() -> None:
    """``--generalist`` sets the three objects, ADR from a quarter of the full ranges, history
    and the asymmetric critic; given options still apply; bad objects and ADR bounds are
    refused by name."""
    cfg = parse_config(["--generalist", "--seed", "3"])
    assert cfg.objects == list(TRAIN_OBJECTS) and cfg.seed == 3
    rnd = cfg.randomization
    assert rnd.randomize and rnd.adr_step == GENERALIST["adr_step"] and rnd.range_scale == 0.25
    assert rnd.full_ranges().friction == (0.5, 1.5) and rnd.ranges().friction == (0.875, 1.125)
    assert cfg.observation.history == 3 and cfg.observation.privileged
    with pytest.raises(SystemExit):
        parse_config(["--objects", "sphere", "sphere"])
    with pytest.raises(SystemExit):
        parse_config(["--objects", "sphere", "--randomize", "--adr-step", "0.1",
                      "--adr-widen", "0.5", "--adr-narrow", "0.2"])  # fmt: skip


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "train.ppo", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)  # fmt: skip


def _one_run(out: Path) -> Path:
    (run_dir,) = list(out.iterdir())
    return run_dir


@pytest.mark.slow
def test_a_stopped_and_resumed_run_equals_an_uninterrupted_one(tmp_path) -> None:
    """A tiny mixed-object ADR run of 512 env steps, and the same run stopped at 256 and
    resumed for 256 more: the same step count and the same schedule (the ADR decisions at
    the same steps with the same scales; ``--adr-widen 1`` widens at every decision, so the
    schedule does not depend on which episodes dropped), the config kept."""
    tiny = [
        "--objects", *TRAIN_OBJECTS, "--randomize", "--range-scale", "0.25", "--adr-step",
        "0.125", "--adr-every", "128", "--adr-widen", "1", "--adr-narrow", "1", "--object-share",
        "0.5", "--n-envs", "2",
        "--workers", "0", "--n-steps", "64", "--batch-size", "64", "--n-epochs", "1", "--pi",
        "16", "--vf", "16", "--history", "2", "--privileged-critic", "--episode-steps", "5",
        "--eval-episodes", "0", "--checkpoint-every", "256", "--no-progress",
    ]  # fmt: skip
    p = _run(*tiny, "--total-steps", "512", "--out", str(tmp_path / "whole"))
    assert p.returncode == 0, p.stderr[-2000:]
    q = _run(*tiny, "--total-steps", "256", "--out", str(tmp_path / "split"))
    assert q.returncode == 0, q.stderr[-2000:]
    split = _one_run(tmp_path / "split")
    r = _run("--resume", str(split), "--total-steps", "256", "--no-progress")
    assert r.returncode == 0, r.stderr[-2000:]
    whole = _one_run(tmp_path / "whole")
    a, b = (json.loads((d / "adr.json").read_text()) for d in (whole, split))
    key = [(h["steps"], h["scale_before"], h["scale"]) for h in a["history"]]
    assert key == [(h["steps"], h["scale_before"], h["scale"]) for h in b["history"]]
    assert key == [(128, 0.25, 0.375), (256, 0.375, 0.5), (384, 0.5, 0.625), (512, 0.625, 0.75)]
    assert a["scale"] == b["scale"] == 0.75
    for h in a["history"] + b["history"]:  # the object curriculum's draw, each decision
        assert set(h["weights"]) == set(TRAIN_OBJECTS) and sum(h["weights"].values()) > 0.99
        assert min(h["weights"].values()) >= 0.5 / 3 - 1e-4
    res = [json.loads((d / "eval.json").read_text()) for d in (whole, split)]
    assert res[0]["num_timesteps"] == res[1]["num_timesteps"] == 512
    cfgs = [json.loads((d / "config.json").read_text()) for d in (whole, split)]
    assert cfgs[1]["objects"] == list(TRAIN_OBJECTS) and cfgs[1]["randomization"]["adr_step"]
