"""Shields (thesis Psi_simple, Psi_smart): safety, exactness against brute force, wrappers.

The core tests use a small fake env built on :mod:`envs.geometry` so that they do not depend on
the islands env; the tests at the end wrap the real ``ihm/IslandsBridges-v0`` and
``ihm/IslandsBridgesRing-v0``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from envs.geometry import Box, Disc, signed_distance
from shields import (
    SimpleShield,
    SmartShield,
    project_disc_box,
    project_union_box,
    simple_shield,
    smart_shield,
)

# islands (discs, boxes) and narrow bridges (0.1 wide), some pieces overlapping
PIECES = (
    Disc((0.0, 0.0), 0.5),
    Box((1.0, -0.3), (1.6, 0.3)),
    Disc((0.5, 1.2), 0.35),
    Disc((1.3, 1.0), 0.25),
    Box((0.4, -0.05), (1.05, 0.05)),
    Box((0.45, 0.4), (0.55, 0.9)),
    Box((1.25, 0.25), (1.35, 0.8)),
    Box((0.8, 1.15), (1.1, 1.2)),
)
LO = np.min([p.bounds()[0] for p in PIECES], axis=0)
HI = np.max([p.bounds()[1] for p in PIECES], axis=0)


def predict(state, action, scale):
    """The affine model of the islands world: ``s + k clip(a, -1, 1)``."""
    return np.asarray(state, dtype=float) + scale * np.clip(np.asarray(action, dtype=float), -1, 1)


def safe_states(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` states with ``M(s) >= 0``: uniform in the region, plus some on piece edges."""
    pts = rng.uniform(LO - 0.05, HI + 0.05, size=(20 * n, 2))
    inside = pts[signed_distance(PIECES, pts) >= 0][: n - n // 5]
    edge = []
    while len(edge) < n // 5:  # boundary points of random pieces, kept if M >= 0 after rounding
        piece = PIECES[rng.integers(len(PIECES))]
        lo, hi = piece.bounds()
        p = piece.project(rng.uniform(lo - 0.3, hi + 0.3))
        if signed_distance(PIECES, p) >= 0:
            edge.append(p)
    return np.concatenate([inside, np.array(edge)])


# --------------------------------------------------------------------------- smart shield


@pytest.mark.parametrize("scale", [0.1, 0.3])
def test_smart_shield_next_state_always_safe_and_safe_actions_unchanged(scale):
    rng = np.random.default_rng(0)
    states = safe_states(rng, 3000)
    actions = rng.uniform(-1.3, 1.3, size=(len(states), 2))  # some outside the action box
    n_intervened = 0
    for s, a in zip(states, actions, strict=True):
        was_safe = signed_distance(PIECES, predict(s, a, scale)) >= 0
        a_t, intervened = smart_shield(s, a, PIECES, scale)
        assert intervened == (not was_safe)
        if was_safe:
            np.testing.assert_array_equal(a_t, np.clip(a, -1, 1))  # the env's step, unchanged
        else:
            assert np.all(np.abs(a_t) <= 1.0)
            n_intervened += 1
        assert signed_distance(PIECES, predict(s, a_t, scale)) >= 0.0, (s, a, a_t)
    assert n_intervened > 200  # the test exercises the projection, not just the fast path


@pytest.mark.parametrize(
    ("scale", "a_max"),
    [(0.3, 1.0), (0.1, 3.0)],  # the second: targets beyond the action box, whose edges bind
)
def test_smart_shield_is_optimal_against_brute_force_grid(scale, a_max):
    """``||a~ - clip(a)||`` matches the best safe action on a 401x401 grid of [-1, 1]^2, from
    both sides: never worse than the grid (the grid's safe points are feasible, so the exact
    minimum is <= theirs), never better by more than one grid cell diagonal (the safe points
    nearest to the optimum, which must lie inside the region, are at most that far away).
    The target is the clipped action: the shield answers for the step the env would take."""
    rng = np.random.default_rng(1)
    ticks = np.linspace(-1.0, 1.0, 401)
    step = ticks[1] - ticks[0]
    grid = np.stack(np.meshgrid(ticks, ticks, indexing="ij"), axis=-1).reshape(-1, 2)
    states = safe_states(rng, 600)
    checked = out_of_box = 0
    for s in states:
        a = rng.uniform(-a_max, a_max, size=2)
        if signed_distance(PIECES, predict(s, a, scale)) >= 0:
            continue
        c = np.clip(a, -1.0, 1.0)
        a_t, intervened = smart_shield(s, a, PIECES, scale)
        assert intervened
        assert np.all(np.abs(a_t) <= 1.0)
        smart = np.linalg.norm(a_t - c)
        # brute force over the grid points within smart + 3 steps of clip(a) (a cheaper but
        # equal minimum whenever brute <= smart + 3 steps; otherwise brute = inf fails below)
        dist = np.linalg.norm(grid - c, axis=1)
        near = dist <= smart + 3 * step
        ok = signed_distance(PIECES, s + scale * grid[near]) >= 0
        brute = dist[near][ok].min() if ok.any() else np.inf
        assert smart <= brute + 1e-6, (s, a, smart, brute)
        assert smart >= brute - step * np.sqrt(2), (s, a, smart, brute)
        out_of_box += bool(np.any(np.abs(a) > 1.0))
        checked += 1
        if checked == 150:
            break
    assert checked == 150
    assert (out_of_box > 100) == (a_max > 1.0)  # a_max = 3: mostly out-of-box actions


def test_smart_shield_safe_out_of_box_action_is_clipped_not_intervened():
    s = np.array([1.3, 0.0])  # deep inside the box island [1.0, 1.6] x [-0.3, 0.3]
    a_t, intervened = smart_shield(s, [3.0, 0.0], PIECES, 0.1)
    assert not intervened  # clipping alone is not an intervention
    assert a_t.dtype == np.float64
    np.testing.assert_array_equal(a_t, [1.0, 0.0])  # exactly the env's clipped step
    a_t, intervened = smart_shield(s, [-2.0, 0.5], PIECES, 0.1, low=[-0.5, -1], high=[1, 0.2])
    assert not intervened
    np.testing.assert_array_equal(a_t, [-0.5, 0.2])


def test_smart_shield_projects_the_clipped_action_not_the_raw_one():
    """From inside the big disc, ``a = (-0.2, 3)``: ``clip(a) = (-0.2, 1)`` leaves the disc to
    the north, and its nearest safe action slides along the disc's rim. Projecting the raw
    target ``s + k a`` instead would jump to the vertical bridge's corner ``(0.5, 1)``, which
    is much farther from the step the env would take."""
    s, k, a = np.array([0.3, 0.3]), 0.3, np.array([-0.2, 3.0])
    c = np.clip(a, -1.0, 1.0)
    assert signed_distance(PIECES, s + k * c) < 0
    a_t, intervened = smart_shield(s, a, PIECES, k)
    assert intervened
    # what projecting the unclipped target would give
    raw = (project_union_box(PIECES, s - k, s + k, s + k * a) - s) / k
    np.testing.assert_allclose(raw, [0.5, 1.0], atol=1e-12)
    assert np.linalg.norm(a_t - raw) > 0.5
    # the exact answer: q = s + k clip(a) projected radially onto the disc |p| <= 0.5
    q = s + k * c
    np.testing.assert_allclose(a_t, (0.5 * q / np.linalg.norm(q) - s) / k, atol=1e-8)
    # ... and no safe action on a fine grid of the action box is nearer to clip(a)
    ticks = np.linspace(-1.0, 1.0, 801)
    step = ticks[1] - ticks[0]
    grid = np.stack(np.meshgrid(ticks, ticks, indexing="ij"), axis=-1).reshape(-1, 2)
    brute = np.linalg.norm(grid - c, axis=1)[signed_distance(PIECES, s + k * grid) >= 0].min()
    smart = np.linalg.norm(a_t - c)
    assert brute - step * np.sqrt(2) <= smart <= brute + 1e-9
    assert smart < np.linalg.norm(raw - c) - 0.2


def test_smart_shield_no_safe_action_gives_zero_step():
    s = np.array([5.0, 5.0])  # far outside every piece: nothing reachable is safe
    a_t, intervened = smart_shield(s, [0.3, -0.2], PIECES, 0.1)
    assert intervened
    np.testing.assert_array_equal(a_t, [0.0, 0.0])


def test_smart_shield_respects_action_bounds():
    rng = np.random.default_rng(2)
    for s in safe_states(rng, 300):
        a = rng.uniform(-1, 1, size=2)
        a_t, intervened = smart_shield(s, a, PIECES, 0.3, low=[-0.5, -0.2], high=[0.4, 0.6])
        if not intervened:  # safe after the clip: returned clipped, as the env would step
            np.testing.assert_array_equal(a_t, np.clip(a, [-0.5, -0.2], [0.4, 0.6]))
            continue
        assert np.all(a_t >= [-0.5, -0.2]) and np.all(a_t <= [0.4, 0.6])
        nxt = s + 0.3 * np.clip(a_t, [-0.5, -0.2], [0.4, 0.6])
        assert signed_distance(PIECES, nxt) >= 0


# --------------------------------------------------------------------------- projections


def test_disc_box_projection_matches_dense_sampling():
    rng = np.random.default_rng(3)
    n_checked = n_empty = 0
    for _ in range(300):
        c = rng.uniform(-1, 1, size=2)
        r = rng.uniform(0.1, 1.0)
        lo = rng.uniform(-1.5, 1.0, size=2)
        hi = lo + rng.uniform(0.05, 1.5, size=2)
        q = rng.uniform(-2, 2, size=2)
        p = project_disc_box(c, r, lo, hi, q)
        # dense sampling of D ∩ B: a grid of the box plus points on the circle and box edges
        t = np.linspace(0, 1, 301)
        gx, gy = np.meshgrid(lo[0] + t * (hi[0] - lo[0]), lo[1] + t * (hi[1] - lo[1]))
        th = np.linspace(0, 2 * np.pi, 20001)
        samples = np.concatenate(
            [
                np.stack([gx.ravel(), gy.ravel()], axis=1),
                c + r * np.stack([np.cos(th), np.sin(th)], axis=1),
            ]
        )
        feas = samples[
            (np.linalg.norm(samples - c, axis=1) <= r)
            & np.all(samples >= lo, axis=1)
            & np.all(samples <= hi, axis=1)
        ]
        empty_truth = np.linalg.norm(np.clip(c, lo, hi) - c) > r
        if empty_truth:
            assert p is None
            n_empty += 1
            continue
        assert p is not None
        assert np.linalg.norm(p - c) <= r * (1 + 1e-12) + 1e-12
        assert np.all(p >= lo - 1e-12) and np.all(p <= hi + 1e-12)
        if len(feas) == 0:
            continue  # intersection thinner than the sampling
        d_exact = np.linalg.norm(p - q)
        d_sampled = np.linalg.norm(feas - q, axis=1).min()
        res = np.linalg.norm(hi - lo) / 300
        assert d_exact <= d_sampled + 1e-9
        assert d_exact >= d_sampled - res
        n_checked += 1
    assert n_checked > 100 and n_empty > 10


def test_single_point_signed_distance_is_bitwise_the_array_one():
    """The float path for one point (what the env and the shields call every step) must give
    exactly the array path's value, also for points on an edge (projections), where a last-bit
    difference would flip the safety verdict."""
    rng = np.random.default_rng(11)
    pts = [rng.uniform(-1.5, 1.5, size=(3000, 2))]
    pts += [np.array([piece.project(q) for q in rng.uniform(-1.5, 1.5, size=(500, 2))])
            for piece in PIECES]  # fmt: skip
    pts = np.concatenate(pts)
    batch = signed_distance(PIECES, pts)
    single = np.array([signed_distance(PIECES, q) for q in pts])
    assert np.array_equal(batch, single)
    assert np.sum(batch == 0.0) > 100  # edge points were exercised
    assert np.array_equal(batch >= 0, single >= 0)


def test_union_projection_is_nearest_piece_projection():
    q = np.array([0.7, 0.3])  # between the big disc, the bridge and the vertical bridge
    p = project_union_box(PIECES, [-10, -10], [10, 10], q)
    candidates = [piece.project(q) for piece in PIECES]
    best = min(candidates, key=lambda c: np.linalg.norm(c - q))
    np.testing.assert_allclose(p, best, atol=1e-12)
    assert project_union_box(PIECES, [5, 5], [6, 6], q) is None


# --------------------------------------------------------------------------- simple shield


def test_simple_shield_zero_step_if_unsafe_else_unchanged():
    rng = np.random.default_rng(4)
    states = safe_states(rng, 2000)
    actions = rng.uniform(-1, 1, size=(len(states), 2))
    n_unsafe = 0
    for s, a in zip(states, actions, strict=True):
        a_t, intervened = simple_shield(
            s, a, lambda s_, a_: predict(s_, a_, 0.3), lambda x: signed_distance(PIECES, x)
        )
        if signed_distance(PIECES, predict(s, a, 0.3)) >= 0:
            assert not intervened
            np.testing.assert_array_equal(a_t, a)
        else:
            assert intervened
            np.testing.assert_array_equal(a_t, [0.0, 0.0])
            n_unsafe += 1
        assert signed_distance(PIECES, predict(s, a_t, 0.3)) >= 0
    assert n_unsafe > 100


# --------------------------------------------------------------------------- wrappers


class FakeIslands(gym.Env):
    """Minimal env with the shield interface; records every action it receives."""

    def __init__(self, scale: float = 0.3, action_shape: tuple[int, ...] = (2,)):
        self.action_space = spaces.Box(-1.0, 1.0, action_shape, np.float32)
        self.observation_space = spaces.Box(-10.0, 10.0, (2,), np.float64)
        self.safe_pieces = PIECES
        self.action_scale = scale
        self.state = np.zeros(2)
        self.received: list[np.ndarray] = []

    def predict(self, state, action):
        return predict(state, action, self.action_scale)

    def safe_distance(self, state):
        return float(signed_distance(self.safe_pieces, state))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = np.array([0.3, 0.0])
        self.received = []
        return self.state.copy(), {}

    def step(self, action):
        self.received.append(np.array(action, copy=True))
        self.state = self.predict(self.state, action)
        failure = self.safe_distance(self.state) < 0
        return self.state.copy(), 0.0, failure, False, {"failure": failure}


@pytest.mark.parametrize("wrapper", [SimpleShield, SmartShield])
def test_wrapper_info_and_inner_env_receives_executed_action(wrapper):
    env = wrapper(FakeIslands())
    env.reset(seed=0)
    rng = np.random.default_rng(5)
    n_intervened = 0
    for _ in range(300):
        a = rng.uniform(-1, 1, size=2).astype(np.float32)
        _, _, terminated, _, info = env.step(a)
        assert not info["failure"] and not terminated
        assert set(info) >= {"agent_action", "executed_action", "shield_intervened"}
        np.testing.assert_array_equal(info["agent_action"], a)
        np.testing.assert_array_equal(env.unwrapped.received[-1], info["executed_action"])
        assert isinstance(info["shield_intervened"], bool)
        if info["shield_intervened"]:
            n_intervened += 1
        else:
            np.testing.assert_array_equal(info["executed_action"], a)
    assert n_intervened > 10


def test_smart_wrapper_goes_along_the_edge_where_simple_stops():
    """Pushing out of the disc sideways: simple stands still, smart slides along the edge."""
    for wrapper, moves in ((SimpleShield, False), (SmartShield, True)):
        env = wrapper(FakeIslands())
        env.reset()
        env.unwrapped.state = np.array([0.0, -0.45])
        _, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))
        assert info["shield_intervened"]
        assert (np.linalg.norm(info["executed_action"]) > 0.1) == moves


