"""Gurobi backend (``gurobipy``): native indicator and SOS2 constraints.

The model is passed through gurobipy's matrix API (one ``addMVar``, one ``addMConstr`` over a
sparse matrix); indicators are ``addGenConstrIndicator`` (``==`` natively, one general
constraint) and SOS2 sets ``addSOS(GRB.SOS_TYPE2, ...)``. Every solve runs on one thread
(:data:`THREADS`) with :data:`SETTINGS`, in a model of one shared ``gurobipy.Env`` created on
first use with ``OutputFlag`` 0 before it starts, so the licence banner is never printed.

The pip licence of ``gurobipy`` is size-limited (:data:`LICENCE_LIMIT`: 2000 variables and
2000 constraints, counting linear rows, general constraints and SOS constraints, as measured
with gurobipy 13.0.3). When the installed licence is limited (probed once), a model over the
limit is refused before Gurobi sees it, with status ``"error"`` and a message that says so;
a licence error from Gurobi itself (code 10010) gets the same message.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from .model import MipModel

__all__ = ["LICENCE_LIMIT", "SETTINGS", "THREADS", "gurobi_size", "solve_gurobi"]

THREADS = 1  # small models solved many times: more threads cost more than they save
LICENCE_LIMIT = (2000, 2000)  # variables, constraints of gurobipy's size-limited licence
_LICENCE_ERROR = 10010  # GRB_ERROR_SIZE_LIMIT_EXCEEDED

# Every model's settings (on the shared environment), checked on refinement's MIPs against
# SCIP's answers. IntFeasTol: Gurobi's default 1e-5 lets a binary sit 1e-5 off its value,
# which where Gurobi makes big-M rows of an indicator or SOS (bounds up to 3e4 in refinement)
# is a "trickle" past the condition: answers that fail the exact conditions, and "optimal"
# ones above the optimum; IntFeasTol 1e-9 (Gurobi's least) gives none there. PreSOS1BigM and
# PreSOS2BigM 0 keep indicators and SOS2 native (no big-M in presolve): the same answers,
# several times faster (on their own, with IntFeasTol at 1e-5, they leave the wrong
# answers). FeasibilityTol stays at its default 1e-6 (1e-9 changes no answer).
SETTINGS: dict[str, float] = {"Threads": THREADS, "IntFeasTol": 1e-9, "PreSOS1BigM": 0,
                              "PreSOS2BigM": 0}  # fmt: skip

_ENV: Any = None
_LIMITED: bool | None = None  # whether the installed licence is size-limited (probed once)


def _env() -> Any:
    """The shared, silent environment (created on first use)."""
    global _ENV
    if _ENV is None:
        import gurobipy as gp  # imported here: a missing backend is reported by solve()

        env = gp.Env(empty=True)
        env.setParam("OutputFlag", 0)
        env.start()
        for name, value in SETTINGS.items():
            env.setParam(name, value)
        _ENV = env
    return _ENV


def _size_limited() -> bool:
    """Whether the licence refuses a model just over :data:`LICENCE_LIMIT` (probed once, on
    an empty model of ``LICENCE_LIMIT[0] + 1`` variables: a few milliseconds)."""
    global _LIMITED
    if _LIMITED is None:
        import gurobipy as gp

        m = gp.Model(env=_env())
        try:
            m.addMVar(LICENCE_LIMIT[0] + 1)
            m.optimize()
            _LIMITED = False
        except gp.GurobiError as e:
            _LIMITED = e.errno == _LICENCE_ERROR
        finally:
            m.dispose()
    return _LIMITED


def _row_sides(model: MipModel) -> tuple[list[int], list[str], list[float]]:
    """Gurobi's rows of ``model``: (index of the model row, sense, rhs) for each; a ranged
    row is two, a free one none."""
    which, sense, rhs = [], [], []
    for k, r in enumerate(model.rows):
        if r.lo == r.hi:
            which.append(k), sense.append("="), rhs.append(r.lo)
            continue
        if math.isfinite(r.lo):
            which.append(k), sense.append(">"), rhs.append(r.lo)
        if math.isfinite(r.hi):
            which.append(k), sense.append("<"), rhs.append(r.hi)
    return which, sense, rhs


def gurobi_size(model: MipModel) -> tuple[int, int]:
    """(variables, constraints) of ``model`` as Gurobi counts them against its licence:
    constraints are linear rows (a ranged row is two), indicators (one each, ``==`` too)
    and SOS2 sets of more than two members."""
    return _size(model, _row_sides(model))


def _size(model: MipModel, sides: tuple[list[int], list[str], list[float]]) -> tuple[int, int]:
    n_sos = sum(len(s.idx) > 2 for s in model.sos2)
    return model.n_vars, len(sides[0]) + len(model.indicators) + n_sos


def _too_big(model: MipModel, t0: float, why: str = "") -> dict[str, Any]:
    n_vars, n_cons = gurobi_size(model)
    return {
        "status": "error",
        "x": None,
        "objective": None,
        "bound": math.nan,
        "nodes": 0,
        "message": (
            f"gurobipy's size-limited licence covers models up to {LICENCE_LIMIT[0]} variables "
            f"and {LICENCE_LIMIT[1]} constraints; this model has {n_vars} variables and "
            f"{n_cons} constraints (linear rows, indicators and SOS2 sets as Gurobi counts "
            f"them){why}: use backend 'scip' or 'highs', or install a full Gurobi licence"
        ),
        "time_s": time.perf_counter() - t0,
        "size": f"{n_vars} variables, {n_cons} constraints",
    }


def solve_gurobi(
    model: MipModel, time_limit: float | None, verbose: bool, gap: float
) -> dict[str, Any]:
    """Solve with Gurobi; returns the raw fields of a :class:`~stability.mip.MipResult`."""
    import gurobipy as gp

    t0 = time.perf_counter()
    sides = _row_sides(model)
    n_vars, n_cons = _size(model, sides)
    if (n_vars > LICENCE_LIMIT[0] or n_cons > LICENCE_LIMIT[1]) and _size_limited():
        return _too_big(model, t0)
    m = gp.Model(model.name, env=_env())
    try:
        x = _build(m, model, sides, time_limit, verbose, gap)
        try:
            m.optimize()
        except gp.GurobiError as e:
            if e.errno == _LICENCE_ERROR:
                return _too_big(model, t0, f" (Gurobi: {e})")
            raise
        name, gurobi_name = _status(m.Status)
        has_x = m.SolCount > 0
        bound = math.nan
        if name in ("optimal", "timeout"):
            try:
                bound = float(m.ObjBound) if m.IsMIP else float(m.ObjVal)
            except (AttributeError, gp.GurobiError):
                pass
        return {
            "status": name,
            "x": np.array(x.X, dtype=float).reshape(-1) if has_x else None,
            "objective": float(m.ObjVal) if has_x else None,
            "bound": bound,
            "nodes": int(m.NodeCount) if m.IsMIP else 0,
            "message": f"Gurobi status {gurobi_name}",
            "time_s": time.perf_counter() - t0,
            "size": f"{n_vars} variables, {n_cons} constraints, native indicators and SOS2",
        }
    finally:
        m.dispose()


def _build(
    m: Any,
    model: MipModel,
    sides: tuple[list[int], list[str], list[float]],
    time_limit: float | None,
    verbose: bool,
    gap: float,
) -> Any:
    """Settings and contents of the empty ``gurobipy.Model`` ``m``; the ``MVar`` of
    ``model``'s variables. Rows go in as one sparse matrix (``addMConstr``), faster than one
    ``addLConstr`` per row."""
    import gurobipy as gp
    from gurobipy import GRB

    if verbose:
        m.Params.OutputFlag = 1
    if time_limit is not None:
        m.Params.TimeLimit = float(time_limit)
    m.Params.MIPGap = float(gap)
    m.Params.MIPGapAbs = min(float(gap), 1e-9)  # the gap is relative; tiny values
    if model.many_small:
        # one of many small MIPs (a refinement round), as for SCIP (stability.mip._scip):
        # cutting planes and primal heuristics cost more than they save, with the same
        # answers.
        m.Params.Heuristics = 0
        m.Params.Cuts = 0
    if not model.presolve:
        m.Params.Presolve = 0
    n = model.n_vars
    lb = np.asarray(model.lb, dtype=float)
    ub = np.asarray(model.ub, dtype=float)
    lb[np.isneginf(lb)] = -GRB.INFINITY
    ub[np.isposinf(ub)] = GRB.INFINITY
    x = m.addMVar(n, lb=lb, ub=ub, obj=np.asarray(model.objective, dtype=float),
                  vtype=np.array(model.kind, dtype="U1"))  # fmt: skip
    m.ModelSense = GRB.MAXIMIZE if model.maximize else GRB.MINIMIZE
    m.ObjCon = model.offset
    which, sense, rhs = sides
    if which:
        import scipy.sparse as sparse

        rows = [model.rows[k] for k in which]
        starts = np.concatenate([[0], np.cumsum([len(r.idx) for r in rows])])
        a = sparse.csr_matrix(
            (np.concatenate([r.val for r in rows]), np.concatenate([r.idx for r in rows]),
             starts),
            shape=(len(rows), n),
        )  # fmt: skip
        m.addMConstr(a, x, np.array(sense, dtype="U1"), np.array(rhs, dtype=float))
    if model.indicators or model.sos2:
        xs = x.tolist()
        for ind in model.indicators:
            lhs = gp.LinExpr(ind.val.tolist(), [xs[i] for i in ind.idx.tolist()])
            m.addGenConstrIndicator(xs[ind.z], ind.active == 1, lhs, _SENSE[ind.sense], ind.rhs)
        for s in model.sos2:
            if len(s.idx) > 2:
                m.addSOS(GRB.SOS_TYPE2, [xs[i] for i in s.idx.tolist()],
                         list(range(1, len(s.idx) + 1)))  # fmt: skip
    return x


_SENSE = {"<=": "<", ">=": ">", "==": "="}


def _status(code: int) -> tuple[str, str]:
    """(our status, Gurobi's name) of a ``Model.Status`` code."""
    from gurobipy import GRB

    ours = {GRB.OPTIMAL: "optimal", GRB.INFEASIBLE: "infeasible", GRB.UNBOUNDED: "unbounded",
            GRB.INF_OR_UNBD: "infeasible_or_unbounded", GRB.TIME_LIMIT: "timeout"}  # fmt: skip
    names = {getattr(GRB.Status, k): k for k in dir(GRB.Status) if k.isupper()}
    return ours.get(code, "error"), names.get(code, str(code))
