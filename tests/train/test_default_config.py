"""The main job's defaults are what the README says: the table under "Set-up: two commands"
is compared with the config and the env that ``python -m train.ppo`` builds (issue 29)."""

from __future__ import annotations

import math
from pathlib import Path

from train.options import get_option
from train.rotation import POLICY_DT, THESIS, make_env, parse_config

ROOT = Path(__file__).resolve().parents[2]


def _nets(sizes: list[int]) -> str:
    return f"{len(sizes)} x {sizes[0]}" if len(set(sizes)) == 1 else " - ".join(map(str, sizes))


def test_readme_states_the_default_configuration() -> None:
    cfg = parse_config([])
    env = make_env(cfg)()
    u = env.unwrapped
    r = u.reward
    steps = env.spec.max_episode_steps
    assert steps == cfg.episode_steps
    cap = "uncapped" if math.isinf(r.rotation_cap) else f"capped at {r.rotation_cap:g} rad/s"
    physics = "randomised" if u.randomize is not None else "nominal"
    if u.starts.replay_prob == 0 and u.starts.turned_prob == 0:
        physics += "; start grasps uniform over the cache (no replay, no turned starts)"
    lr = f"{cfg.learning_rate:g}" + (", linear decay to 0" if cfg.lr_schedule == "linear" else "")
    rows = [
        f"| object | `{u.object}`, gravity {'on' if u.sim.gravity else 'off'} |",
        f"| training episode | {steps} steps ({steps * POLICY_DT:g} s) |",
        f"| reward | rotation about +z [rad/s], {cap}; height term weight {r.height_weight:g}; "
        f"drop penalty {r.drop_weight:g}; slip penalty {r.slip_weight:g}; "
        f"tilt penalty {r.tilt_weight:g} |",
        f"| physics | {physics} |",
        f"| budget | {cfg.total_steps:,} env steps |",
        f"| nets | policy {_nets(cfg.pi)}, value {_nets(cfg.vf)} |",
        f"| learning rate | {lr} |",
        f"| validation | every {cfg.checkpoint_every // 1000}k steps, "
        f"{cfg.eval_episodes} x {cfg.eval_seconds:g} s |",
        f"| policy kept | {'best validated checkpoint' if cfg.keep_best else 'final'} |",
    ]
    readme = (ROOT / "README.md").read_text()
    missing = [r for r in rows if r not in readme]
    assert not missing, "README's default table differs from the code: " + "; ".join(missing)


def test_thesis_option_restores_the_thesis_setup() -> None:
    cfg = parse_config(["--thesis"])
    for k, v in THESIS.items():
        assert get_option(cfg, k) == v
    assert cfg.thesis and parse_config(["--thesis", "--episode-steps", "100"]).episode_steps == 100
    env = make_env(cfg)()
    assert env.spec.max_episode_steps == 64 and math.isinf(env.unwrapped.reward.rotation_cap)
    assert env.unwrapped.randomize is None and env.unwrapped.reward.drop_weight == 0.0


def test_height_from_reaches_the_training_env() -> None:
    """``--height-from start`` reaches the env the run trains on; the default keeps the
    fixed reference (``HOLD_Z``) that the README's height term means."""
    assert make_env(parse_config([]))().unwrapped.reward.height_from == "hold"
    env = make_env(parse_config(["--height-from", "start"]))().unwrapped
    assert env.reward.height_from == "start"


def test_tilt_weight_reaches_the_training_env() -> None:
    assert make_env(parse_config([]))().unwrapped.reward.tilt_weight == 0.0
    assert make_env(parse_config(["--tilt-weight", "2"]))().unwrapped.reward.tilt_weight == 2.0
