"""The committed generalist (``policies/four_finger_generalist``): one policy for the three
training objects, read by the same loader as every shipped policy, and its committed corner
tables reproduced here at two corners."""

from __future__ import annotations

import csv
import json

import pytest

from envs.four_finger import TRAIN_OBJECTS, Randomization, corners
from train.heldout import csv_path, evaluate_heldout
from train.policy import ROOT, load_policy

GEN = ROOT / "policies" / "four_finger_generalist"


def _rows(obj: str) -> list[dict[str, str]]:
    with csv_path(GEN, "robustness", 1.0, obj).open() as f:
        return list(csv.DictReader(f))


def test_the_generalist_is_one_policy_for_the_three_objects() -> None:
    """Its config draws the three training objects; its corner tables are of the full ranges'
    16 corners for each of them; the resume checkpoint carries the curriculum's schedule."""
    cfg = json.loads((GEN / "config.json").read_text())
    assert cfg["objects"] == list(TRAIN_OBJECTS) and cfg["randomization"]["adr_step"] > 0
    want = [c.label() for c in corners(Randomization())]
    for obj in TRAIN_OBJECTS:
        assert [r["corner"] for r in _rows(obj)] == want, obj
    adr = json.loads((GEN / "run" / "adr.json").read_text())
    assert adr["history"] and 0.25 <= adr["scale"] <= 1.0
    assert (GEN / "run" / "model.zip").is_file()


@pytest.mark.parametrize(("obj", "corner"), [("cube", 0), ("cylinder", 15)])
def test_the_committed_corner_table_is_reproduced(obj: str, corner: int) -> None:
    """Run here with the table's episode count (test grasps ``0..n-1``, 10 envs, noise seed
    0: what ``python -m train.heldout --corners`` ran), the corner's speed and drops are the
    table's."""
    row = _rows(obj)[corner]
    act, kw = load_policy(GEN)
    physics = corners(Randomization())[corner]
    r = evaluate_heldout(act, {**kw, "object": obj}, int(row["episodes"]), 20.0, physics=physics)
    assert r["drops"] == int(row["drops"])
    assert round(r["speed_rad_s"], 4) == pytest.approx(float(row["speed_rad_s"]), abs=1e-4)
    assert " ".join(map(str, r["dropped_grasps"])) == row["dropped_grasps"]
