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


@pytest.mark.slow
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
    assert "rad/s" in p.stdout and "validation on training start grasps" in p.stdout
    assert f"python -m train.heldout {run_dir}" in p.stdout
    q = _train_ppo("--resume", str(run_dir), "--total-steps", "128", "--no-progress")
    assert q.returncode == 0, q.stderr[-2000:]
    assert json.loads((run_dir / "eval.json").read_text())["num_timesteps"] == 384


@pytest.mark.slow
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
    assert cfg["task"] == "rotation" and cfg["sim"]["frame_skip"] == 25
    res = json.loads((run_dir / "eval.json").read_text())
    assert res["num_timesteps"] == 128 and 0.0 <= res["intervention_rate"] <= 1.0


def test_train_timestep_option_keeps_the_policy_period() -> None:
    """``python -m train.ppo --timestep``: the env runs 0.05 s / timestep substeps (a 20 Hz
    policy either way), and a timestep that does not divide 0.05 s is refused."""
    from train.rotation import env_physics, parse_config

    cfg = parse_config(["--timestep", "0.0025"])
    # the env takes cfg.sim as it is (test_trainer.py); its 2.5 ms start cache is not built here
    assert cfg.sim.timestep == 0.0025 and cfg.sim.frame_skip == 20
    assert cfg.sim.timestep * cfg.sim.frame_skip == pytest.approx(0.05)
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
        sim = load_policy(SHIPPED.parent / name)[1]["sim"]
        assert (sim.timestep, sim.frame_skip) == physics


def test_gait_period_of_a_periodic_signal() -> None:
    from train.gait import gait_period

    t = np.arange(400)
    ctrl = np.stack([np.sin(2 * np.pi * t / 23 + k) for k in range(12)], axis=1)
    assert gait_period(ctrl) == 23


@pytest.mark.slow
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


@pytest.mark.slow
def test_finetune_validates_at_the_corners_and_init_from_transfers(tmp_path) -> None:
    """``--resume RUN --randomize --corner-prob P --hard-prob Q --validate-corners N --grip
    firm``: config.json records the fine-tune (the training envs draw the hard region with
    probability Q; a sum of P and Q above 1 is refused; the policy loads with the firm start
    grasps), eval.csv gains the pooled corner figures (16 corners x N episodes), the earlier
    ``best/`` moves aside (``best_nominal/``) and the new ``best/`` is ranked on the worse of
    nominal and corners. ``--init-from RUN --object cube`` starts a new run from the run's weights
    (equal before training); nets that do not match are refused by name."""
    import torch
    from stable_baselines3 import PPO

    tiny = [
        "--total-steps", "128", "--n-envs", "2", "--n-steps", "64", "--batch-size", "64",
        "--n-epochs", "1", "--pi", "32", "32", "--vf", "32", "32", "--eval-episodes", "2",
        "--eval-seconds", "1", "--checkpoint-every", "128", "--no-progress", "--workers", "0",
    ]  # fmt: skip
    p = _train_ppo(*tiny, "--out", str(tmp_path / "a"))
    assert p.returncode == 0, p.stderr[-2000:]
    (run_dir,) = list((tmp_path / "a").iterdir())
    assert (run_dir / "best" / "model.zip").is_file()
    q = _train_ppo(
        "--resume", str(run_dir), "--randomize", "--corner-prob", "0.5", "--validate-corners",
        "1", "--total-steps", "128", "--no-progress", "--workers", "0", "--grip", "firm",
        "--hard-prob", "0.25",
    )  # fmt: skip
    assert q.returncode == 0, q.stderr[-2000:]
    saved = json.loads((run_dir / "config.json").read_text())
    assert saved["task"] == "rotation"  # config.json: the task, the env's settings in groups
    rnd = saved["randomization"]
    assert rnd["randomize"] and rnd["corner_prob"] == 0.5 and saved["validate_corners"] == 1
    from train.options import from_options, from_saved
    from train.rotation import RotateConfig, parse_config, training_randomization

    cfg = from_saved(RotateConfig, saved)
    assert cfg.randomization.hard_prob == 0.25 and cfg.starts.grip == "firm"
    r = training_randomization(from_options(RotateConfig, {"randomize": True, "hard_prob": 0.25}))
    assert r is not None and (r.corner_prob, r.hard_prob) == (0.0, 0.25)
    with pytest.raises(SystemExit):
        parse_config(["--corner-prob", "0.6", "--hard-prob", "0.5"])
    late = training_randomization(parse_config(["--randomize", "--latency-prob", "1"]))
    assert late is not None and late.latency_prob == 1.0
    rng = np.random.default_rng(0)
    assert all(late.sample(rng, 12).latency == 1 for _ in range(50))
    assert training_randomization(parse_config(["--randomize"])).latency_prob == 0.5
    with pytest.raises(SystemExit):
        parse_config(["--latency-prob", "1.5"])
    half = training_randomization(parse_config(["--randomize", "--range-scale", "0.5"]))
    assert half is not None and half.friction == (0.75, 1.25) and half.gain == (0.9, 1.1)
    for bad in ("0", "1.5"):
        with pytest.raises(SystemExit):
            parse_config(["--randomize", "--range-scale", bad])
    from train.policy import load_policy

    assert saved["starts"]["grip"] == "firm" and load_policy(run_dir)[1]["starts"].grip == "firm"
    assert saved["finetune_from_step"] == 128
    rows = (run_dir / "eval.csv").read_text().splitlines()
    assert "corner_drop_rate" in rows[0] and rows[-1].split(",")[-1] == "16"
    best = json.loads((run_dir / "best" / "eval.json").read_text())
    assert best["corner_episodes"] == 16  # the nominal run's best/ moved aside:
    assert (run_dir / "best_nominal" / "model.zip").is_file()
    worse = best["ranked_on"]
    assert worse["drop_rate"] == max(best["drop_rate"], best["corner_drop_rate"])
    assert worse["speed_rad_s"] == min(best["speed_rad_s"], best["corner_speed_rad_s"])

    from envs.four_finger import ObservationSettings
    from train.rotation import RotateConfig, build_model, make_env
    from train.runfiles import init_weights
    from train.vec import make_vec_env

    cfg_c = RotateConfig(object="cube", pi=[32, 32], vf=[32, 32], n_steps=64, batch_size=64)
    vec = make_vec_env([make_env(cfg_c)], 0)
    model = build_model(cfg_c, vec)
    init_weights(model, run_dir)
    src = PPO.load(run_dir / "best" / "model.zip", device="cpu").policy.state_dict()
    for k, v in model.policy.state_dict().items():
        assert torch.equal(v, src[k]), k
    with pytest.raises(ValueError, match="do not match"):
        init_weights(build_model(RotateConfig(pi=[16], vf=[16], n_steps=64), vec), run_dir)
    vec.close()

    # --history 3 from a one-frame source: the widened nets compute what the source computes
    # from the newest frame, and the observation statistics are tiled over the frames
    from train.runfiles import init_normalizer

    three = ObservationSettings(history=3)
    cfg_h = RotateConfig(observation=three, pi=[32, 32], vf=[32, 32], n_steps=64, batch_size=64)
    vec_h = init_normalizer(make_vec_env([make_env(cfg_h)], 0), run_dir)
    model_h = build_model(cfg_h, vec_h)
    init_weights(model_h, run_dir)
    src_pol = PPO.load(run_dir / "best" / "model.zip", device="cpu").policy
    x = torch.as_tensor(np.random.default_rng(0).normal(size=(5, 3 * 56)), dtype=torch.float32)
    with torch.no_grad():
        a_h, v_h, _ = model_h.policy.forward(x, deterministic=True)
        a_1, v_1, _ = src_pol.forward(x[:, 2 * 56 :], deterministic=True)
    torch.testing.assert_close(a_h, a_1)
    torch.testing.assert_close(v_h, v_1)
    n = vec_h.obs_rms.mean.shape[0] // 3
    np.testing.assert_array_equal(vec_h.obs_rms.mean[:n], vec_h.obs_rms.mean[2 * n :])
    assert n == 56
    vec_h.close()
    r = _train_ppo(
        *tiny, "--object", "cube", "--init-from", str(run_dir), "--out", str(tmp_path / "c")
    )
    assert r.returncode == 0, r.stderr[-2000:]
    (cube,) = list((tmp_path / "c").iterdir())
    assert json.loads((cube / "config.json").read_text())["init_from"] == str(run_dir)