class NoInterface(gym.Env):
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)


class DiscreteActions(FakeIslands):
    def __init__(self):
        super().__init__()
        self.action_space = spaces.Discrete(4)


@pytest.mark.parametrize("wrapper", [SimpleShield, SmartShield])
def test_wrappers_reject_non_box_actions_and_missing_interface(wrapper):
    with pytest.raises(TypeError, match="Box"):
        wrapper(DiscreteActions())
    with pytest.raises(TypeError, match="lacks"):
        wrapper(NoInterface())


def test_smart_wrapper_rejects_missing_pieces_and_non_2d_actions():
    env = FakeIslands()
    del env.safe_pieces
    SimpleShield(env)  # simple does not need the pieces
    with pytest.raises(TypeError, match="safe_pieces"):
        SmartShield(env)
    with pytest.raises(TypeError, match="2D"):
        SmartShield(FakeIslands(action_shape=(3,)))


@pytest.mark.parametrize("wrapper", [SimpleShield, SmartShield])
def test_wrapper_clips_out_of_box_actions_before_shielding(wrapper):
    """A safe action outside the box runs as its clipped value, not as an intervention."""
    env = wrapper(FakeIslands(scale=0.1))
    env.reset()
    env.unwrapped.state = np.array([1.3, 0.0])  # deep inside the box island
    _, _, _, _, info = env.step(np.array([3.0, -0.5]))
    assert not info["shield_intervened"]
    np.testing.assert_array_equal(info["agent_action"], [3.0, -0.5])
    np.testing.assert_array_equal(info["executed_action"], [1.0, -0.5])
    np.testing.assert_array_equal(env.unwrapped.received[-1], [1.0, -0.5])


