"""HiGHS backend (``highspy``): indicators as big-M rows, SOS2 as a logarithmic encoding.

HiGHS has neither indicator nor SOS constraints, so :func:`reformulate` turns a
:class:`~stability.mip.model.MipModel` into plain rows and binaries:

- ``z = 1 => a.x <= b`` becomes ``a.x - b <= M (1 - z)`` and ``z = 0 => a.x <= b`` becomes
  ``a.x - b <= M z``, with ``M = max(a.x) - b`` over the variables' own bounds (interval
  arithmetic); a row that holds over the whole box needs nothing, and a row with an
  unbounded variable is refused (:class:`~stability.ModelError`), never given a guessed M.
  ``>=`` is the same on ``-a``, ``==`` both.
- SOS2 over ``n`` members (segment ``s`` joins members ``s`` and ``s + 1``): ``k =
  ceil(log2(n - 1))`` binaries ``y`` spell a segment in a reflected Gray code ``G(s) = s xor
  (s >> 1)``; for each bit ``l``, the members all of whose segments have bit ``l`` = 1 sum to
  at most ``U1 y_l`` and those whose segments all have it 0 to at most ``U0 (1 - y_l)``
  (``U`` the members' fixed sum where a row fixes it, else the sum of their upper
  bounds; :func:`stability.mip.model.add_log_sos2`, shared with the SCIP backend).
  Consecutive Gray codes differ in one bit, so exactly the two members of the chosen
  segment stay free (Vielma and Nemhauser, Math. Program. 128, 2011).

Every "optimal" answer is checked against the model's exact conditions before it is
returned (:func:`stability.mip.solve`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import highspy
import numpy as np

from .._lp import quiet_highs
from ..errors import ModelError
from .model import INF, MipModel, add_log_sos2

__all__ = ["reformulate", "solve_highs"]

_KIND = {"C": highspy.HighsVarType.kContinuous, "B": highspy.HighsVarType.kInteger,
         "I": highspy.HighsVarType.kInteger}  # fmt: skip


def reformulate(model: MipModel) -> MipModel:
    """A copy of ``model`` with indicators and SOS2 sets replaced by rows and binaries (the
    original variables keep their indices; the encoding's binaries are appended)."""
    if not model.indicators and not model.sos2:  # an LP or a plain MIP: nothing to add
        return model
    # the variables and rows as they are (already checked by the model): copied, not re-added
    out = model.plain(model.name + " (big-M, log SOS2)")
    for ind in model.indicators:
        for a, b in ind.as_le():  # z = active => a.x <= b
            _, top = model.activity_bounds(ind.idx, a)
            if not math.isfinite(top):
                free = [
                    model.var_names[i]
                    for i, v in zip(ind.idx, a, strict=True)
                    if v != 0 and not math.isfinite(model.ub[i] if v > 0 else model.lb[i])
                ]
                raise ModelError(
                    f"{model.name}: indicator {ind.name} needs finite bounds for its big-M "
                    f"(HiGHS backend); unbounded: {free}"
                )
            big_m = top - b
            if big_m <= 0.0:
                continue  # holds over the whole box
            idx = np.append(ind.idx, ind.z)
            if ind.active == 1:  # a.x + M z <= b + M
                out.add_row(idx, np.append(a, big_m), -INF, b + big_m, ind.name)
            else:  # a.x - M z <= b
                out.add_row(idx, np.append(a, -big_m), -INF, b, ind.name)
    for s in model.sos2:
        if len(s.idx) <= 2:
            continue
        if not add_log_sos2(out, model, s):
            raise ModelError(
                f"{model.name}: SOS2 {s.name} needs members with 0 <= lb and finite ub "
                "(HiGHS backend's logarithmic encoding)"
            )
    out.objective[: model.n_vars] = model.objective  # (the encoding's binaries: 0)
    out.maximize, out.offset = model.maximize, model.offset
    return out


def _to_lp(m: MipModel) -> highspy.HighsLp:
    lp = highspy.HighsLp()
    lp.num_col_ = m.n_vars
    lp.num_row_ = len(m.rows)
    lp.col_cost_ = np.asarray(m.objective, dtype=float)
    lp.offset_ = m.offset
    lp.col_lower_ = np.asarray(m.lb, dtype=float)
    lp.col_upper_ = np.asarray(m.ub, dtype=float)
    lp.row_lower_ = np.array([r.lo for r in m.rows], dtype=float)
    lp.row_upper_ = np.array([r.hi for r in m.rows], dtype=float)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kRowwise
    starts = np.concatenate([[0], np.cumsum([len(r.idx) for r in m.rows])]).astype(np.int32)
    lp.a_matrix_.start_ = starts
    lp.a_matrix_.index_ = np.concatenate([r.idx for r in m.rows] or [[]]).astype(np.int32)
    lp.a_matrix_.value_ = np.concatenate([r.val for r in m.rows] or [[]]).astype(float)
    lp.a_matrix_.num_col_ = m.n_vars
    lp.a_matrix_.num_row_ = len(m.rows)
    lp.integrality_ = [_KIND[k] for k in m.kind]
    if m.maximize:
        lp.sense_ = highspy.ObjSense.kMaximize
    return lp


def solve_highs(
    model: MipModel, time_limit: float | None, verbose: bool, gap: float
) -> dict[str, Any]:
    """Solve with HiGHS; returns the raw fields of a :class:`~stability.mip.MipResult`."""
    t0 = time.perf_counter()
    flat = reformulate(model)
    h = quiet_highs()
    h.setOptionValue("output_flag", bool(verbose))
    if time_limit is not None:
        h.setOptionValue("time_limit", float(time_limit))
    h.setOptionValue("mip_rel_gap", float(gap))
    h.setOptionValue("mip_abs_gap", min(float(gap), 1e-9))
    h.passModel(_to_lp(flat))
    h.run()
    status = h.getModelStatus()
    info = h.getInfo()
    S = highspy.HighsModelStatus
    name = {
        S.kOptimal: "optimal",
        S.kInfeasible: "infeasible",
        S.kUnbounded: "unbounded",
        S.kUnboundedOrInfeasible: "infeasible_or_unbounded",
        S.kTimeLimit: "timeout",
        S.kModelEmpty: "optimal",
    }.get(status, "error")
    has_x = info.primal_solution_status == highspy.SolutionStatus.kSolutionStatusFeasible
    x = np.array(h.getSolution().col_value)[: model.n_vars] if has_x else None
    return {
        "status": name,
        "x": x,
        "objective": float(info.objective_function_value) if has_x else None,
        "bound": float(getattr(info, "mip_dual_bound", math.nan)),
        "nodes": int(getattr(info, "mip_node_count", 0)),
        "message": h.modelStatusToString(status),
        "time_s": time.perf_counter() - t0,
        "size": f"{flat.n_vars} columns, {len(flat.rows)} rows after reformulation",
    }
