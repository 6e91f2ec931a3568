"""``python -m stability.bench planar|mip|refinement|grasps|tradeoff|hands|nodelp``: the
command line, and a tiny run of each benchmark (its CSV and PNG written, the CSV's columns)."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from stability.bench import grasps, mip, nodelp, planar, tradeoff
from stability.bench.__main__ import BENCHMARKS, main

ROOT = Path(__file__).resolve().parents[2]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _run(name: str, out: Path, *options: str) -> list[dict[str, str]]:
    main([name, "--out", str(out), *options])
    assert (out / f"{name}.png").stat().st_size > 0
    return _rows(out / f"{name}.csv")


def test_command_line() -> None:
    """``--help`` names every benchmark; an unknown one is a usage error (exit 2)."""
    run = [sys.executable, "-m", "stability.bench"]
    ok = subprocess.run([*run, "--help"], cwd=ROOT, capture_output=True, text=True, check=True)
    assert all(name in ok.stdout for name in BENCHMARKS)
    for option in ("--max-levels", "--time-limit", "--directions", "--wrenches", "--only",
                   "--out", "--repeats", "--seed"):  # fmt: skip
        assert option in ok.stdout
    bad = subprocess.run([*run, "nope"], cwd=ROOT, capture_output=True, text=True)
    assert bad.returncode == 2 and "invalid choice" in bad.stderr


def test_planar(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(planar, "MS", [2, 3])
    rows = _run("planar", tmp_path, "--repeats", "1")
    assert [int(r["m"]) for r in rows] == [2, 3]
    assert [int(r["faces"]) for r in rows] == [10, 26]  # the thesis' #S
    assert [int(r["thesis_states"]) for r in rows] == [10, 26]


def test_mip(tmp_path, monkeypatch) -> None:
    real = mip._cases
    monkeypatch.setattr(mip, "_cases", lambda rng, repeats: real(rng, repeats)[:1])  # pinch
    rows = _run("mip", tmp_path, "--repeats", "1")
    assert len(rows) == 2 * len(mip.METHODS) * len(mip.BACKENDS)
    assert {r["case"] for r in rows} == {"pinch"}
    assert all(r["backends_agree"] == "1/1" for r in rows)


def test_refinement(tmp_path) -> None:
    rows = _run("refinement", tmp_path, "--max-levels", "0", "--time-limit", "60")
    assert len(rows) == 1 and rows[0]["equivalent_edges"] == "4"
    assert float(rows[0]["value"]) == pytest.approx(float(rows[0]["full_value"]))


@pytest.mark.slow  # modesearch and refinement on one grasp's queries, up to 60 s each
def test_grasps(tmp_path) -> None:
    both = _run("grasps", tmp_path / "two", "--only", "a", "--directions", "1", "--wrenches",
                "1", "--time-limit", "60")  # fmt: skip
    tasks = ["check", "max_disturbance", "optimal_commands"]
    # the default: modesearch and refinement on the same queries, the same answers
    assert [(r["variant"], r["task"]) for r in both] == [
        (v, t) for v in ("modesearch", "refinement") for t in tasks
    ]
    for a, b in zip(both[:3], both[3:], strict=True):
        assert a["status"] == b["status"] == "solved"
        if a["task"] != "check":
            assert float(a["answer"]) == pytest.approx(float(b["answer"]), rel=1e-4)
    rows = _run("grasps", tmp_path, "--only", "a", "--directions", "1", "--wrenches", "1",
                "--time-limit", "60", "--methods", "refinement")  # fmt: skip
    assert [r["task"] for r in rows] == tasks
    assert {r["grasp"] for r in rows} == {"a"} and {r["contacts"] for r in rows} == {"3"}
    assert rows[0]["status"] == "solved" and rows[0]["certified"] in ("True", "False", "")
    # --merge: no run; this run's rows and a copy under another variant name, summarised and
    # charted together (the docs' table combines runs so)
    other = tmp_path / "other"
    other.mkdir()
    with (other / "grasps.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows({**r, "variant": "copy", "time_s": "99"} for r in rows)
    merged = tmp_path / "merged"
    main(["grasps", "--merge", str(tmp_path / "grasps.csv"), str(other / "grasps.csv"),
          "--time-limit", "60", "--out", str(merged)])  # fmt: skip
    summ = _rows(merged / "grasps_summary.csv")
    tasks = ("check", "max_disturbance", "optimal_commands")
    assert [(r["variant"], r["task"]) for r in summ] == [
        (v, t) for v in ("refinement", "copy") for t in tasks
    ]
    # the copy's 99 s counts at the 60 s limit only when it is not solved
    assert all(float(r["median_s"]) == 99.0 for r in summ if r["variant"] == "copy")
    assert (merged / "grasps.png").stat().st_size > 0 and len(_rows(merged / "grasps.csv")) == 6
    # --queries: one query re-run; merged after the full run, its row replaces the old one
    again = tmp_path / "again"
    main(["grasps", "--queries", "a:check:0", "--directions", "1", "--wrenches", "1",
          "--time-limit", "60", "--methods", "refinement", "--out", str(again)])  # fmt: skip
    one = _rows(again / "grasps.csv")
    assert [(r["grasp"], r["task"], r["k"]) for r in one] == [("a", "check", "0")]
    both = tmp_path / "both"
    main(["grasps", "--merge", str(tmp_path / "grasps.csv"), str(again / "grasps.csv"),
          "--time-limit", "60", "--out", str(both)])  # fmt: skip
    rows2 = _rows(both / "grasps.csv")
    assert [(r["task"], r["k"]) for r in rows2] == [(r["task"], r["k"]) for r in rows]
    assert rows2[0]["time_s"] == one[0]["time_s"] and rows2[1]["time_s"] == rows[1]["time_s"]
    with pytest.raises(SystemExit, match="grasp:task:index"):
        main(["grasps", "--queries", "a:nothing:0", "--out", str(again)])


def test_tradeoff(tmp_path, monkeypatch) -> None:
    """Two queries (the pinch, the embedded three-contact grasp along +y) and four
    settings; the error is measured against ``exact``, whose own error is 0."""
    keep = {"planar", "gws", "no_mdp", "exact"}
    real = tradeoff.settings
    monkeypatch.setattr(tradeoff, "settings", lambda: [s for s in real() if s[0] in keep])
    rows = _run("tradeoff", tmp_path, "--only", "03", "--time-limit", "60")
    got = {(r["query"], r["setting"]) for r in rows}
    assert ("pinch +z", "exact") in got and ("three (0.0, 1.0, 0.0)", "planar") in got
    assert ("pinch +z", "planar") not in got  # planar answers the embedded queries only
    assert all(float(r["error"]) == 0.0 for r in rows if r["setting"] == "exact")
    back = tradeoff.read_tradeoff(tmp_path / "tradeoff.csv")
    assert [r["setting"] for r in back] == [r["setting"] for r in rows]


def test_hands(tmp_path) -> None:
    """Two random 3-contact hand grasps, modesearch and refinement: one row per query and
    method, each scored against the best exact value, no bound below another's value."""
    rows = _run("hands", tmp_path, "--n", "2", "--contacts", "3", "--methods",
                "modesearch,refinement", "--time-limit", "60")  # fmt: skip
    assert [(r["id"], r["method"]) for r in rows] == [
        (f"rand-3-{k}", m) for k in range(2) for m in ("modesearch", "refinement")
    ]
    assert all(r["status"] == "solved" and r["bound_violated"] == "False" for r in rows)
    assert all(float(r["error"]) <= 1e-3 for r in rows)
    summ = _rows(tmp_path / "hands_summary.csv")
    assert [r["method"] for r in summ] == ["modesearch", "refinement"]


