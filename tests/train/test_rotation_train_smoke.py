"""Training on the four-finger rotation env: subprocess smoke runs of the main job
``python -m train.ppo`` (plain, with the QP shield), its ``--timestep`` option, and the gait
period of train.gait (moved from tests/envs/test_four_finger_env.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs.four_finger import FRAME_SKIP, TIMESTEP

ROOT = Path(__file__).resolve().parents[2]


def _train_ppo(*args: str) -> subprocess.CompletedProcess:
    """``python -m train.ppo *args`` in a subprocess from the checkout (5 min limit)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, "-m", "train.ppo", *args],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip


def test_train_ppo_main_job_smoke_and_resume(tmp_path) -> None:
    """``python -m train.ppo`` (no task: the rotation main job) with a tiny budget writes the
    model, normalisation, evaluation, curve; --resume adds steps."""
    tiny = [
        "--total-steps", "256", "--n-envs", "2", "--n-steps", "64", "--batch-size", "64",
        "--n-epochs", "1", "--pi", "32", "32", "--vf", "32", "32", "--eval-episodes", "2",
        "--eval-seconds", "1", "--checkpoint-every", "128", "--no-progress",
    ]  # fmt: skip
    p = _train_ppo(*tiny, "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr[-2000:]
    (run_dir,) = list(tmp_path.iterdir())
    for f in ("model.zip", "vecnormalize.pkl", "eval.json", "eval.csv", "curve.png"):
        assert (run_dir / f).is_file(), f
    res = json.loads((run_dir / "eval.json").read_text())
    assert res["num_timesteps"] == 256 and res["episodes"] == 2
    assert 0.0 <= res["drop_rate"] <= 1.0 and np.isfinite(res["speed_rad_s"])
    assert "rad/s" in p.stdout
    q = _train_ppo("--resume", str(run_dir), "--total-steps", "128", "--no-progress")
    assert q.returncode == 0, q.stderr[-2000:]
    assert json.loads((run_dir / "eval.json").read_text())["num_timesteps"] == 384


def test_train_ppo_with_the_qp_shield_smoke(tmp_path) -> None:
    """``python -m train.ppo --shield qp``: the envs (training and evaluation) run inside
    ``shields.GraspShield``; the run records it."""
    tiny = [
        "--shield", "qp", "--total-steps", "128", "--n-envs", "2", "--n-steps", "64",
        "--batch-size", "64", "--n-epochs", "1", "--pi", "32", "32", "--vf", "32", "32",
        "--eval-episodes", "2", "--eval-seconds", "1", "--workers", "0", "--no-progress",
    ]  # fmt: skip
    p = _train_ppo(*tiny, "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr[-2000:]
    (run_dir,) = list(tmp_path.iterdir())
    assert "__qp__" in run_dir.name
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["shield"] == "qp" and cfg["shield_backend"] == "daqp"
    res = json.loads((run_dir / "eval.json").read_text())
    assert res["num_timesteps"] == 128 and 0.0 <= res["intervention_rate"] <= 1.0


def test_train_timestep_option_keeps_the_policy_period() -> None:
    """``python -m train.ppo --timestep``: the env runs 0.05 s / timestep substeps (a 20 Hz
    policy either way), and a timestep that does not divide 0.05 s is refused."""
    from train.rotation import env_physics, make_env, parse_config

    cfg = parse_config(["--timestep", "0.0025"])
    env = make_env(cfg)()
    assert env.unwrapped.model.opt.timestep == 0.0025 and env.unwrapped.frame_skip == 20
    assert env.unwrapped.dt == pytest.approx(0.05)
    assert env_physics(TIMESTEP) == {"timestep": TIMESTEP, "frame_skip": FRAME_SKIP}
    with pytest.raises(SystemExit):
        parse_config(["--timestep", "0.003"])
    with pytest.raises(ValueError, match="divide"):
        env_physics(0.0)
    # a run's physics travels with its policy (config.json); runs before the option: 2 ms
    from train.policy import SHIPPED, load_policy

    for name, physics in (
        ("four_finger_sphere", (0.002, 25)),
        ("four_finger_sphere_2.5ms", (0.0025, 20)),
    ):
        kw = load_policy(SHIPPED.parent / name)[1]
        assert (kw["timestep"], kw["frame_skip"]) == physics


def test_gait_period_of_a_periodic_signal() -> None:
    from train.gait import gait_period

    t = np.arange(400)
    ctrl = np.stack([np.sin(2 * np.pi * t / 23 + k) for k in range(12)], axis=1)
    assert gait_period(ctrl) == 23


@pytest.mark.parametrize("obj", ["sphere", "cylinder", "cube"])
def test_train_ppo_smoke_per_object_with_randomised_physics(tmp_path, obj) -> None:
    """A few thousand steps per object, with the default's randomised physics: the documented
    files, the object and the randomisation recorded in config.json, and the final
    evaluation's held-out speed measure (net turn) beside the summed one."""
    tiny = [
        "--object", obj, "--total-steps", "2048", "--n-envs", "4", "--n-steps", "256",
        "--batch-size", "256", "--n-epochs", "1", "--pi", "32", "32", "--vf", "32", "32",
        "--eval-episodes", "2", "--eval-seconds", "2", "--workers", "0", "--no-progress",
    ]  # fmt: skip
    p = _train_ppo(*tiny, "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr[-2000:]
    (run_dir,) = list(tmp_path.iterdir())
    assert run_dir.name.startswith(f"FourFingerRotate-{obj}__")
    for f in ("model.zip", "vecnormalize.pkl", "config.json", "eval.json", "eval.csv", "curve.png"):
        assert (run_dir / f).is_file(), f
    assert len(list((run_dir / "monitor").glob("*.monitor.csv"))) == 4
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["object"] == obj
    res = json.loads((run_dir / "eval.json").read_text())
    assert res["num_timesteps"] == 2048 and res["episodes"] == 2
    assert np.isfinite(res["speed_rad_s"]) and np.isfinite(res["summed_rad_s"])
