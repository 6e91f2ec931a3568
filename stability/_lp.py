"""Small dense LPs through HiGHS, called directly (no modelling layer per call)."""

from __future__ import annotations

import highspy
import numpy as np
from numpy.typing import NDArray

from .errors import SolverError

__all__ = ["solve_lp", "INF"]

INF = highspy.kHighsInf


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
) -> tuple[bool, NDArray[np.float64] | None, float | None]:
    """Solve ``min/max cost.x  s.t.  row_lower <= A x <= row_upper, col_lower <= x <= col_upper``.

    Returns ``(feasible, x, objective)``; ``(False, None, None)`` when HiGHS
    proves infeasibility. Unbounded problems and any other status raise
    :class:`SolverError` naming the HiGHS status.
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
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("time_limit", float(time_limit_s))
    h.setOptionValue("primal_feasibility_tolerance", feas_tol)
    h.setOptionValue("dual_feasibility_tolerance", feas_tol)
    h.passModel(lp)
    h.run()
    status = h.getModelStatus()
    if status == highspy.HighsModelStatus.kOptimal:
        x = np.array(h.getSolution().col_value)
        return True, x, float(h.getInfo().objective_function_value)
    if status == highspy.HighsModelStatus.kInfeasible:
        return False, None, None
    if status == highspy.HighsModelStatus.kTimeLimit:
        raise SolverError(f"HiGHS hit its time limit of {time_limit_s} s")
    raise SolverError(f"HiGHS returned status {h.modelStatusToString(status)}")
