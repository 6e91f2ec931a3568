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


class _Chatty:
    """A stand-in for a ``pyscipopt.Model`` whose ``optimize`` writes to file descriptor 2
    as SCIP's C code does ("unresolved numerical troubles"), then ends ``status`` (or
    raises, as pyscipopt does on "error in LP solver")."""

    def __init__(self, status: str = "infeasible", fail: bool = False) -> None:
        self.status, self.fail = status, fail

    def optimize(self) -> None:
        os.write(2, b"(node 3) unresolved numerical troubles in LP 7 -- using pseudo solution\n")
        if self.fail:
            raise Exception("SCIP: error in LP solver!")  # noqa: TRY002  (pyscipopt's type)

    def getStatus(self) -> str:  # noqa: N802  (pyscipopt's names)
        return self.status

    def getNSols(self) -> int:  # noqa: N802
        return 0

    def getNNodes(self) -> int:  # noqa: N802
        return 3


def test_scip_chatter_on_stderr_goes_into_the_message(capfd) -> None:
    """What SCIP writes to ``stderr`` from C reaches the answer's message, not the terminal;
    so does it when SCIP then fails."""
    from stability.mip import MipModel
    from stability.mip._scip import optimize_scip

    model = MipModel()
    raw = optimize_scip(_Chatty(), [], model, 0.0)
    assert raw["status"] == "infeasible"
    assert "SCIP said: (node 3) unresolved numerical troubles in LP 7" in raw["message"]
    with pytest.raises(RuntimeError, match="error in LP solver!; SCIP said: .node 3. unresolved"):
        optimize_scip(_Chatty(fail=True), [], model, 0.0)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