def test_finetune_moves_best_aside_when_the_validated_ranges_change(tmp_path) -> None:
    """``start_finetune``: a ``best/`` chosen at one range's corners moves to
    ``best_previous/`` when ``--range-scale`` changes (its figures are of other corners), and
    stays when the fine-tune keeps the range (here: only ``--hard-prob`` changes). The
    options are recorded in the layout config.json has: by name at the top of a flat file
    (from before the groups), in their groups in a nested one."""
    import json

    from train.options import from_saved, set_options, to_json
    from train.rotation import RotateConfig
    from train.runfiles import start_finetune

    old = {"validate_corners": 2, "range_scale": 0.5}
    new = set_options(RotateConfig(), old)
    for layout, text in (("flat", json.dumps(old)), ("nested", to_json(new, task="rotation"))):
        run = tmp_path / layout
        (run / "best").mkdir(parents=True)
        (run / "best" / "eval.json").write_text("{}")
        (run / "config.json").write_text(text)
        cfg = from_saved(RotateConfig, json.loads(text))
        cfg = set_options(cfg, {"hard_prob": 0.5})
        start_finetune(cfg, run, ["hard_prob"], 100)
        assert (run / "best").is_dir() and not (run / "best_previous").exists()
        start_finetune(set_options(cfg, {"range_scale": 1.0}), run, ["range_scale"], 200)
        assert not (run / "best").exists() and (run / "best_previous" / "eval.json").is_file()
        saved = json.loads((run / "config.json").read_text())
        rnd = saved if layout == "flat" else saved["randomization"]
        assert rnd["range_scale"] == 1.0 and rnd["hard_prob"] == 0.5
        assert saved["finetune_from_step"] == 200
        assert ("range_scale" in saved) == (layout == "flat")
        back = from_saved(RotateConfig, saved).randomization
        assert (back.range_scale, back.hard_prob) == (1.0, 0.5)
