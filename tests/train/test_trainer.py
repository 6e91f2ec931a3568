"""The one trainer (train.trainer) and the configs it runs (train.options): the run directory
records its task, ``--resume`` picks it back, config.json keeps the env's settings in their
groups, and the flat config.json of the committed policies and older runs still reads."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from envs.four_finger import ObservationSettings, RewardSettings, SimSettings, StartSettings
from train import islands_ppo, rotation
from train.options import (
    build_parser,
    flat,
    from_options,
    from_saved,
    get_option,
    options,
    record_options,
    saved_value,
    set_options,
    to_json,
)
from train.policy import ROOT, load_policy
from train.ppo import TASKS
from train.rotation import RotateConfig, make_env
from train.trainer import run_task, train

POLICIES = sorted(p for p in (ROOT / "policies").iterdir() if (p / "config.json").is_file())
FLAT = [p for p in POLICIES if "task" not in json.loads((p / "config.json").read_text())]
"""The policies committed before config.json had groups (every one but the generalist)."""


def test_tasks_are_registered_by_the_name_their_runs_record() -> None:
    assert TASKS == {"rotation": rotation.TASK, "islands": islands_ppo.TASK}


def test_run_task_reads_the_record_and_falls_back_for_older_runs(tmp_path: Path) -> None:
    for name, saved in (
        ("rotation", {"task": "rotation", "object": "cube"}),
        ("islands", {"task": "islands", "env_id": "ihm/IslandsBridges-v0"}),
        ("rotation", {"object": "sphere", "seed": 1}),  # before the record: names an object
        ("islands", {"env_id": "ihm/IslandsBridges-v0", "seed": 1}),
    ):
        (tmp_path / "config.json").write_text(json.dumps(saved))
        assert run_task(tmp_path) == name


def test_resume_refuses_a_run_of_another_task(tmp_path: Path) -> None:
    (tmp_path / "config.json").write_text(json.dumps({"task": "rotation", "object": "sphere"}))
    (tmp_path / "model.zip").write_bytes(b"")
    with pytest.raises(SystemExit, match="a rotation run, not a islands run"):
        train(islands_ppo.TASK, ["--resume", str(tmp_path)])


def test_options_are_the_old_flat_names_and_build_the_groups() -> None:
    names = [o.name for o in options(RotateConfig)]
    assert len(names) == len(set(names)) == len(build_parser(RotateConfig)._actions) - 1
    for name in ("gravity", "timestep", "drop_weight", "randomize", "grip", "privileged_critic"):
        assert name in names
    cfg = from_options(
        RotateConfig,
        {"timestep": 0.0025, "drop_weight": 0.5, "grip": "firm", "privileged_critic": True},
    )
    assert cfg.sim == SimSettings(timestep=0.0025, frame_skip=20)  # the policy period kept
    assert cfg.reward == RewardSettings(rotation_cap=1.0, height_weight=1.0, drop_weight=0.5)
    assert cfg.starts == StartSettings(grip="firm")
    assert cfg.observation == ObservationSettings(privileged=True)
    assert get_option(cfg, "privileged_critic") is True
    assert from_options(RotateConfig, flat(cfg)) == cfg
    # the groups reach the env as they are (the default sim and starts: the shared cache)
    cfg = from_options(RotateConfig, {"drop_weight": 0.5, "privileged_critic": True})
    env = make_env(cfg)().unwrapped
    assert (env.reward, env.sim, env.observation) == (cfg.reward, cfg.sim, cfg.observation)
    assert env.reward.drop_weight == 0.5 and env.observation.privileged
    env.close()


def test_config_json_keeps_the_groups_and_reads_back(tmp_path: Path) -> None:
    cfg = set_options(RotateConfig(), {"randomize": True, "range_scale": 0.5, "history": 3})
    saved = json.loads(to_json(cfg, task="rotation"))
    assert next(iter(saved)) == "task" and saved["task"] == "rotation"
    assert saved["randomization"]["range_scale"] == 0.5 and saved["observation"]["history"] == 3
    assert saved["sim"]["frame_skip"] == 25 and "drop_weight" not in saved
    assert from_saved(RotateConfig, saved) == cfg
    assert saved_value(saved, "range_scale") == saved_value(saved, "randomization.range_scale")
    path = tmp_path / "config.json"
    path.write_text(to_json(cfg, task="rotation"))
    record_options(path, set_options(cfg, {"hard_prob": 0.25}), ["hard_prob"], mark=7)
    again = json.loads(path.read_text())
    assert again["randomization"]["hard_prob"] == 0.25 and again["mark"] == 7
    isl = islands_ppo.Config(shield="smart", n_envs=3)
    assert from_saved(islands_ppo.Config, json.loads(to_json(isl, task="islands"))) == isl


@pytest.mark.parametrize("policy", FLAT, ids=[p.name for p in FLAT])
def test_committed_flat_configs_read_as_before(policy: Path) -> None:
    """The committed policies' config.json (flat, unchanged) convert on load: every option
    the file names keeps its value; the policy's env is its object, physics, observation and
    grip."""
    saved = json.loads((policy / "config.json").read_text())
    assert "task" not in saved and not any(isinstance(v, dict) for v in saved.values())
    cfg = from_saved(RotateConfig, saved)
    values = flat(cfg)
    assert {k: v for k, v in saved.items() if k in values and k != "resume"} == {
        k: values[k] for k in saved if k in values and k != "resume"
    }
    kw = load_policy(policy)[1]
    assert kw["object"] == saved["object"] and kw["sim"].timestep == saved.get("timestep", 0.002)
    assert kw["sim"].frame_skip * kw["sim"].timestep == pytest.approx(0.05)
    assert kw["starts"] == StartSettings(grip=saved.get("grip", "nominal"))
    assert kw["observation"].history == saved.get("history", 1)
