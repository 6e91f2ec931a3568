"""Independent run seeds (train.seeding), Wilson intervals (train.stats), the evaluator's
exact cycle stop and the benchmark's training-episode windows."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.stats import binomtest

from train import islands, islands_ppo
from train.evaluation import evaluate_success
from train.seeding import STREAMS, RunSeeds
from train.stats import wilson_interval

# ---------------------------------------------------------------------------- seeding


def test_run_seeds_share_no_reset_stream():
    """Every (run seed, stream, env) gets its own reset seed; the former scheme (seed + i for
    training, seed + 1e6 + i for evaluation) gave seeds 1, 2, 3 seven of eight streams in
    common."""
    seen: dict[int, tuple] = {}
    for seed, stream, i in itertools.product(range(6), ("train", "validation", "test"), range(8)):
        s = RunSeeds(seed).env(stream, i)
        for value in (s.reset, s.action_space):
            assert value not in seen, (seed, stream, i, seen.get(value))
            seen[value] = (seed, stream, i)
    # nothing in the range the old integer scheme (and the tuning of issue 4) drew from
    assert min(seen) > 2_000_100


def test_run_seeds_are_reproducible_and_segments_differ():
    a, b = RunSeeds(7), RunSeeds(7)
    assert a.envs("train", 4) == b.envs("train", 4) and a.global_seed == b.global_seed
    resumed = RunSeeds(7, segment=1024)
    assert not set(e.reset for e in a.envs("train", 8)) & set(
        e.reset for e in resumed.envs("train", 8)
    )
    assert a.global_seed != resumed.global_seed != RunSeeds(8).global_seed
    assert a.policy_seed("test") != a.policy_seed("validation")
    assert 0 <= a.global_seed < 2**32 and set(STREAMS) == {"train", "validation", "test", "global"}


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: RunSeeds(-1), "seed must be an integer >= 0"),
        (lambda: RunSeeds(1.5), "seed must be an integer"),
        (lambda: RunSeeds(1, segment=-3), "segment must be"),
        (lambda: RunSeeds(1).stream("eval"), "unknown stream 'eval'"),
        (lambda: RunSeeds(1).env("global", 0), "no environments"),
        (lambda: RunSeeds(1).env("train", -1), "index must be >= 0"),
        (lambda: RunSeeds(1).policy_seed("train"), "policy_seed is for"),
    ],
)
def test_run_seeds_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def _first_tasks(env, n: int) -> list[tuple[float, ...]]:
    """Start and goal of the next ``n`` episodes of a built (already seeded) env."""
    tasks = []
    for _ in range(n):
        env.reset()
        u = env.unwrapped
        tasks.append((*u.state, *u.goal))
    return tasks


def test_training_envs_of_two_runs_draw_different_episodes():
    """The envs that build_envs makes for run seeds 1 and 2 draw no common episode, and the
    same run seed redraws the same ones."""
    cfg = islands_ppo.Config(n_envs=8, normalize=False)
    draws = {}
    for seed in (1, 2, 1):
        vec = islands_ppo.build_envs(cfg, RunSeeds(seed))
        draws.setdefault(seed, []).append(
            [tuple(t) for env in vec.envs for t in _first_tasks(env, 3)]
        )
        vec.close()
    assert draws[1][0] == draws[1][1]
    assert not set(draws[1][0]) & set(draws[2][0])
    assert len(set(draws[1][0])) == 24  # no two envs of one run share a stream either


def test_eval_envs_are_paired_across_shields_and_disjoint_from_training():
    cfg = islands_ppo.Config(shield="smart", normalize=False)
    seeds = RunSeeds(4)
    shielded = islands_ppo.make_eval_envs(cfg, seeds, "test", 3)
    plain = islands_ppo.make_eval_envs(cfg, seeds, "test", 3, shield="none")
    val = islands_ppo.make_eval_envs(cfg, seeds, "validation", 3)
    assert type(shielded[0]).__name__ == "SmartShield" and type(plain[0]).__name__ != "SmartShield"
    a = [_first_tasks(e, 4) for e in shielded]
    assert a == [_first_tasks(e, 4) for e in plain]  # the same episodes with and without shield
    assert not {t for x in a for t in x} & {t for e in val for t in _first_tasks(e, 4)}
    with pytest.raises(ValueError, match="'validation' or 'test'"):
        islands_ppo.make_eval_envs(cfg, seeds, "train", 2)


def test_ppo_parse_rejects_negative_seed(capsys):
    with pytest.raises(SystemExit):
        islands_ppo.parse_config(["--seed", "-2"])
    assert "--seed must be >= 0" in capsys.readouterr().err


# ---------------------------------------------------------------------------- statistics


@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (10, 10), (199, 200), (57, 500), (1, 3)])
def test_wilson_interval_matches_scipy(k, n):
    ref = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    np.testing.assert_allclose(wilson_interval(k, n), (ref.low, ref.high), atol=1e-12)
    lo, hi = wilson_interval(k, n, 0.99)
    assert lo <= wilson_interval(k, n)[0] and hi >= wilson_interval(k, n)[1]


def test_wilson_interval_edge_cases():
    assert all(np.isnan(wilson_interval(0, 0)))
    lo, hi = wilson_interval(199, 200)
    assert 0.97 < lo < 0.975 and hi < 1.0  # the point: 199/200 is not ">= 0.99"
    for bad in ((-1, 3), (4, 3), (1, -1)):
        with pytest.raises(ValueError, match="0 <= successes <= n"):
            wilson_interval(*bad)
    with pytest.raises(ValueError, match="confidence"):
        wilson_interval(1, 2, 1.0)


# ---------------------------------------------------------------------------- evaluator


class ConstantPolicy:
    """A deterministic 'model': the same action everywhere (walks into the sea)."""

    def __init__(self, action):
        self.action = np.asarray(action, dtype=np.float32)

    def predict(self, obs, deterministic=True):
        return np.tile(self.action, (len(obs), 1)), None


class GreedyPolicy:
    """Steps straight at the goal (observation ``[x, y, gx, gy]``); noisy when stochastic."""

    def __init__(self, seed=0):
        self.rng = np.random.default_rng(seed)

    def predict(self, obs, deterministic=True):
        a = np.clip((obs[:, 2:] - obs[:, :2]) / 0.1, -1, 1)
        if not deterministic:
            a = a + self.rng.normal(0, 0.5, a.shape)
        return a.astype(np.float32), None


@pytest.mark.parametrize(
    ("shield", "policy", "env_id"),
    [
        ("simple", ConstantPolicy([1.0, 0.3]), "ihm/IslandsBridges-v0"),
        ("smart", ConstantPolicy([1.0, 0.3]), "ihm/IslandsBridgesRing-v0"),
        ("simple", GreedyPolicy(), "ihm/IslandsBridges-v0"),
        ("smart", GreedyPolicy(), "ihm/IslandsBridges-v0"),
    ],
)
def test_cycle_stop_gives_the_same_result_as_running_to_the_limit(shield, policy, env_id):
    """Stopping an episode whose state repeats (and completing it analytically) changes no
    statistic against stepping it out to the 200-step limit."""
    cfg = islands_ppo.Config(env_id=env_id, shield=shield, normalize=False)
    res = {}
    for stop in (True, False):
        envs = islands_ppo.make_eval_envs(cfg, RunSeeds(11), "test", 4)
        res[stop] = evaluate_success(policy, envs, 30, stop_cycles=stop)
    assert res[True]["cycles_stopped"] > 0 and res[False]["cycles_stopped"] == 0
    for key in ("episodes", "successes", "failures", "mean_length", "intervention_rate"):
        assert res[True][key] == res[False][key], key
    assert res[True]["mean_return"] == pytest.approx(res[False]["mean_return"], rel=1e-12)
    assert res[True]["episodes"] == 30


def test_evaluate_counts_episodes_per_env_and_ignores_cycles_when_stochastic():
    cfg = islands_ppo.Config(env_id="ihm/IslandsBridgesRing-v0", shield="none", normalize=False)
    envs = islands_ppo.make_eval_envs(cfg, RunSeeds(2), "validation", 3)
    res = evaluate_success(GreedyPolicy(1), envs, 10, deterministic=False)
    assert res["episodes"] == 10 and res["cycles_stopped"] == 0
    assert res["successes"] + res["failures"] <= 10
    assert res["intervention_rate"] == 0.0  # no shield
    empty = evaluate_success(GreedyPolicy(), envs, 0)
    assert empty["episodes"] == 0 and np.isnan(empty["success_rate"])


def test_greedy_policy_shows_the_shields_difference():
    """A sanity anchor for the benchmark's reading: walking straight at the goal falls off
    without a shield, freezes with the simple shield and gets further with the smart one."""
    out = {}
    for shield in ("none", "simple", "smart"):
        cfg = islands_ppo.Config(env_id="ihm/IslandsBridgesRing-v0", shield=shield, normalize=False)
        envs = islands_ppo.make_eval_envs(cfg, RunSeeds(3), "test", 4)
        out[shield] = evaluate_success(GreedyPolicy(), envs, 40)
    assert out["none"]["failure_rate"] > 0.5
    assert out["simple"]["failures"] == out["smart"]["failures"] == 0
    assert out["simple"]["cycles_stopped"] > 0
    assert out["smart"]["successes"] >= out["simple"]["successes"]


# ---------------------------------------------------------------------------- benchmark parts


def test_training_windows_bin_by_end_step():
    eps = [(5, True, False, 5), (10, False, True, 3), (11, True, False, 4), (25, True, False, 2)]
    assert islands.training_windows(eps, 25, 10) == [
        (10, 2, 1, 1),
        (20, 1, 1, 0),
        (25, 1, 1, 0),
    ]
    assert islands.training_windows([], 20, 10) == [(10, 0, 0, 0), (20, 0, 0, 0)]


def test_benchmark_jobs_cover_grid_and_study_slowest_first():
    bc = islands.parse_config([])
    jobs = islands._jobs(bc)
    assert len(jobs) == 2 * 3 * 2 * 3 + 2 * 2  # maps x shields x rewards x seeds + study
    assert [j["net"] for j in jobs[:2]] == ["large"] * 2
    study = [j for j in jobs if j["net"] != "medium"]
    assert {(j["env_id"], j["shield"], j["reward"]) for j in study} == {
        ("ihm/IslandsBridgesRing-v0", "smart", "sparse")
    }
    assert {j["env_id"] for j in jobs} == set(islands.MAPS)
    none = islands.parse_config(["--study-nets"])
    assert all(j["net"] == "medium" for j in islands._jobs(none))
