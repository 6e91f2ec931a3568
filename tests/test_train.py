"""``python -m train.ppo`` and ``python -m train.islands``: smoke runs, resume, bad options.

Tiny budgets (a few hundred steps) so the file stays well under a minute; the
real benchmark is ``python -m train.islands`` (see README).
"""

from __future__ import annotations

import csv
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from train import islands, ppo

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--n-envs", "2", "--n-steps", "64", "--batch-size", "64", "--n-epochs", "1"]


def run(module: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def num_timesteps(model_zip: Path) -> int:
    with zipfile.ZipFile(model_zip) as z:
        return int(json.loads(z.read("data"))["num_timesteps"])


def monitor_lines(run_dir: Path) -> list[str]:
    return (run_dir / "monitor" / "0.monitor.csv").read_text().splitlines()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    args = ["--shield", "none", "--total-steps", "256", "--eval-episodes", "6"]
    p = run("train.ppo", *args, *TINY, "--seed", "3", "--out", str(out), "--no-progress")
    assert p.returncode == 0, p.stderr
    (d,) = out.iterdir()
    assert "success rate" in p.stdout
    return d


def test_ppo_smoke_run_writes_model_config_eval_and_monitor(run_dir: Path) -> None:
    assert run_dir.name.startswith("IslandsBridges-v0__none__3__")
    assert (run_dir / "model.zip").is_file()
    assert num_timesteps(run_dir / "model.zip") == 256
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["shield"] == "none" and cfg["total_steps"] == 256 and cfg["pi"] == [64, 64]
    ev = json.loads((run_dir / "eval.json").read_text())
    assert 0.0 <= ev["success_rate"] <= 1.0
    assert ev["episodes"] == 6 and ev["deterministic"] and ev["num_timesteps"] == 256
    lines = monitor_lines(run_dir)
    assert lines[0].startswith("#") and lines[1] == "r,l,t,is_success"
    assert len(lines) > 2  # the untrained policy falls off islands within 128 steps
    assert (run_dir / "monitor" / "1.monitor.csv").is_file()
    assert cfg["normalize"] and stats_count(run_dir) == pytest.approx(2 + 256)


def stats_count(run_dir: Path) -> float:
    """Observations seen by the run's VecNormalize: n_envs (2) per reset of the VecEnv, at the start
    of each (resumed) run, plus one per env step (1e-4 initial count)."""
    with (run_dir / "vecnormalize.pkl").open("rb") as f:
        return float(pickle.load(f).obs_rms.count)


def test_ppo_resume_continues_the_run(run_dir: Path) -> None:
    before = monitor_lines(run_dir)
    p = run("train.ppo", "--resume", str(run_dir), "--total-steps", "128", "--eval-episodes", "4")
    assert p.returncode == 0, p.stderr
    assert num_timesteps(run_dir / "model.zip") == 256 + 128
    ev = json.loads((run_dir / "eval.json").read_text())
    assert ev["num_timesteps"] == 384 and ev["episodes"] == 4
    after = monitor_lines(run_dir)
    assert after[: len(before)] == before and len(after) > len(before)
    assert sum(line.startswith("r,l,t") for line in after) == 1  # appended, no second header
    assert len(list((run_dir.parent).iterdir())) == 1  # no new run directory
    # the normalisation statistics were reloaded and went on counting, not restarted
    assert stats_count(run_dir) == pytest.approx(2 + 256 + 2 + 128)


def test_islands_quick_writes_csv_png_and_table(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    args = ["--quick", "--steps", "256", "--eval-every", "128", "--eval-episodes", "3"]
    args += ["--final-episodes", "3", "--shields", "none", "smart", "--workers", "2"]
    p = run("train.islands", *args, *TINY[:4], "--out", str(out), "--no-progress")
    assert p.returncode == 0, p.stderr
    with (out / "islands.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == islands.COLUMNS
    # 2 shields x 2 rewards x 1 seed (quick) x evaluations at 0, 128, 256 steps
    assert len(rows) == 12
    assert {(r["shield"], r["reward"]) for r in rows} == {
        (s, r) for s in ("none", "smart") for r in ("dense", "sparse")
    }
    assert sorted({int(r["steps"]) for r in rows}) == [0, 128, 256]
    assert all(0.0 <= float(r["success_rate"]) <= 1.0 for r in rows)
    assert all(r["net"] == "small" and r["pi"] == "16x16" for r in rows)
    smart = [r for r in rows if r["shield"] == "smart"]
    assert all(float(r["failure_rate"]) == 0.0 for r in smart)  # the shield stays in place
    png = (out / "islands.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert "| smart | sparse | small |" in (out / "summary.md").read_text()
    assert "| none | dense | small |" in p.stdout


def test_build_envs_share_frozen_normalisation_and_lr_schedule() -> None:
    cfg = ppo.Config(n_envs=2, eval_episodes=3, lr_schedule="linear", learning_rate=1e-3)
    train_env, eval_env = ppo.build_envs(cfg, seed=5)
    assert train_env.training and not eval_env.training and not eval_env.norm_reward
    assert eval_env.obs_rms is train_env.obs_rms  # evaluation sees the current statistics
    train_env.reset()
    train_env.step(np.zeros((2, 2), dtype=np.float32))
    before = eval_env.obs_rms.count
    eval_env.reset()
    eval_env.step(np.zeros((2, 2), dtype=np.float32))
    assert eval_env.obs_rms.count == before  # evaluation does not update them
    model = ppo.build_model(cfg, train_env)
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)  # progress_remaining 1 -> 0
    assert model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    raw_train, raw_eval = ppo.build_envs(ppo.Config(n_envs=2, normalize=False), seed=5)
    assert not isinstance(raw_train, ppo.VecNormalize)
    assert ppo.build_model(ppo.Config(), raw_train).lr_schedule(0.25) == pytest.approx(3e-4)
    for env in (train_env, eval_env, raw_train, raw_eval):
        env.close()


def test_help_documents_every_option() -> None:
    text = ppo.build_parser().format_help()
    for f in ppo.dataclasses.fields(ppo.Config):
        assert "--" + f.name.replace("_", "-") in text
        assert f.metadata["help"].split()[0] in text


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--shield", "qp"], "invalid choice: 'qp'"),
        (["--reward", "shaped"], "invalid choice: 'shaped'"),
        (["--total-steps", "0"], "--total-steps must be >= 1"),
        (["--pi", "64", "0"], "--pi: sizes must be >= 1"),
        (["--resume", "/nonexistent/run"], "no model.zip there"),
    ],
)
def test_ppo_bad_options_exit_with_a_message(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        ppo.parse_config(argv)
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_islands_bad_options_exit_with_a_message(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, message in [
        (["--nets", "huge"], "unknown net 'huge'"),
        (["--shields", "magic"], "invalid choice: 'magic'"),
        (["--workers", "0"], "--workers must be >= 1"),
    ]:
        with pytest.raises(SystemExit) as e:
            islands.parse_config(argv)
        assert e.value.code == 2
        assert message in capsys.readouterr().err


def test_unknown_shield_subprocess_exits_2() -> None:
    p = run("train.ppo", "--shield", "magic", "--total-steps", "64")
    assert p.returncode == 2
    assert "invalid choice: 'magic'" in p.stderr
