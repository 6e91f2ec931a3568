"""``python -m train.ppo islands`` and ``python -m train.islands``: smoke runs, resume, bad options.

Tiny budgets (a few hundred steps) so the file stays well under a minute; the
real benchmark is ``python -m train.islands`` (see README).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecNormalize

from train import islands, islands_ppo, sb3
from train.seeding import RunSeeds
from train.stats import wilson_interval

ROOT = Path(__file__).resolve().parents[2]
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
    p = run("train.ppo", "islands", *args, *TINY, "--seed", "3", "--out", str(out), "--no-progress")
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
    assert cfg["task"] == "islands"  # what --resume reads (train.trainer.run_task)
    ev = json.loads((run_dir / "eval.json").read_text())
    assert 0.0 <= ev["success_rate"] <= 1.0 and ev["stream"] == "validation"
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


@pytest.mark.slow
def test_islands_quick_writes_csv_png_and_table(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    # 200 steps: not a rollout boundary (2 envs x 64 steps), so the budget stop is exercised
    args = ["--quick", "--steps", "200", "--window", "128", "--final-window", "72"]
    args += ["--eval-every", "128", "--eval-episodes", "3", "--final-episodes", "5"]
    args += ["--eval-envs", "2", "--shields", "none", "smart", "--workers", "2"]
    args += ["--study-nets", "medium", "--study-envs", "ihm/IslandsBridges-v0"]
    p = run("train.islands", *args, *TINY[:4], "--out", str(out), "--no-progress")
    assert p.returncode == 0, p.stderr
    with (out / "islands.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == islands.COLUMNS
    assert {r["measure"] for r in rows} == set(islands.MEASURES)
    # grid: 2 maps x 2 shields x 2 rewards x 1 seed (quick) with 2x16 nets, plus the study
    # (2x64, smart, sparse, v0 map)
    configs = {(r["env_id"], r["shield"], r["reward"], r["net"]) for r in rows}
    assert len(configs) == 2 * 2 * 2 + 1
    assert ("ihm/IslandsBridges-v0", "smart", "sparse", "medium") in configs
    assert {r["map"] for r in rows} == {"dead-end", "ring"}
    for config in configs:
        mine = [r for r in rows if (r["env_id"], r["shield"], r["reward"], r["net"]) == config]
        by = {m: [r for r in mine if r["measure"] == m] for m in islands.MEASURES}
        assert [int(r["steps"]) for r in by["train_stochastic"]] == [128, 200]
        assert [int(r["steps"]) for r in by["eval_deterministic"]] == [128]
        for m in ("final_stochastic", "final_deterministic", "final_deterministic_noshield"):
            (row,) = by[m]
            assert int(row["episodes"]) == 5 and int(row["steps"]) == 200
        # the last-window training measure is the last window's counts ((128, 200] both)
        (fin,) = by["train_stochastic_final"]
        assert fin["episodes"] == by["train_stochastic"][-1]["episodes"]
    for r in rows:
        n, k = int(r["episodes"]), int(r["successes"])
        if n:
            assert float(r["success_rate"]) == pytest.approx(k / n)
            lo, hi = wilson_interval(k, n)
            assert float(r["ci_low"]) == pytest.approx(lo) and float(r["ci_high"]) == pytest.approx(
                hi
            )
            assert float(r["ci_low"]) <= k / n <= float(r["ci_high"])
    smart_final = [r for r in rows if r["shield"] == "smart" and r["measure"].startswith("final_")]
    # the shield stays in place: no held-out failure with it
    assert all(int(r["failures"]) == 0 for r in smart_final if "noshield" not in r["measure"])
    for name in ("islands.png", "islands_nets.png"):
        png = (out / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    summary = (out / "summary.md").read_text()
    assert (
        "| ring | smart | sparse | 16x16 |" in summary
        and "| dead-end | none | dense | 16x16 |" in p.stdout
    )
    # re-summarising from the CSV gives the same table
    assert islands.summary_table(islands.read_csv(out / "islands.csv")) == summary.split("\n\n")[0]


def test_build_envs_and_frozen_normalisation_and_lr_schedule() -> None:
    cfg = islands_ppo.Config(n_envs=2, eval_episodes=3, lr_schedule="linear", learning_rate=1e-3)
    train_env = islands_ppo.build_envs(cfg, RunSeeds(5))
    assert train_env.training and train_env.num_envs == 2
    train_env.reset()
    train_env.step(np.zeros((2, 2), dtype=np.float32))
    norm = sb3.normalizer(train_env)
    before = train_env.obs_rms.count
    x = np.array([[0.4, 0.4, 1.6, 1.55]], dtype=np.float32)
    y = norm(x)
    assert train_env.obs_rms.count == before  # evaluation does not update the statistics
    np.testing.assert_allclose(
        y, np.clip((x - train_env.obs_rms.mean) / np.sqrt(train_env.obs_rms.var + 1e-8), -10, 10)
    )
    model = islands_ppo.build_model(cfg, train_env)
    assert model.seed is None  # SB3 would re-seed the envs with seed + i
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)  # progress_remaining 1 -> 0
    assert model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    raw_train = islands_ppo.build_envs(islands_ppo.Config(n_envs=2, normalize=False), RunSeeds(5))
    assert not isinstance(raw_train, VecNormalize) and sb3.normalizer(raw_train) is None
    raw_model = islands_ppo.build_model(islands_ppo.Config(), raw_train)
    assert raw_model.lr_schedule(0.25) == pytest.approx(3e-4)
    for env in (train_env, raw_train):
        env.close()


def test_same_seed_same_initial_policy_and_rollout() -> None:
    """Two builds from one run seed give the same weights and the same first rollout."""
    cfg = islands_ppo.Config(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, normalize=False)
    outs = []
    for seed in (3, 3, 4):
        seeds = RunSeeds(seed)
        sb3.seed_everything(seeds.global_seed)
        env = islands_ppo.build_envs(cfg, seeds)
        model = islands_ppo.build_model(cfg, env)
        w = np.concatenate([p.detach().numpy().ravel() for p in model.policy.parameters()])
        model.learn(64)  # one rollout of 2 x 32 steps
        # after training the buffer is flattened env-major: (n_envs * n_steps, obs_dim)
        obs = model.rollout_buffer.observations.reshape(2, 32, 4).copy()
        outs.append((w, obs))
        env.close()
        # SB3 trained on our streams: env i's first episode is the second draw (after the
        # seeding reset in make_env) of an env built from RunSeeds(seed).env("train", i)
        for i in range(2):
            ref = islands_ppo.make_env(cfg, seeds.env("train", i))()
            np.testing.assert_array_equal(obs[i, 0], ref.reset()[0])
    np.testing.assert_array_equal(outs[0][0], outs[1][0])
    np.testing.assert_array_equal(outs[0][1], outs[1][1])
    assert not np.array_equal(outs[0][0], outs[2][0])


def test_help_documents_every_option() -> None:
    text = sb3.build_parser(islands_ppo.Config).format_help()
    for f in dataclasses.fields(islands_ppo.Config):
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
        islands_ppo.parse_config(argv)
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_islands_bad_options_exit_with_a_message(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, message in [
        (["--net", "huge"], "unknown net 'huge'"),
        (["--study-nets", "tiny"], "unknown net 'tiny'"),
        (["--env-ids", "ihm/Nowhere-v0"], "unknown env id 'ihm/Nowhere-v0'"),
        (["--study-rewards", "shaped"], "unknown reward 'shaped'"),
        (["--eval-every", "-1"], "--eval-every must be >= 0"),
        (["--shields", "magic"], "invalid choice: 'magic'"),
        (["--workers", "0"], "--workers must be >= 1"),
    ]:
        with pytest.raises(SystemExit) as e:
            islands.parse_config(argv)
        assert e.value.code == 2
        assert message in capsys.readouterr().err


def test_unknown_shield_subprocess_exits_2() -> None:
    p = run("train.ppo", "islands", "--shield", "magic", "--total-steps", "64")
    assert p.returncode == 2
    assert "invalid choice: 'magic'" in p.stderr
