"""Small dense LPs through HiGHS, called directly (no modelling layer per call), and
:func:`quiet_highs`, the one way this package makes a HiGHS instance."""

from __future__ import annotations

from typing import NamedTuple

import highspy
import numpy as np
from numpy.typing import NDArray

from .errors import SolverError

__all__ = ["solve_lp", "LPResult", "INF", "quiet_highs"]

INF = highspy.kHighsInf


class _QuietHighs(highspy.Highs):
    """``highspy.Highs`` with its log off before its first call: highspy's constructor calls
    ``enableCallbacks``, and HiGHS prints its "Running HiGHS ... Copyright" banner on stdout
    at the first call of an instance whose ``output_flag`` is still on (once per process)."""

    def enableCallbacks(self) -> None:  # noqa: N802  (highspy's name)
        self.setOptionValue("output_flag", False)
        super().enableCallbacks()


def quiet_highs() -> highspy.Highs:
    """A new HiGHS instance that prints nothing (``output_flag`` off, set before any call
    that could log); a caller that wants the log sets ``output_flag`` back on."""
    h = _QuietHighs()
    h.setOptionValue("output_flag", False)
    return h


class LPResult(NamedTuple):
    """``feasible``; ``x`` and ``objective`` (None when infeasible); simplex ``iterations``."""

    feasible: bool
    x: NDArray[np.float64] | None
    objective: float | None
    iterations: int


def solve_lp(
    cost: NDArray[np.float64],
    A: NDArray[np.float64],
    row_lower: NDArray[np.float64],
    row_upper: NDArray[np.float64],
    col_lower: NDArray[np.float64],
    col_upper: NDArray[np.float64],
    maximize: bool = False,
    time_limit_s: float = 60.0,
    feas_tol: float = 1e-9,
) -> LPResult:
    """Solve ``min/max cost.x  s.t.  row_lower <= A x <= row_upper, col_lower <= x <= col_upper``.

    Infinite bounds may be given as ``numpy.inf``. The callers' objectives are
    bounded (feasibility problems, or a bounded variable), so HiGHS's
    "unbounded or infeasible" means infeasible. Any other non-optimal status
    (time limit, numerical trouble) raises :class:`SolverError` naming it.
    """
    A = np.asarray(A, dtype=float)
    nrow, ncol = A.shape
    lp = highspy.HighsLp()
    lp.num_col_ = ncol
    lp.num_row_ = nrow
    lp.col_cost_ = np.asarray(cost, dtype=float)
    lp.col_lower_ = np.asarray(col_lower, dtype=float)
    lp.col_upper_ = np.asarray(col_upper, dtype=float)
    lp.row_lower_ = np.asarray(row_lower, dtype=float)
    lp.row_upper_ = np.asarray(row_upper, dtype=float)
    nz_r, nz_c = np.nonzero(A.T)  # column-wise order: (col, row)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.concatenate([[0], np.cumsum(np.bincount(nz_r, minlength=ncol))])
    lp.a_matrix_.index_ = nz_c.astype(np.int32)
    lp.a_matrix_.value_ = A.T[nz_r, nz_c]
    lp.a_matrix_.num_col_ = ncol
    lp.a_matrix_.num_row_ = nrow
    if maximize:
        lp.sense_ = highspy.ObjSense.kMaximize
    h = quiet_highs()
    h.setOptionValue("time_limit", float(time_limit_s))
    h.setOptionValue("primal_feasibility_tolerance", feas_tol)
    h.setOptionValue("dual_feasibility_tolerance", feas_tol)
    h.passModel(lp)
    h.run()
    status = h.getModelStatus()
    info = h.getInfo()
    iters = int(info.simplex_iteration_count)
    if status == highspy.HighsModelStatus.kOptimal:
        x = np.array(h.getSolution().col_value)
        return LPResult(True, x, float(info.objective_function_value), iters)
    if status in (
        highspy.HighsModelStatus.kInfeasible,
        highspy.HighsModelStatus.kUnboundedOrInfeasible,
    ):
        return LPResult(False, None, None, iters)
    if status == highspy.HighsModelStatus.kTimeLimit:
        raise SolverError(f"HiGHS hit its time limit of {time_limit_s} s")
    raise SolverError(f"HiGHS returned status {h.modelStatusToString(status)}")
