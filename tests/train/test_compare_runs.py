"""train.compare: grouping of rotation runs by shield, summary rows, chart."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from train import compare


def fake_run(root: Path, name: str, shield: str, seed: int, returns: list[float]) -> Path:
    d = root / name
    (d / "monitor").mkdir(parents=True)
    (d / "config.json").write_text(json.dumps({"shield": shield, "seed": seed}))
    with (d / "monitor" / "0.monitor.csv").open("w") as f:
        f.write('#{"t_start": 0}\nr,l,t\n')
        for i, r in enumerate(returns):
            f.write(f"{r},64,{i + 1}\n")
    (d / "eval.csv").write_text(
        "steps,speed_rad_s,drop_rate,episodes,wall_s\n64,0.1,0.5,10,1\n"
        f"{64 * len(returns)},{0.2 * seed},0.1,10,2\n"
    )
    return d


def test_summary_and_chart(tmp_path: Path) -> None:
    runs = [
        fake_run(tmp_path, "a", "none", 1, [float(i) for i in range(20)]),
        fake_run(tmp_path, "b", "qp", 2, [1.0] * 18 + [3.0, 5.0]),
    ]
    rows = compare.main([*map(str, runs), "--out", str(tmp_path / "out" / "cmp"), "--window", "5"])
    by = {r["shield"]: r for r in rows}
    assert by["none"]["final_return"] == pytest.approx(18.5)  # last 10 %: episodes 18, 19
    assert by["qp"]["final_return"] == pytest.approx(4.0)
    assert by["qp"]["eval_speed_rad_s"] == pytest.approx(0.4)
    assert by["none"]["env_steps"] == 20 * 64
    assert (tmp_path / "out" / "cmp.png").stat().st_size > 10_000
    with (tmp_path / "out" / "cmp.csv").open() as f:
        assert [r["shield"] for r in csv.DictReader(f)] == ["none", "qp"]


def test_group_by_another_config_field(tmp_path: Path) -> None:
    """``--group-by episode_steps``: runs grouped by that field, a run without it in
    ``none``; the CSV names the field."""
    a = fake_run(tmp_path, "a", "none", 1, [1.0] * 10)
    b = fake_run(tmp_path, "b", "none", 2, [2.0] * 10)
    cfg = json.loads((b / "config.json").read_text())
    (b / "config.json").write_text(json.dumps({**cfg, "episode_steps": 200}))
    out = tmp_path / "g"
    rows = compare.main([str(a), str(b), "--out", str(out), "--window", "2", "--group-by",
                         "episode_steps"])  # fmt: skip
    assert [r["episode_steps"] for r in rows] == ["200", "none"]
    assert rows[0]["final_return"] == pytest.approx(2.0)
    with out.with_suffix(".csv").open() as f:
        assert [r["episode_steps"] for r in csv.DictReader(f)] == ["200", "none"]


def test_not_a_run_directory(tmp_path: Path) -> None:
    (tmp_path / "x").mkdir()
    with pytest.raises(SystemExit, match="not a training run"):
        compare.main([str(tmp_path / "x"), "--out", str(tmp_path / "o")])
