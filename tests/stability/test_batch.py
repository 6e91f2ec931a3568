"""stability.batch: the same answers on local processes and on Ray, resume after a kill, no
query lost to a dead worker, bad rows reported by number, the file format round-trips."""

from __future__ import annotations

import functools
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import batch_helpers
import numpy as np
import pytest

from stability import Existence, GraspError, MaxDisturbance, solve
from stability.batch import (
    BatchError,
    LocalExecutor,
    MapPlane,
    RayExecutor,
    decode_row,
    encode_query,
    executors,
    map_rows,
    random_planar,
    random_rows,
    run_batch,
    write_rows,
)
from stability.maps import resistible_forces

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def ray_cluster():
    """One local Ray cluster of 2 CPUs for this module's Ray tests (started here, inside
    the test run; RayExecutor connects to it and leaves it running)."""
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def _rows(path: Path) -> dict[str, dict]:
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    ids = [r["id"] for r in rows]
    assert len(ids) == len(set(ids)), "a query answered twice"
    return {r["id"]: r for r in rows}


def _same(a: dict, b: dict) -> bool:
    """Equal result rows, the measured time aside."""
    return {k: v for k, v in a.items() if k != "time_s"} == {
        k: v for k, v in b.items() if k != "time_s"
    }


def _fifty(path: Path) -> Path:
    """50 queries: planar Existence and MaxDisturbance (method planar) and spatial hands
    (refinement)."""
    rows = (
        random_rows(20, contacts=3, planar=True, seed=1)
        + random_rows(20, contacts=3, planar=True, query="MaxDisturbance", seed=2, cap=5.0)
        + random_rows(5, contacts=3, seed=3)
        + random_rows(5, contacts=3, query="MaxDisturbance", seed=4, cap=5.0)
    )
    write_rows(path, rows)
    return path


@pytest.mark.slow
def test_local_and_ray_give_identical_rows(tmp_path: Path, ray_cluster) -> None:
    q = _fifty(tmp_path / "q.jsonl")
    opts = {"time_limit": 60.0}
    with LocalExecutor(2) as ex:
        c1 = run_batch(q, tmp_path / "local.jsonl", options=opts, executor=ex, progress=False)
    with RayExecutor() as ex:
        assert ex.cpus == 2
        c2 = run_batch(q, tmp_path / "ray.jsonl", options=opts, executor=ex, progress=False)
    assert c1["done"] == c2["done"] == 50 and c1.get("solved") == 50
    a, b = _rows(tmp_path / "local.jsonl"), _rows(tmp_path / "ray.jsonl")
    assert a.keys() == b.keys() and len(a) == 50
    assert all(_same(a[k], b[k]) for k in a)
    # and the same as one solve() in this process, bit for bit
    for line in q.read_text().splitlines()[::7]:
        data = json.loads(line)
        grasp, query, _, _ = decode_row(1, data)
        sol = solve(grasp, query) if grasp.planar else solve(grasp, query, time_limit=60.0)
        r = a[data["id"]]
        assert (r["stable"], r["value"]) == (sol.stable, sol.value)
    # stable MaxDisturbance answers carry a finite value; the planar ones are certain
    md = [r for r in a.values() if r["value"] is not None]
    assert md and all(math.isfinite(r["value"]) and 0 <= r["value"] <= 5.0 for r in md)


def test_resume_after_a_kill_answers_every_query_once(tmp_path: Path) -> None:
    rows = random_rows(24, contacts=3, seed=7)
    q, out = tmp_path / "q.jsonl", tmp_path / "r.jsonl"
    write_rows(q, rows)
    cmd = [
        sys.executable,
        "-m",
        "stability.batch",
        str(q),
        str(out),
        "--workers",
        "1",
        "--no-progress",
        "--time-limit",
        "60",
    ]
    proc = subprocess.Popen(cmd, cwd=REPO, start_new_session=True, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120:
        n = len(out.read_text().splitlines()) if out.exists() else 0
        if n >= 5 or proc.poll() is not None:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the run and its workers, mid-batch
    proc.wait()
    first = _rows(out)
    assert 5 <= len(first) < 24, "the kill did not land half way"
    with open(out, "a") as f:  # a row cut short by the kill
        f.write('{"row": 24, "id": "rand-7-3')
    counts = run_batch(
        q, out, options={"time_limit": 60.0}, executor=LocalExecutor(2), progress=False
    )
    assert counts["skipped"] == len(first) and counts["done"] == 24 - len(first)
    final = _rows(out)
    assert sorted(final) == sorted(r["id"] for r in rows)
    assert all(_same(final[k], first[k]) for k in first)  # the first run's rows kept


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_a_worker_killed_mid_query_loses_nothing(
    tmp_path: Path, executor: str, request: pytest.FixtureRequest
) -> None:
    q = tmp_path / "q.jsonl"
    write_rows(q, random_rows(12, contacts=3, planar=True, seed=5))
    victims = ("rand-5-2", "rand-5-7")
    fn = functools.partial(batch_helpers.kill_once_then_solve, str(tmp_path), victims)
    if executor == "ray":
        from ray import cloudpickle

        request.getfixturevalue("ray_cluster")
        cloudpickle.register_pickle_by_value(batch_helpers)
        ex = RayExecutor()
    else:
        ex = LocalExecutor(2)
    with ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False, solver=fn)
    assert all((tmp_path / f"{v}.killed").exists() for v in victims)  # they did die
    got = _rows(tmp_path / "r.jsonl")
    assert counts["done"] == 12 and len(got) == 12
    assert all(r["status"] == "solved" for r in got.values())
    ref = _rows_of(q, tmp_path / "ref.jsonl")
    assert all(_same(got[k], ref[k]) for k in got)