@pytest.mark.parametrize("wrapper", [SimpleShield, SmartShield])
def test_wrapper_executed_action_is_the_step_the_real_env_took(wrapper):
    """On ``ihm/IslandsBridgesRing-v0`` with actions up to 3 in size: ``executed_action`` is in the
    action box and is exactly the step taken, ``(s_{t+1} - s_t) / action_scale``."""
    pytest.importorskip("envs")
    env = wrapper(gym.make("ihm/IslandsBridgesRing-v0"))
    u = env.unwrapped
    rng = np.random.default_rng(8)
    env.reset(seed=0)
    n_out = n_intervened = 0
    for _ in range(600):
        a = rng.uniform(-3.0, 3.0, size=2).astype(np.float32)
        before = u.state.copy()
        _, _, terminated, truncated, info = env.step(a)
        after = u.state.copy()
        executed = info["executed_action"]
        np.testing.assert_array_equal(info["agent_action"], a.astype(np.float64))
        assert executed.dtype == np.float64 and np.all(np.abs(executed) <= 1.0)
        np.testing.assert_allclose(executed, (after - before) / u.action_scale, rtol=0, atol=1e-12)
        if not info["shield_intervened"]:
            np.testing.assert_array_equal(executed, np.clip(a.astype(np.float64), -1.0, 1.0))
        assert not info["failure"]
        n_out += bool(np.any(np.abs(a) > 1.0))
        n_intervened += info["shield_intervened"]
        if terminated or truncated:
            env.reset()
    assert n_out > 400 and n_intervened > 10


@pytest.mark.parametrize("env_id", ["ihm/IslandsBridges-v0", "ihm/IslandsBridgesRing-v0"])
@pytest.mark.parametrize("wrapper", [SimpleShield, SmartShield])
def test_shield_around_real_islands_env_never_fails(wrapper, env_id):
    envs = pytest.importorskip("envs")
    if not hasattr(envs, "IslandsBridges"):
        pytest.skip("envs.IslandsBridges not available")
    env = wrapper(gym.make(env_id, max_step=0.2))
    rng = np.random.default_rng(6)
    env.reset(seed=0)
    env.action_space.seed(0)
    n_intervened = 0
    for _ in range(2000):
        a = rng.uniform(-1, 1, size=2).astype(np.float32)
        _, _, terminated, truncated, info = env.step(a)
        assert not info["failure"]
        assert info["distance_to_edge"] >= 0
        n_intervened += info["shield_intervened"]
        if terminated or truncated:
            env.reset()
    assert n_intervened > 10
