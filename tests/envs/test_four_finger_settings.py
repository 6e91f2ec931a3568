"""The four-finger env's settings groups (envs.four_finger.settings): the env keeps the groups
it is given, fields given by name are set on top of them, each group checks its values."""

from __future__ import annotations

import dataclasses
import math

import pytest

from envs.four_finger import (
    FourFingerError,
    FourFingerRotate,
    ObservationSettings,
    RenderSettings,
    RewardSettings,
    SimSettings,
    StartSettings,
    apply_overrides,
)


def test_the_env_keeps_its_groups_and_overrides_go_on_top() -> None:
    reward = RewardSettings(rotation_cap=1.0, height_weight=1.0)
    env = FourFingerRotate(reward=reward, drop_weight=2.0, history=2, grasps="test", n_grasps=4)
    assert env.reward == dataclasses.replace(reward, drop_weight=2.0)
    assert env.observation == ObservationSettings(history=2)
    assert env.starts == StartSettings(grasps="test", n_grasps=4)
    assert env.sim == SimSettings() and env.render_settings == RenderSettings()
    assert (env.frame_skip, env.max_setpoint_step, env.dt) == (25, 0.05, pytest.approx(0.05))
    assert env.observation_space.shape == (112,)
    plain = FourFingerRotate(reward=reward, grasps="test", n_grasps=4)
    assert plain.reward is reward  # a group given whole is the env's own
    env.close()
    plain.close()


def test_overrides_name_fields_of_one_group_each() -> None:
    groups = {"reward": RewardSettings(), "sim": SimSettings(), "render": RenderSettings()}
    out = apply_overrides(groups, {"gravity": False, "width": 64, "tilt_weight": 1})
    assert out["sim"] == SimSettings(gravity=False) and out["render"].width == 64
    assert out["reward"].tilt_weight == 1.0 and isinstance(out["reward"].tilt_weight, float)
    with pytest.raises(TypeError, match="'gravty'"):
        apply_overrides(groups, {"gravty": False})
    with pytest.raises(TypeError, match="unexpected keyword"):
        FourFingerRotate(gravty=False)
    names = [f.name for g in groups.values() for f in dataclasses.fields(g)]
    names += [f.name for f in dataclasses.fields(StartSettings)]
    names += [f.name for f in dataclasses.fields(ObservationSettings)]
    assert len(names) == len(set(names))  # an override finds one group


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: RewardSettings(rotation_cap=math.nan), "rotation_cap"),
        (lambda: RewardSettings(slip_weight=-1.0), "slip_weight"),
        (lambda: RewardSettings(height_from="palm"), "height_from"),
        (lambda: SimSettings(timestep=0.0), "timestep must be > 0"),
        (lambda: SimSettings(frame_skip=0), "frame_skip"),
        (lambda: SimSettings(solver="magic"), "unknown solver"),
        (lambda: StartSettings(grip="tight"), "grip must be one of"),
        (lambda: StartSettings(n_grasps=0), "n_grasps"),
        (lambda: StartSettings(turned_prob=0.5).for_object("sphere"), "for the cube"),
        (lambda: ObservationSettings(history=0), "history"),
        (lambda: RenderSettings(camera="front"), "camera"),
    ],
)
def test_groups_check_their_values(make, message: str) -> None:
    with pytest.raises(FourFingerError, match=message):
        make()


def test_groups_hold_plain_python_numbers() -> None:
    import numpy as np

    s = SimSettings(frame_skip=np.int64(20), timestep=np.float64(0.0025), gravity=np.bool_(True))
    assert type(s.frame_skip) is int and type(s.timestep) is float and s.gravity is True
    assert s.dt == pytest.approx(0.05)
    assert type(ObservationSettings(history=np.int32(3)).history) is int
