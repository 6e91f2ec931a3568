"""Mixed-integer programs for the 3D methods: one model layer, three solvers.

>>> from stability.mip import MipModel, solve
>>> m = MipModel("toy")
>>> x = m.add_var(0, 10)
>>> z = m.add_var(kind="B")
>>> _ = m.add_indicator(z, [x], [1.0], ">=", 4.0)   # z = 1 => x >= 4
>>> _ = m.add_constraint([z], [1.0], "==", 1.0)
>>> m.set_objective([x], [1.0])
>>> r = solve(m, backend="highs")
>>> r.status, round(r.objective, 6)
('optimal', 4.0)

``backend="highs"`` (``highspy``; indicators as big-M from the model's own bounds, SOS2 as
a logarithmic encoding, :mod:`stability.mip._highs`), ``"scip"`` (``pyscipopt``; native
indicator and SOS2 constraints) or ``"gurobi"`` (``gurobipy``, optional: ``pip install
ihm[gurobi]``; native indicator and SOS2 constraints, one thread; the pip licence's size
limit of 2000 variables and 2000 constraints is a status ``"error"`` that says so,
:mod:`stability.mip._gurobi`). All return a :class:`MipResult`; a time-out or a solver
failure is a status (``"timeout"``, ``"error"``), never an exception from the solver's
internals and never an unchecked answer: every returned point is measured against the
model's exact conditions (:meth:`MipModel.violations`) and an "optimal" point that fails
them is reported as ``"error"``.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import MethodError, ModelError
from .model import INF, MipModel

__all__ = ["BACKENDS", "DEFAULT_BACKEND", "INF", "MipModel", "MipResult", "available_backends",
           "build_scip", "check_backend", "optimize_scip", "solve"]  # fmt: skip

BACKENDS = ("highs", "scip", "gurobi")
# the package each backend needs
_PACKAGES = {"highs": "highspy", "scip": "pyscipopt", "gurobi": "gurobipy"}
DEFAULT_BACKEND = "highs"
STATUSES = ("optimal", "infeasible", "unbounded", "infeasible_or_unbounded", "timeout", "error")


@dataclass
class MipResult:
    """The answer of one MIP solve.

    ``status``: one of ``"optimal"``, ``"infeasible"``, ``"unbounded"``,
    ``"infeasible_or_unbounded"``, ``"timeout"`` (``x`` is the best point found, if any),
    ``"error"`` (``message`` says why). ``x`` the values of the model's variables,
    ``objective`` its objective value, ``bound`` the solver's dual bound, ``violations`` the
    exact-condition check of ``x`` (:meth:`MipModel.violations`), ``time_s`` the wall time
    of build and solve, ``nodes`` branch-and-bound nodes.
    """

    status: str
    backend: str
    x: NDArray[np.float64] | None = None
    objective: float | None = None
    bound: float = math.nan
    time_s: float = 0.0
    nodes: int = 0
    message: str = ""
    violations: dict[str, float] = field(default_factory=dict)

    @property
    def optimal(self) -> bool:
        return self.status == "optimal"


def available_backends() -> list[str]:
    """The backends whose solver package is installed (for ``"gurobi"``: installed and
    importable, as ``gurobipy`` is a binary wheel that may fail to load)."""
    return [b for b in BACKENDS if _installed(b)]


@functools.cache
def _installed(backend: str) -> bool:
    """Whether ``backend``'s package is installed (looked up once per process: a look-up
    walks the import path, 0.6 ms, and small LPs are solved thousands of times)."""
    pkg = _PACKAGES[backend]
    if importlib.util.find_spec(pkg) is None:
        return False
    return backend != "gurobi" or _imports(pkg)


@functools.cache
def _imports(pkg: str) -> bool:
    try:
        importlib.import_module(pkg)
    except Exception:  # noqa: BLE001  (any failure to load means "not available")
        return False
    return True


def check_backend(backend: str) -> None:
    """MethodError unless ``backend`` is known and its package installed (naming it)."""
    if backend not in BACKENDS:
        raise MethodError(f"unknown MIP backend {backend!r}; choose one of {BACKENDS}")
    if backend not in available_backends():
        pkg = _PACKAGES[backend]
        raise MethodError(
            f"MIP backend {backend!r} needs the {pkg!r} package, which is not installed "
            f"(pip install {pkg}); available: {available_backends()}"
        )


def solve(
    model: MipModel,
    backend: str = DEFAULT_BACKEND,
    time_limit: float | None = None,
    verbose: bool = False,
    gap: float = 1e-9,
    tol: float = 1e-6,
    polish: bool = True,
) -> MipResult:
    """Solve ``model`` with ``backend``; see :class:`MipResult`.

    Args:
        time_limit: seconds (``None``: no limit); reaching it gives ``status="timeout"``.
        verbose: the solver's own log on stdout (off by default).
        gap: relative and absolute optimality gap at which the solver may stop (every
            backend gets the same).
        tol: largest violation of the exact conditions a returned point may have, relative
            to ``1 + max|x|``.
        polish: re-solve the LP left when the integer variables are fixed at the answer's
            rounded values (:meth:`MipModel.fixed`, HiGHS simplex) and return its point when
            it is feasible: this removes the big-M round-off ("trickle flow") of HiGHS
            answers at the cost of one small LP; its objective may then be worse than the
            unpolished one by that round-off (``bound`` stays the solver's dual bound). The
            result's ``message`` says "polished".

    Raises:
        MethodError: an unknown backend, or one whose package is not installed.
        ModelError: a model the backend cannot state (e.g. an indicator over an unbounded
            variable for HiGHS' big-M).
    """
    check_backend(backend)
    if time_limit is not None and not (math.isfinite(time_limit) and time_limit >= 0):
        raise ModelError(f"time_limit must be a finite number of seconds >= 0, got {time_limit}")
    if not (0 <= gap < 1) or not (tol > 0):
        raise ModelError(f"need 0 <= gap < 1 and tol > 0, got gap={gap}, tol={tol}")
    if backend == "highs":
        from ._highs import solve_highs as run
    elif backend == "gurobi":
        from ._gurobi import solve_gurobi as run
    else:
        from ._scip import solve_scip as run
    try:
        raw = run(model, time_limit, verbose, gap)
    except ModelError:
        raise
    except Exception as e:  # a solver's internal failure is a status, not a traceback
        return MipResult("error", backend, message=f"{backend} failed: {type(e).__name__}: {e}")
    res = MipResult(
        raw["status"],
        backend,
        raw["x"],
        raw["objective"],
        raw["bound"],
        raw["time_s"],
        raw["nodes"],
        raw["message"],
    )
    if polish and res.x is not None and any(k != "C" for k in model.kind):
        _polish(model, res)
    if res.x is not None:
        res.violations = model.violations(res.x)
        worst = max(res.violations.values())
        if worst > tol * (1.0 + float(np.max(np.abs(res.x), initial=0.0))):
            bad = {k: v for k, v in res.violations.items() if v > 0}
            if res.status == "optimal":
                res.status = "error"
                res.message = f"{backend}'s answer fails the exact conditions: {bad}"
            else:  # a time-out's incumbent that fails them is no incumbent
                res.x, res.objective = None, None
    return res


def build_scip(
    model: MipModel, time_limit: float | None = None, verbose: bool = False, gap: float = 1e-9
) -> tuple[Any, list[Any]]:
    """``model`` as a ``pyscipopt.Model`` and its variables (in ``model``'s order), not yet
    solved, with the settings :func:`solve` uses: a caller may add SCIP's own (e.g.
    nonlinear) constraints, then :func:`optimize_scip`. Needs ``pyscipopt``."""
    from ._scip import build_scip as build

    return build(model, time_limit, verbose, gap)


def optimize_scip(m: Any, x: list[Any], model: MipModel, t0: float) -> dict[str, Any]:
    """Solve a model from :func:`build_scip`: the raw fields of a :class:`MipResult`
    (``status``, ``x``, ``objective``, ``bound``, ``nodes``, ``message``, ``time_s`` counted
    from ``t0``, a ``time.perf_counter()`` reading); no check of the answer."""
    from ._scip import optimize_scip as optimize

    return optimize(m, x, model, t0)


def _polish(model: MipModel, res: MipResult) -> None:
    """Replace ``res.x`` by the solution of the LP with the integers fixed, when it has one;
    see :func:`solve`."""
    from ._highs import solve_highs

    t0 = time.perf_counter()
    try:
        lp = solve_highs(model.fixed(res.x), None, False, 0.0)
    except Exception:  # noqa: BLE001  (keep the unpolished answer; it is checked anyway)
        return
    finally:
        res.time_s += time.perf_counter() - t0
    if lp["status"] != "optimal" or lp["x"] is None or res.objective is None:
        return
    # The fixed LP's point satisfies the exact conditions; its objective can be a little
    # worse than the big-M answer's, which a trickle flow may have flattered. A point much
    # worse is a different answer (the trickle decided which integers the LP fixed, e.g. a
    # 6e-7 slide under a "no slide" indicator): then the solver's own point is kept, and the
    # caller's check of the exact conditions decides.
    new = float(lp["objective"])
    old = float(res.objective)
    worse = (old - new) if model.maximize else (new - old)
    if worse > 1e-6 * (1.0 + abs(old)):
        res.message += f" (polish rejected: objective {new:.9g} vs {old:.9g})"
        return
    res.x, res.objective = lp["x"], new
    res.message += " (polished)"