def test_conflicts_tell_a_wrong_bound_from_a_point_beyond_the_box() -> None:
    """An exact value above another variant's bound is a wrong bound when the point lies in
    that variant's box, and is counted apart when it lies beyond it (max disturbance: the
    lower side is exact; optimal commands: the upper)."""

    def row(variant, task, lower, upper, reach, B):
        return {"variant": variant, "grasp": "a", "task": task, "k": 0, "lower": lower,
                "upper": upper, "reach": reach, "force_bound": B}  # fmt: skip

    md = [row("x", "max_disturbance", 2.0, 2.0, 50.0, 1e3),
          row("y", "max_disturbance", 1.5, 1.9, 5.0, 10.0)]  # fmt: skip
    (c,) = grasps.conflicts(md)
    assert (c["variant"], c["other"], c["inside"]) == ("x", "y", False)
    md[0]["reach"] = 9.0
    assert grasps.conflicts(md)[0]["inside"]
    oc = [row("x", "optimal_commands", 0.5, 0.5, 1.0, 1e3),
          row("y", "optimal_commands", 0.6, 0.7, 1.0, 1e3)]  # fmt: skip
    assert [(c["variant"], c["inside"]) for c in grasps.conflicts(oc)] == [("x", True)]
    md[0]["lower"] = 1.9 * (1 + 1e-9)  # within the rounding allowance: no conflict
    assert grasps.conflicts(md) == []


def test_nodelp(tmp_path, monkeypatch) -> None:
    """Grasp (a)'s first 20 node LPs replayed: HiGHS warm and cold give the search's
    answers on every LP; DAQP's row is there (its agreement is measured, not promised)."""
    monkeypatch.setattr(nodelp, "QUERIES", (("a", 0),))
    main(["nodelp", "--repeats", "20", "--out", str(tmp_path)])
    rows = _rows(tmp_path / "nodelp.csv")
    assert [r["solver"] for r in rows] == ["highs warm", "highs cold", "daqp"]
    assert all(r["agree"] == r["lps"] == "20" for r in rows[:2])
    assert all(float(r["median_ms"]) > 0 for r in rows)
