"""``python -m train.heldout`` options: ``--ranges playground`` (MuJoCo Playground's LEAP cube
rotate-z evaluation: its draw of each episode's physics, reproducible from a seed) and
``--object`` (another object than the policy's own, named in the output files)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from envs.four_finger import PhysicsSample
from train.heldout import (
    PLAYGROUND,
    csv_path,
    evaluate_heldout,
    main,
    nominal_friction,
)
from train.policy import ROOT

CYLINDER = ROOT / "policies" / "four_finger_cylinder"  # nominal grip, trained on the cylinder


def test_playground_draw_honours_the_ranges_and_its_seed() -> None:
    """Each episode's physics comes from ``(seed, episode)`` alone: uniform within
    Playground's ranges (absolute friction 0.5-1.0 over the nominal 1.0, mass and each gain
    x0.8-1.2), torsional friction nominal, no latency, joint noise of Playground's spread
    (uniform +-0.05 rad: std 0.0289 rad), no contact noise."""
    draws = [PLAYGROUND.draw(7, g) for g in range(400)]
    fr = np.array([s.friction for s in draws])
    mass = np.array([s.mass for s in draws])
    gain = np.array([s.gain for s in draws])
    assert gain.shape == (400, 12)
    for x, (lo, hi) in ((fr, (0.5, 1.0)), (mass, (0.8, 1.2)), (gain, (0.8, 1.2))):
        assert lo <= x.min() and x.max() <= hi
        assert x.min() < lo + 0.05 * (hi - lo) and x.max() > hi - 0.05 * (hi - lo)  # spread
        assert np.mean(x) == pytest.approx((lo + hi) / 2, abs=0.03 * (hi - lo))  # uniform
    assert {(s.torsional, s.latency) for s in draws} == {(1.0, 0)}
    assert {s.noise for s in draws} == {(0.05 / math.sqrt(3), 0.0, 0.0)}
    assert PLAYGROUND.draw(7, 12) == draws[12]  # the same episode from the same seed
    assert PLAYGROUND.draw(8, 12) != draws[12] and draws[11] != draws[12]
    assert PLAYGROUND.draw(7, 12, nominal=0.5).friction == pytest.approx(2 * draws[12].friction)
    assert nominal_friction("capsule") == 1.0  # every object pair: the skin's 1.0


def test_episode_physics_does_not_depend_on_how_episodes_fall_to_envs() -> None:
    """With one physics per episode (test grasp ``g`` under ``physics[g]``, its sensor noise
    seeded by ``seed + g``) an episode is the same on one env as on three."""
    each = [PLAYGROUND.draw(0, g) for g in range(3)]
    each[1] = PhysicsSample(friction=0.5, mass=1.2, gain=0.8, noise=each[1].noise)

    def act(obs: np.ndarray) -> np.ndarray:  # reads the (noisy) joints
        return np.tanh(20.0 * obs[:, :12]).astype(np.float32)

    kw = {"object": "sphere"}
    one = evaluate_heldout(act, kw, 3, 0.5, physics=each, n_envs=1)
    three = evaluate_heldout(act, kw, 3, 0.5, physics=each, n_envs=3)
    assert one["grasps"] == [0, 1, 2]
    assert sorted(three["grasps"]) == [0, 1, 2]
    assert one["speed_rad_s"] == pytest.approx(three["speed_rad_s"], abs=1e-12)
    nominal = evaluate_heldout(act, kw, 3, 0.5, n_envs=1)
    assert nominal["speed_rad_s"] != pytest.approx(one["speed_rad_s"], abs=1e-6)
    with pytest.raises(ValueError, match="one per episode"):
        evaluate_heldout(act, kw, 2, 0.5, physics=each)


def test_object_option_names_the_output_files(tmp_path: Path) -> None:
    """``--object``: the policy runs on that object and every output file carries its name,
    so the policy's own files stay; the playground preset writes eval_playground_OBJECT.json."""
    assert csv_path(tmp_path, "robustness", 1.0, "capsule").name == "robustness_capsule.csv"
    assert csv_path(tmp_path, "factors", 0.25, "ellipsoid").name == "factors_x0.25_ellipsoid.csv"
    assert csv_path(tmp_path, "robustness", 0.5).name == "robustness_x0.5.csv"
    short = ["--episodes", "2", "--seconds", "0.5", "--object", "sphere", "--out", str(tmp_path)]
    res = main([str(CYLINDER), *short])["nominal"]
    assert res["episodes"] == 2 and res["grasps"] == [0, 1]
    pg = main([str(CYLINDER), *short, "--ranges", "playground"])["playground"]
    assert pg["episodes"] == 2 and pg["friction_scale"] == [0.5, 1.0]
    assert pg["physics"][1]["friction"] == pytest.approx(PLAYGROUND.draw(0, 1).friction)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["eval_heldout_sphere.json", "eval_playground_sphere.json"]
    saved = json.loads((tmp_path / "eval_playground_sphere.json").read_text())
    assert saved["playground"] == {"speed_rad_s": 0.94, "drop_rate": 0.023}
    assert saved["preset"]["episodes"] == 128 and saved["preset"]["seconds"] == 10.0
    for bad in (["--corners"], ["--range-scale", "0.5"], ["--object", "torus"]):
        with pytest.raises(SystemExit):
            main([str(CYLINDER), "--ranges", "playground", *bad])


def test_centre_of_the_ranges() -> None:
    """``--centre``: each scale at its range's middle (the mass's geometric middle, where its
    log-uniform draw is centred), with latency and the noise."""
    from envs.four_finger import Randomization, centre

    c = centre(Randomization())
    assert (c.friction, c.torsional, c.mass, c.gain, c.latency) == (1.0, 1.0, 1.0, 1.0, 1)
    r = Randomization(friction=(0.5, 1.0), mass=(0.8, 1.2), latency_prob=0.0)
    c = centre(r)
    assert c.friction == 0.75 and c.mass == pytest.approx((0.8 * 1.2) ** 0.5) and c.latency == 0
    assert c.noise == (r.noise_joint, r.noise_pos, r.noise_force)
