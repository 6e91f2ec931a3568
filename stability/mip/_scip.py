"""SCIP backend (``pyscipopt``): native indicator constraints; SOS2 sets as the
logarithmic encoding of :func:`stability.mip.model.add_log_sos2` (:data:`LOG_SOS2`)."""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from .model import MipModel, add_log_sos2

__all__ = ["build_scip", "c_stderr", "optimize_scip", "solve_scip"]

_VTYPE = {"C": "C", "B": "B", "I": "I"}


def _bound(v: float) -> float | None:
    return None if math.isinf(v) else float(v)


def solve_scip(
    model: MipModel, time_limit: float | None, verbose: bool, gap: float
) -> dict[str, Any]:
    """Solve with SCIP; returns the raw fields of a :class:`~stability.mip.MipResult`."""
    t0 = time.perf_counter()
    m, x = build_scip(model, time_limit, verbose, gap)
    return optimize_scip(m, x, model, t0)


def build_scip(
    model: MipModel, time_limit: float | None, verbose: bool, gap: float
) -> tuple[Any, list[Any]]:
    """``model`` as a ``pyscipopt.Model`` and its variables (in ``model``'s order), not yet
    solved: a caller may add SCIP's own (e.g. nonlinear) constraints before
    :func:`optimize_scip`."""
    import pyscipopt as scip  # imported here: a missing backend is reported by solve()

    m = scip.Model(model.name)
    if not verbose:
        m.hideOutput()
    if time_limit is not None:
        m.setParam("limits/time", float(time_limit))
    m.setParam("limits/gap", float(gap))
    m.setParam("limits/absgap", min(float(gap), 1e-9))  # the gap is relative; tiny values
    # SCIP's presolve otherwise drops indicator couplings with big coefficients and can
    # answer "optimal" with a wrong value once the model's bounds reach ~1e4
    m.setParam("constraints/indicator/maxcouplingvalue", 1e9)
    if model.many_small:
        # one of many small MIPs (a refinement round): cutting planes and primal heuristics
        # cost more than they save, with the same answers. Not for iterative, whose scheme
        # follows the MIPs' particular optimal vertices and does not converge on the wedge
        # with it. (Round-off in the load can decide such a search's answer: it is zeroed
        # first, stability.model.problem.clean_wrench, tests/stability/test_solver_regressions.py.)
        import pyscipopt as scip

        m.setSeparating(scip.SCIP_PARAMSETTING.OFF)
        m.setHeuristics(scip.SCIP_PARAMSETTING.OFF)
        # no dual reductions: with them SCIP's presolve can prove a wrong optimum on a
        # round, a dual bound below a point the same MIP has
        # (tests/stability/test_solver_regressions.py); without them a round takes somewhat
        # longer, for the same brackets
        m.setParam("misc/allowstrongdualreds", False)
        m.setParam("misc/allowweakdualreds", False)
    if not model.presolve:
        m.setPresolve(scip.SCIP_PARAMSETTING.OFF)
    n_vars = model.n_vars
    enc, native = _log_sos2(model) if LOG_SOS2 else (model, model.sos2)
    x = [
        m.addVar(
            name=enc.var_names[j],
            vtype=_VTYPE[enc.kind[j]],
            lb=_bound(enc.lb[j]),
            ub=_bound(enc.ub[j]),
        )  # fmt: skip
        for j in range(enc.n_vars)
    ]

    def expr(idx: np.ndarray, val: np.ndarray) -> Any:
        return scip.quicksum(float(v) * x[int(i)] for i, v in zip(idx, val, strict=True))

    for r in enc.rows:
        e = expr(r.idx, r.val)
        if r.lo == r.hi:
            m.addCons(e == r.lo, name=r.name)
            continue
        if math.isfinite(r.lo):
            m.addCons(e >= r.lo, name=r.name + ".lo")
        if math.isfinite(r.hi):
            m.addCons(e <= r.hi, name=r.name + ".hi")
    for ind in model.indicators:
        for k, (a, b) in enumerate(ind.as_le()):
            m.addConsIndicator(
                expr(ind.idx, a) <= b,
                binvar=x[ind.z],
                activeone=ind.active == 1,
                name=f"{ind.name}.{k}",
            )
    for s in native:
        if len(s.idx) > 2:
            m.addConsSOS2([x[int(i)] for i in s.idx], weights=list(range(1, len(s.idx) + 1)),
                          name=s.name)  # fmt: skip
    obj = expr(np.flatnonzero(model.objective), model.objective[model.objective != 0])
    m.setObjective(obj + model.offset, sense="maximize" if model.maximize else "minimize")
    return m, x[:n_vars]


# SOS2 sets as the logarithmic encoding (binaries and rows) rather than SCIP's SOS2
# constraint handler: SCIP's search needs far fewer nodes on the encoding (and fewer than
# with one binary per segment), for the same optimum. Gurobi is faster with its own SOS2,
# so only SCIP encodes.
LOG_SOS2 = True


def _log_sos2(model: MipModel) -> tuple[MipModel, list[Any]]:
    """A copy of ``model`` with its SOS2 sets encoded (:func:`add_log_sos2`; the encoding's
    binaries appended after the model's variables), and the sets left native (members
    that the encoding cannot take: a negative lower or an infinite upper bound)."""
    if not model.sos2:
        return model, []
    out = model.plain(model.name)
    native = [s for s in model.sos2 if len(s.idx) > 2 and not add_log_sos2(out, model, s)]
    return out, native


@contextmanager
def c_stderr() -> Iterator[list[str]]:
    """What is written to file descriptor 2 inside the block (C code's ``stderr``: SCIP's
    error messages such as "unresolved numerical troubles in LP", which its quiet message
    handler does not silence), as the one string the yielded list holds after the block;
    the terminal sees none of it."""
    said: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            said.append(tmp.read().decode(errors="replace").strip())


def optimize_scip(m: Any, x: list[Any], model: MipModel, t0: float) -> dict[str, Any]:
    """Solve a model from :func:`build_scip`; the raw fields of a
    :class:`~stability.mip.MipResult` (``time_s`` counted from ``t0``). What SCIP writes to
    ``stderr`` (:func:`c_stderr`) ends the message, or the exception's, not the terminal."""
    try:
        with c_stderr() as said:
            m.optimize()
    except Exception as e:
        raise RuntimeError(f"{e}; SCIP said: {said[0]}" if said and said[0] else str(e)) from e
    status = m.getStatus()
    name = {
        "optimal": "optimal",
        "infeasible": "infeasible",
        "unbounded": "unbounded",
        "inforunbd": "infeasible_or_unbounded",
        "timelimit": "timeout",
        "gaplimit": "optimal",
    }.get(status, "error")
    sol = m.getBestSol() if m.getNSols() > 0 else None
    xs = np.array([m.getSolVal(sol, v) for v in x]) if sol is not None else None
    return {
        "status": name,
        "x": xs,
        "objective": float(m.getSolObjVal(sol)) if sol is not None else None,
        "bound": float(m.getDualbound()) if name in ("optimal", "timeout") else math.nan,
        "nodes": int(m.getNNodes()),
        "message": f"SCIP status {status!r}" + (f"; SCIP said: {said[0]}" if said[0] else ""),
        "time_s": time.perf_counter() - t0,
        "size": f"{model.n_vars} variables, native indicators and SOS2",
    }