def _rows_of(q: Path, out: Path) -> dict[str, dict]:
    with LocalExecutor(1) as ex:
        run_batch(q, out, executor=ex, progress=False)
    return _rows(out)


def test_a_query_that_always_kills_its_worker_is_recorded_crashed(tmp_path: Path) -> None:
    q = tmp_path / "q.jsonl"
    write_rows(q, random_rows(6, contacts=3, planar=True, seed=6))
    fn = functools.partial(batch_helpers.always_kill, ("rand-6-1",))
    with LocalExecutor(2, retries=1) as ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False, solver=fn)
    got = _rows(tmp_path / "r.jsonl")
    assert counts["crashed"] == 1 and counts["solved"] == 5
    assert got["rand-6-1"]["status"] == "crashed" and "2 attempts" in got["rand-6-1"]["message"]


def test_hard_timeout_stops_a_hung_query(tmp_path: Path) -> None:
    q = tmp_path / "q.jsonl"
    write_rows(q, random_rows(4, contacts=3, planar=True, seed=8))
    fn = functools.partial(batch_helpers.sleep_on, ("rand-8-0",), 60.0)
    t0 = time.monotonic()
    with LocalExecutor(2, hard_timeout=3.0) as ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False, solver=fn)
    assert time.monotonic() - t0 < 30
    got = _rows(tmp_path / "r.jsonl")
    assert counts["killed"] == 1 and got["rand-8-0"]["status"] == "killed"
    assert sum(r["status"] == "solved" for r in got.values()) == 3


@pytest.mark.parametrize(
    ("start_s", "ready_s", "hard_timeout"),
    [
        # start-up waited for: before, it counted and every worker's first query was killed
        (4.0, executors.READY_S, 3.0),
        # start-up past the wait: its late ready token is skipped, not read as an answer
        (2.0, 0.5, 30.0),
    ],
)
def test_a_workers_start_up_does_not_cost_a_query(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    start_s: float,
    ready_s: float,
    hard_timeout: float,
) -> None:
    """Each fresh worker takes ``start_s`` to start (its solver unpickles slowly, as heavy
    imports do on a loaded machine); the executor waits ``ready_s`` for it. Every quick
    query solves, none is killed."""
    monkeypatch.setattr(executors, "READY_S", ready_s)
    q = tmp_path / "q.jsonl"
    write_rows(q, random_rows(4, contacts=3, planar=True, seed=8))
    with LocalExecutor(2, hard_timeout=hard_timeout) as ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False,
                           solver=batch_helpers.SlowToStart(start_s))  # fmt: skip
    assert counts.get("killed", 0) == 0 and counts["solved"] == 4


