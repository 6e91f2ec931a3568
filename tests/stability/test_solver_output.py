"""No solver writes to stdout: HiGHS' "Running HiGHS ... Copyright" banner (printed once per
process, by the first HiGHS instance whose log is on) and SCIP's log stay off for every
method unless ``verbose=True`` is asked for."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from stability import Existence, MaxDisturbance, examples, solve

ROOT = Path(__file__).resolve().parents[2]

# (method, the grasp and query it answers), each the first solve of a fresh process
CASES = {
    "planar": "examples.three_planar(), MaxDisturbance((0, 1, 0), preload=1.0, cap=10.0)",
    "gws": "examples.three_planar(), Existence((0, -1, 0))",
    "no_mdp": "examples.pinch(), MaxDisturbance((0, 0, 1, 0, 0, 0), commands=0.1, cap=20.0)",
    "iterative": "examples.pinch(), Existence((0, 0, 1, 0, 0, 0), commands=0.1)",
    "refinement": "examples.pinch(), MaxDisturbance((0, 0, 1, 0, 0, 0), commands=0.1, cap=20.0)",
    "exact": "examples.pinch(), MaxDisturbance((0, 0, 1, 0, 0, 0), commands=0.1, cap=20.0)",
}


@pytest.mark.parametrize("method", sorted(CASES))
def test_first_solve_of_a_process_prints_nothing(method, capfd) -> None:
    code = (
        "from stability import Existence, MaxDisturbance, examples, solve\n"
        f"sol = solve({CASES[method]}, method={method!r})\n"
        "assert sol.status == 'solved', sol.status\n"
    )
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=env)
    out, _ = capfd.readouterr()
    assert out == "", out


def test_highs_backed_solves_print_nothing(capfd) -> None:
    """In this process too: the HiGHS MIP backend, its polish LPs and the planar LPs."""
    g = examples.pinch()
    q = MaxDisturbance((0, 0, 1, 0, 0, 0), commands=0.1, cap=20.0)
    for method in ("no_mdp", "iterative", "refinement"):
        assert solve(g, q, method=method, backend="highs").status == "solved"
    assert solve(examples.three_planar(), Existence((0, -1, 0), preload=1.0)).stable
    out, _ = capfd.readouterr()
    assert "HiGHS" not in out and out == "", out
