"""``python -m train.distill``: DAgger from the robust specialists into the generalist's
actor. A tiny run writes a policy directory that loads as a policy, records its teachers,
and starts a generalist run (``--init-from``) with equal weights and statistics."""

from __future__ import annotations

import csv
import json

import numpy as np
import torch

from train.distill import TEACHERS, main
from train.policy import load_policy


def test_a_tiny_distillation_writes_a_policy_that_starts_the_generalist(tmp_path) -> None:
    out = tmp_path / "student"
    main(["--iterations", "2", "--steps", "512", "--n-envs", "4", "--workers", "0",
          "--epochs", "3", "--out", str(out)])  # fmt: skip
    rows = list(csv.DictReader((out / "distill.csv").open()))
    assert [r["actor"] for r in rows] == ["teacher", "student"]
    assert [int(r["samples"]) for r in rows] == [512, 1024]
    assert all(np.isfinite(float(r["loss"])) and float(r["loss"]) >= 0 for r in rows)
    cfg = json.loads((out / "config.json").read_text())
    assert set(cfg["distilled"]["teachers"]) == set(TEACHERS) == set(cfg["objects"])
    act, kw = load_policy(out)
    assert kw["observation"].history == 3 and kw["observation"].privileged
    from stable_baselines3.common.vec_env import DummyVecEnv

    from train.rotation import build_model, make_env
    from train.rotation_config import parse_config
    from train.runfiles import init_normalizer, init_weights, load_actor_critic

    gen = parse_config(["--generalist", "--n-envs", "1", "--init-from", str(out)])
    vec = DummyVecEnv([make_env(gen)])
    norm = init_normalizer(vec, out, 21)
    model = build_model(gen, norm)
    init_weights(model, out)
    src = load_actor_critic(out).state_dict()
    for k, v in model.policy.state_dict().items():
        assert torch.equal(v, src[k]), k
    norm.training = False  # frozen statistics, as load_policy's: a reset does not update them
    obs = norm.reset()
    a = model.policy.predict(obs, deterministic=True)[0]
    np.testing.assert_allclose(a[0], act(norm.get_original_obs())[0], atol=1e-6)
    vec.close()