def test_bad_rows_are_reported_by_number_and_the_rest_completes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = random_rows(4, contacts=3, planar=True, seed=9)
    nan_normal = json.loads(json.dumps(good[0]))
    nan_normal["id"] = "nan"
    nan_normal["grasp"]["normals"][1][0] = float("nan")
    short = json.loads(json.dumps(good[1]))
    short["id"] = "short"
    short["grasp"]["mu"] = [0.5, 0.5]  # 3 contacts
    unknown = json.loads(json.dumps(good[2]))
    unknown["id"] = "unknown"
    unknown["query"]["type"] = "Wobble"
    lines = [json.dumps(r) for r in good[:2]] + [json.dumps(nan_normal), json.dumps(short)]
    lines += ["{not json", json.dumps(unknown), json.dumps(good[0])]  # rows 5, 6 and a dup id
    lines += [json.dumps(r) for r in good[2:]]
    q = tmp_path / "q.jsonl"
    q.write_text("\n".join(lines) + "\n")
    with LocalExecutor(2) as ex:
        counts = run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False)
    got = [json.loads(x) for x in (tmp_path / "r.jsonl").read_text().splitlines()]
    bad = {r["row"]: r["message"] for r in got if r["status"] == "invalid"}
    assert sorted(bad) == [3, 4, 5, 6, 7]
    assert "NaN" in bad[3] or "nan" in bad[3].lower()
    assert "mu" in bad[4] and "not JSON" in bad[5] and "Wobble" in bad[6]
    assert "duplicate id" in bad[7]
    assert counts["solved"] == 4 and counts["invalid"] == 5
    err = capsys.readouterr().err
    assert all(f"row {r}" in err for r in bad)


def test_rows_round_trip_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    g = random_planar(rng, 4)
    q = MaxDisturbance(direction=[0.3, -0.2, 0.01], cap=4.0, base=[0.0, -0.981, 0.0])
    row = json.loads(json.dumps(encode_query(g, q, id="x", method="planar")))
    g2, q2, method, options = decode_row(1, row)
    assert method == "planar" and options == {}
    for a in ("points", "normals", "mu"):
        np.testing.assert_array_equal(getattr(g2, a), getattr(g, a))
    assert solve(g2, q2).value == solve(g, q).value
    from stability.examples import random_fingers

    h = random_fingers(rng, 3)
    e = Existence(wrench=rng.normal(size=6), commands=np.ones(3))
    h2, e2, _, _ = decode_row(1, json.loads(json.dumps(encode_query(h, e))))
    for a in ("points", "normals", "tangents", "mu", "J", "R"):
        np.testing.assert_array_equal(getattr(h2, a), getattr(h, a))
    np.testing.assert_array_equal(np.asarray(e2.wrench), np.asarray(e.wrench))


def test_map_rows_answer_what_resistible_forces_answers(tmp_path: Path) -> None:
    """The directions of a map as a batch give the map that stability.maps computes."""
    g = random_planar(np.random.default_rng(11), 3)
    base = [0.0, -0.5, 0.0]
    rows = map_rows(g, MapPlane(directions=16), cap=5.0, base=base, method="planar")
    q = write_rows(tmp_path / "q.jsonl", rows) and tmp_path / "q.jsonl"
    with LocalExecutor(2) as ex:
        run_batch(q, tmp_path / "r.jsonl", executor=ex, progress=False)
    got = _rows(tmp_path / "r.jsonl")
    vals = np.array([got[f"dir-{k}"]["value"] or 0.0 for k in range(16)])
    ref = np.array(
        [
            solve(g, MaxDisturbance(direction=d, cap=5.0, base=base), method="planar").value or 0.0
            for d in (np.r_[np.cos(a), np.sin(a), 0.0] for a in np.arange(16) * 2 * np.pi / 16)
        ]
    )
    np.testing.assert_array_equal(vals, ref)
    nobase = resistible_forces(g, directions=16, cap=5.0)
    rows0 = map_rows(g, MapPlane(directions=16), cap=5.0)
    q0 = tmp_path / "q0.jsonl"
    write_rows(q0, rows0)
    with LocalExecutor(1) as ex:
        run_batch(q0, tmp_path / "r0.jsonl", executor=ex, progress=False)
    got0 = _rows(tmp_path / "r0.jsonl")
    np.testing.assert_allclose(
        [got0[f"dir-{k}"]["value"] or 0.0 for k in range(16)],
        nobase.magnitudes,
        rtol=1e-9,
        atol=1e-12,
    )


def test_bad_options_are_our_errors(tmp_path: Path) -> None:
    with pytest.raises(BatchError, match="workers"):
        LocalExecutor(0)
    with pytest.raises(BatchError, match="unknown method 'magic'"):
        run_batch(tmp_path / "q.jsonl", tmp_path / "r.jsonl", method="magic", progress=False)
    with pytest.raises(BatchError, match="no query file"):
        run_batch(tmp_path / "missing.jsonl", tmp_path / "r.jsonl", progress=False)
    with pytest.raises(GraspError, match="query must be"):
        random_rows(2, query="Wobble")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "stability.batch",
            str(tmp_path / "none.jsonl"),
            str(tmp_path / "r.jsonl"),
            "--workers",
            "1",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "no query file" in r.stderr and "Traceback" not in r.stderr
