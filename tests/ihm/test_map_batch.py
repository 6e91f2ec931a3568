"""A scene's map as a batch file (python -m ihm batch) gives the map's own values, and
`ihm map` on Ray gives the same map as on local processes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ihm.sim_maps import MapSpec, analysis_map, scene_map_rows
from stability import solve
from stability.batch import LocalExecutor, decode_row, run_batch, write_rows


def test_scene_rows_through_the_batch_give_the_analysis_map(tmp_path: Path) -> None:
    spec = MapSpec("barrett_box", "xz", 6)
    ref = analysis_map(spec, method="gws", progress=False)
    rows = scene_map_rows(spec, method="gws")
    assert [r["id"] for r in rows] == [f"barrett_box-xz-{k}" for k in range(6)]
    q = tmp_path / "q.jsonl"
    write_rows(q, rows)
    with LocalExecutor(2) as ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False)
    assert counts["solved"] == 6
    lines = (tmp_path / "r.jsonl").read_text().splitlines()
    got = {r["id"]: r for r in map(json.loads, lines)}
    vals = [got[f"barrett_box-xz-{k}"] for k in range(6)]
    mags = np.array([v["value"] if v["stable"] else 0.0 for v in vals])
    np.testing.assert_array_equal(mags, ref.magnitudes)
    assert [bool(v["capped"]) for v in vals] == ref.capped.tolist()
    assert 0 < np.count_nonzero(mags) and np.all(mags <= 10.0)
    # the hand-model rows carry the commands and the weight as base load
    hand = scene_map_rows(MapSpec("barrett_box", "xz", 2), method="refinement")
    g, qq, method, _ = decode_row(1, hand[0])
    assert method == "refinement" and g.J is not None and qq.commands is not None
    base, d = np.asarray(qq.base), np.asarray(qq.direction)
    assert abs(np.linalg.norm(base[:3]) - 0.1 * 9.81) < 1e-3  # the 0.1 kg box's weight [N]
    assert abs(base[:3] @ d[:3]) < 1e-6  # direction 0 is world x, the weight world -z
    assert solve(g, qq, method="no_mdp").status == "solved"


@pytest.mark.slow
def test_ihm_map_on_ray_equals_local(tmp_path: Path) -> None:
    import ray

    spec = MapSpec("barrett_box", "xz", 4)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        on_ray = analysis_map(spec, method="gws", progress=False, ray="auto")
    finally:
        ray.shutdown()
    local = analysis_map(spec, method="gws", progress=False, workers=2)
    np.testing.assert_array_equal(on_ray.magnitudes, local.magnitudes)
    np.testing.assert_array_equal(on_ray.capped, local.capped)


def test_map_value_of_a_time_out_is_no_answer() -> None:
    """A time-out's exact point is only the bracket's lower end: the map says NaN (no
    answer), not 0 (unstable); a solved unstable answer is 0, a solved one its value."""
    from ihm.sim_maps import map_value
    from stability import Grasp, MaxDisturbance, Solution

    g = Grasp([[-1.0, 0, 0], [1.0, 0, 0]], [[1.0, 0, 0], [-1.0, 0, 0]], mu=0.5)
    q = MaxDisturbance([0, 1.0, 0, 0, 0, 0])
    late = Solution(None, "modesearch", g, q, value=3.0, status="timeout", lower=3.0, upper=4.0)
    v, capped = map_value(late)
    assert np.isnan(v) and not capped
    assert map_value(Solution(False, "modesearch", g, q, value=None)) == (0.0, False)
    assert map_value(Solution(True, "modesearch", g, q, value=2.5)) == (2.5, False)
