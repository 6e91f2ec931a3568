"""Each shipped rotation policy meets the robustness target over the physics it is stated for
(``train.policy.STATED_RANGES``; nominal physics for the others): its committed evaluation
files are of that range's corners and meet the target, and the policy itself, run here at
one of those corners, turns without a drop at the speed its file records."""

from __future__ import annotations

import csv
import json

import pytest

from envs.four_finger import Randomization, corners
from train.heldout import csv_path, evaluate_heldout
from train.policy import ROOT, STATED_RANGES, load_policy
from train.rotation import MAX_DROP_RATE, TARGET_SPEED

POLICIES = sorted(p for p in (ROOT / "policies").iterdir() if (p / "config.json").is_file())
ROBUST = sorted(STATED_RANGES)


def _rows(name: str) -> list[dict[str, str]]:
    path = csv_path(ROOT / "policies" / name, "robustness", STATED_RANGES[name])
    with path.open() as f:
        return list(csv.DictReader(f))


def test_stated_policies_are_shipped() -> None:
    assert {p.name for p in POLICIES} >= set(STATED_RANGES)
    assert all(0.0 < s <= 1.0 for s in STATED_RANGES.values())


@pytest.mark.parametrize("name", ROBUST)
def test_robust_policy_meets_every_corner_of_its_stated_range(name: str) -> None:
    """The file is of the scaled range's 16 corners (labels from the code), 20 or more
    episodes each, every one >= 0.5 rad/s with at most 1 drop in 20."""
    rows = _rows(name)
    want = [c.label() for c in corners(Randomization().scaled(STATED_RANGES[name]))]
    assert [r["corner"] for r in rows] == want
    for r in rows:
        n, drops = int(r["episodes"]), int(r["drops"])
        assert n >= 20 and drops / n <= MAX_DROP_RATE, r
        assert float(r["speed_rad_s"]) >= TARGET_SPEED, r


@pytest.mark.parametrize("path", POLICIES, ids=lambda p: p.name)
def test_nominal_policy_meets_the_target_on_held_out_grasps(path) -> None:
    """Every shipped policy, stated range or not, meets the target at nominal physics over
    the 100 held-out episodes of 20 s."""
    r = json.loads((path / "eval_heldout.json").read_text())
    assert r["episodes"] == 100 and r["seconds"] == 20.0
    assert r["drop_rate"] <= MAX_DROP_RATE and r["speed_rad_s"] >= TARGET_SPEED


@pytest.mark.slow
@pytest.mark.parametrize("name", ROBUST)
def test_robust_policy_turns_at_its_slowest_stated_corner(name: str) -> None:
    """Run here, at the stated corner where the file records the lowest speed, the first two
    test grasps on one env with noise seed 0 (the episodes the file's first env ran, with
    ``python -m train.heldout``'s 10 envs) turn the object at >= 0.5 rad/s for 20 s and drop
    exactly where the file says (neither, for every policy here), within 20 % of the file's
    mean speed there."""
    rows = _rows(name)
    i = min(range(len(rows)), key=lambda k: float(rows[k]["speed_rad_s"]))
    row = rows[i]
    assert "dropped_grasps" in row or int(row["drops"]) == 0, "which grasps dropped is unknown"
    want = sorted(int(g) for g in row.get("dropped_grasps", "").split() if int(g) < 2)
    act, kw = load_policy(ROOT / "policies" / name)
    corner = corners(Randomization().scaled(STATED_RANGES[name]))[i]
    r = evaluate_heldout(act, kw, episodes=2, seconds=20.0, physics=corner, n_envs=1)
    assert r["dropped_grasps"] == want == []
    assert r["speed_rad_s"] >= TARGET_SPEED
    assert r["speed_rad_s"] == pytest.approx(float(rows[i]["speed_rad_s"]), rel=0.2)
