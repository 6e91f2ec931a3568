"""The asymmetric critic of ``train.ppo --privileged-critic`` (issue 29): the env's
privileged state read back from MuJoCo, an actor that cannot read it, and a transfer from a
policy without it that starts out computing what the source computes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from envs.four_finger import N_OBS, N_PRIVILEGED, FourFingerRotate, PhysicsSample


def test_privileged_state_is_the_object_and_the_episode_physics() -> None:
    """Object position, quaternion and free-joint velocity from ``MjData``, then friction,
    torsional, mass, mean gain scales and latency of the episode; the sensed part of the
    observation is unchanged."""
    ps = PhysicsSample(0.5, 1.5, 2.0, 0.8, 1)
    env = FourFingerRotate(privileged=True, physics=ps, grasps="test", n_grasps=4)
    plain = FourFingerRotate(physics=ps, grasps="test", n_grasps=4)
    assert env.observation_space.shape == (N_OBS + N_PRIVILEGED,)
    obs, _ = env.reset(seed=0, options={"grasp": 1})
    ref, _ = plain.reset(seed=0, options={"grasp": 1})
    np.testing.assert_array_equal(obs[:N_OBS], ref)
    a = np.full(12, 0.3, dtype=np.float32)
    for _ in range(3):
        obs = env.step(a)[0]
        ref = plain.step(a)[0]
    np.testing.assert_array_equal(obs[:N_OBS], ref)
    d, ph = env.data, env.physics
    priv = obs[N_OBS:]
    np.testing.assert_allclose(priv[:3], ph.object_pos(), atol=1e-7)
    np.testing.assert_allclose(priv[3:7], ph.object_quat(), atol=1e-7)
    dof = env.model.jnt_dofadr[env.model.joint("object").id]
    np.testing.assert_allclose(priv[7:13], np.clip(d.qvel[dof : dof + 6], -20, 20), atol=1e-5)
    np.testing.assert_allclose(priv[13:], [0.5, 1.5, 2.0, 0.8, 1.0], atol=1e-7)
    assert env.observation_space.contains(obs)


def test_actor_ignores_the_privileged_state_and_transfer_starts_equal(tmp_path) -> None:
    """:class:`PrivilegedCriticPolicy`: changing the privileged entries changes the value,
    never the action. ``--init-from`` a policy without them: the new actor and critic compute
    what the source computes on the sensed entries (zero weights on the privileged ones);
    saved as ``policy.pt`` and loaded back as the same class."""
    from stable_baselines3 import PPO

    from envs.four_finger import ObservationSettings
    from train.rotation import RotateConfig, build_model, make_env
    from train.runfiles import init_weights, load_actor_critic
    from train.sb3 import PrivilegedCriticPolicy
    from train.vec import make_vec_env

    small = {"pi": [32, 32], "vf": [32, 32], "n_steps": 64, "batch_size": 64}
    vec = make_vec_env([make_env(RotateConfig(**small))], 0)
    src = PPO("MlpPolicy", vec, policy_kwargs={"net_arch": {"pi": [32, 32], "vf": [32, 32]}})
    src.save(tmp_path / "model.zip")
    vec.close()
    cfg = RotateConfig(observation=ObservationSettings(privileged=True), **small)
    vec_p = make_vec_env([make_env(cfg)], 0)
    model = build_model(cfg, vec_p)
    assert isinstance(model.policy, PrivilegedCriticPolicy)
    init_weights(model, tmp_path)
    x = torch.as_tensor(np.random.default_rng(0).normal(size=(6, N_OBS + N_PRIVILEGED)))
    x = x.float()
    y = x.clone()
    y[:, N_OBS:] += 3.0
    with torch.no_grad():
        a_x, v_x, _ = model.policy.forward(x, deterministic=True)
        a_y, _, _ = model.policy.forward(y, deterministic=True)
        a_s, v_s, _ = src.policy.forward(x[:, :N_OBS], deterministic=True)
    torch.testing.assert_close(a_x, a_y)
    torch.testing.assert_close(a_x, a_s)
    torch.testing.assert_close(v_x, v_s)
    # the critic reads them once its weights on them are not zero
    with torch.no_grad():
        model.policy.mlp_extractor.value_net[0].weight.normal_()
        v_x2 = model.policy.predict_values(x)
        v_y2 = model.policy.predict_values(y)
    assert not torch.allclose(v_x2, v_y2)
    model.save(tmp_path / "priv" / "model.zip")
    model.policy.save(str(tmp_path / "priv" / "policy.pt"))
    back = load_actor_critic(tmp_path / "priv")
    assert isinstance(back, PrivilegedCriticPolicy) and back.actor_obs == N_OBS
    with torch.no_grad():
        torch.testing.assert_close(back.forward(y, deterministic=True)[0], a_x)
    vec_p.close()
    with pytest.raises(SystemExit):
        from train.rotation import parse_config

        parse_config(["--privileged-critic", "--shield", "qp"])
