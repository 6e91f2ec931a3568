"""A solver-independent mixed-integer linear model: the one layer the 3D methods build on.

The thesis' 3D problems (ch. 5, 6) are mixed-integer: unilateral springs and nonbackdrivable
actuators are on/off conditions, friction linearisations are piecewise. :class:`MipModel`
states them once, in the terms the thesis uses, and the backends (:mod:`stability.mip`)
translate:

- variables ``lb <= x_j <= ub`` of kind ``"C"`` (continuous), ``"B"`` (binary) or ``"I"``
  (integer);
- linear rows ``lo <= sum_k a_k x_{i_k} <= hi``;
- indicator constraints ``z = active  =>  a.x (<=, >=, ==) rhs`` for a binary ``z``
  (SCIP: native; HiGHS: big-M with ``M`` computed from the variables' own bounds, never a
  fixed constant, so every variable in an indicator row needs finite bounds);
- SOS2 sets: at most two consecutive members (in weight order) nonzero (SCIP: native; HiGHS:
  the logarithmic encoding of Vielma and Nemhauser, ``ceil(log2(n - 1))`` binaries for ``n``
  members, which needs ``0 <= lb`` and finite ``ub`` for the members);
- a linear objective, minimised or maximised.

:meth:`MipModel.violations` measures how far a point is from satisfying every condition
*exactly* (indicators and SOS2 as stated, not as reformulated): each backend's answer is
checked with it before it is returned, so a big-M round-off never passes as a solution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ModelError

__all__ = ["INF", "KINDS", "SENSES", "Indicator", "MipModel", "Row", "Sos2"]

INF = math.inf
KINDS = ("C", "B", "I")
SENSES = ("<=", ">=", "==")


@dataclass(frozen=True)
class Row:
    """``lo <= sum(val * x[idx]) <= hi``."""

    idx: NDArray[np.int64]
    val: NDArray[np.float64]
    lo: float
    hi: float
    name: str


@dataclass(frozen=True)
class Indicator:
    """``x[z] == active  =>  sum(val * x[idx]) (sense) rhs``."""

    z: int
    active: int
    idx: NDArray[np.int64]
    val: NDArray[np.float64]
    sense: str
    rhs: float
    name: str

    def as_le(self) -> list[tuple[NDArray[np.float64], float]]:
        """The implied row as ``a.x <= b`` parts: one for ``<=``/``>=``, two for ``==``."""
        signs = {"<=": (1.0,), ">=": (-1.0,), "==": (1.0, -1.0)}[self.sense]
        return [(sign * self.val, sign * self.rhs) for sign in signs]


@dataclass(frozen=True)
class Sos2:
    """At most two members nonzero, and those adjacent in the order of ``weights``;
    ``idx`` is stored sorted by weight."""

    idx: NDArray[np.int64]
    name: str


class MipModel:
    """A mixed-integer linear program; see the module docstring for what it can state.

    Build it with :meth:`add_var` / :meth:`add_vars`, :meth:`add_row`, :meth:`add_indicator`,
    :meth:`add_sos2` and :meth:`set_objective`; solve it with :func:`stability.mip.solve`.
    Indices are the integers that ``add_var(s)`` return. Bad input raises
    :class:`stability.ModelError` naming the offending entry.
    """

    def __init__(self, name: str = "model") -> None:
        self.name = name
        self.lb: list[float] = []
        self.ub: list[float] = []
        self.kind: list[str] = []
        self.var_names: list[str] = []
        self.rows: list[Row] = []
        self.indicators: list[Indicator] = []
        self.sos2: list[Sos2] = []
        self._objective = np.zeros(0)
        self.maximize = False
        self.offset = 0.0
        # one of many small MIPs solved in a row (refinement rounds): SCIP then runs without
        # separators and primal heuristics (stability.mip._scip.build_scip)
        self.many_small = False
        # False: SCIP solves without presolving (stability.model.run.run re-checks a SCIP
        # "infeasible" that way: its presolve has proved feasible models infeasible)
        self.presolve = True
        # relative optimality gap at which a caller's solve may stop (None: the solver
        # call's own); the dual bound then says how far the optimum can be
        self.gap: float | None = None

    # ---------------------------------------------------------------- variables

    @property
    def n_vars(self) -> int:
        return len(self.lb)

    @property
    def objective(self) -> NDArray[np.float64]:
        """The objective's coefficients, one per variable (0 for variables added after it
        was set; padded here, not per variable added: a model of n variables is built in
        O(n), not O(n^2))."""
        n = len(self.lb)
        if self._objective.size < n:
            self._objective = np.concatenate([self._objective, np.zeros(n - self._objective.size)])
        return self._objective

    @objective.setter
    def objective(self, value: ArrayLike) -> None:
        self._objective = np.asarray(value, dtype=float)

    def add_var(
        self, lb: float = 0.0, ub: float = INF, kind: str = "C", name: str | None = None
    ) -> int:
        """One variable ``lb <= x <= ub`` of ``kind`` (``"C"``, ``"B"``, ``"I"``); its index.

        Binary variables get ``[max(lb, 0), min(ub, 1)]``, so ``lb=0, ub=inf`` is fine for them.
        """
        if kind not in KINDS:
            raise ModelError(f"{self.name}: variable kind must be one of {KINDS}, got {kind!r}")
        lb, ub = float(lb), float(ub)
        if math.isnan(lb) or math.isnan(ub) or lb == INF or ub == -INF:
            raise ModelError(f"{self.name}: bad bounds [{lb}, {ub}] for variable {name!r}")
        if kind == "B":
            lb, ub = max(lb, 0.0), min(ub, 1.0)
        if lb > ub:
            raise ModelError(f"{self.name}: empty bounds [{lb}, {ub}] for variable {name!r}")
        self.lb.append(lb)
        self.ub.append(ub)
        self.kind.append(kind)
        self.var_names.append(name if name is not None else f"x{len(self.lb) - 1}")
        return len(self.lb) - 1

    def add_vars(
        self,
        n: int,
        lb: float | ArrayLike = 0.0,
        ub: float | ArrayLike = INF,
        kind: str = "C",
        name: str = "x",
    ) -> NDArray[np.int64]:
        """``n`` variables (bounds scalars or length-``n`` arrays), named ``name[i]``."""
        lbs = np.broadcast_to(np.asarray(lb, dtype=float), (n,))
        ubs = np.broadcast_to(np.asarray(ub, dtype=float), (n,))
        bad = np.isnan(lbs) | np.isnan(ubs) | (lbs == INF) | (ubs == -INF)
        if kind not in KINDS or np.any(bad):  # add_var names the problem
            j = int(np.argmax(bad)) if np.any(bad) else 0
            self.add_var(lbs[j], ubs[j], kind, f"{name}[{j}]")
        if kind == "B":
            lbs, ubs = np.maximum(lbs, 0.0), np.minimum(ubs, 1.0)
        if np.any(lbs > ubs):
            j = int(np.argmax(lbs > ubs))
            raise ModelError(f"{self.name}: empty bounds [{lbs[j]}, {ubs[j]}] for variable "
                             f"'{name}[{j}]'")  # fmt: skip
        first = len(self.lb)
        self.lb.extend(lbs.tolist())
        self.ub.extend(ubs.tolist())
        self.kind.extend([kind] * n)
        self.var_names.extend(f"{name}[{i}]" for i in range(n))
        return np.arange(first, first + n, dtype=np.int64)

    # ---------------------------------------------------------------- constraints

    def _terms(
        self, idx: ArrayLike, val: ArrayLike, what: str
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        i = np.asarray(idx)
        i = (i.reshape(1) if i.ndim == 0 else i).astype(np.int64)
        if i.ndim != 1:
            raise ModelError(f"{self.name}: {what}: indices must be one-dimensional")
        v = np.asarray(val, dtype=float)
        v = np.full(i.shape, float(v)) if v.ndim == 0 else np.broadcast_to(v, i.shape).copy()
        il = i.tolist()
        if il and (min(il) < 0 or max(il) >= self.n_vars):
            raise ModelError(
                f"{self.name}: {what}: variable index out of range 0..{self.n_vars - 1}"
            )
        if not np.isfinite(v).all():
            raise ModelError(f"{self.name}: {what}: coefficients must be finite, got {v}")
        if len(set(il)) != len(il):  # merge repeated variables
            u, inv = np.unique(i, return_inverse=True)
            v = np.bincount(inv, weights=v, minlength=len(u))
            i = u
        return i, v

    def add_row(
        self, idx: ArrayLike, val: ArrayLike, lo: float = -INF, hi: float = INF, name: str = ""
    ) -> int:
        """``lo <= sum(val * x[idx]) <= hi`` (``val`` may be a scalar); its row index."""
        i, v = self._terms(idx, val, f"row {name or len(self.rows)}")
        lo, hi = float(lo), float(hi)
        if math.isnan(lo) or math.isnan(hi) or lo > hi or lo == INF or hi == -INF:
            raise ModelError(f"{self.name}: row {name or len(self.rows)}: bad sides [{lo}, {hi}]")
        self.rows.append(Row(i, v, lo, hi, name or f"r{len(self.rows)}"))
        return len(self.rows) - 1

    def add_constraint(
        self, idx: ArrayLike, val: ArrayLike, sense: str, rhs: float, name: str = ""
    ) -> int:
        """``sum(val * x[idx]) (sense) rhs`` with ``sense`` in ``("<=", ">=", "==")``."""
        if sense not in SENSES:
            raise ModelError(f"{self.name}: sense must be one of {SENSES}, got {sense!r}")
        lo = rhs if sense in (">=", "==") else -INF
        hi = rhs if sense in ("<=", "==") else INF
        return self.add_row(idx, val, lo, hi, name)

    def add_indicator(
        self,
        z: int,
        idx: ArrayLike,
        val: ArrayLike,
        sense: str,
        rhs: float,
        active: int = 1,
        name: str = "",
    ) -> int:
        """``x[z] == active  =>  sum(val * x[idx]) (sense) rhs`` for a binary ``x[z]``."""
        label = f"indicator {name or len(self.indicators)}"
        if not (0 <= int(z) < self.n_vars) or self.kind[int(z)] != "B":
            raise ModelError(f"{self.name}: {label}: x[{z}] must be a binary variable")
        if active not in (0, 1):
            raise ModelError(f"{self.name}: {label}: active must be 0 or 1, got {active!r}")
        if sense not in SENSES:
            raise ModelError(f"{self.name}: {label}: sense must be one of {SENSES}, got {sense!r}")
        if not math.isfinite(float(rhs)):
            raise ModelError(f"{self.name}: {label}: rhs must be finite, got {rhs}")
        i, v = self._terms(idx, val, label)
        self.indicators.append(
            Indicator(
                int(z), int(active), i, v, sense, float(rhs), name or f"ind{len(self.indicators)}"
            )
        )
        return len(self.indicators) - 1

    def add_sos2(self, idx: ArrayLike, weights: ArrayLike | None = None, name: str = "") -> int:
        """An SOS2 set over ``x[idx]``, ordered by ``weights`` (default: the given order)."""
        label = f"SOS2 {name or len(self.sos2)}"
        i = np.atleast_1d(np.asarray(idx)).astype(np.int64)
        if i.ndim != 1 or len(np.unique(i)) != len(i):
            raise ModelError(f"{self.name}: {label}: members must be distinct indices")
        if i.size and (i.min() < 0 or i.max() >= self.n_vars):
            raise ModelError(f"{self.name}: {label}: variable index out of range")
        if weights is not None:
            w = np.asarray(weights, dtype=float)
            if w.shape != i.shape or len(np.unique(w)) != len(w) or not np.all(np.isfinite(w)):
                raise ModelError(
                    f"{self.name}: {label}: weights must be distinct, finite, one per member"
                )
            i = i[np.argsort(w)]
        self.sos2.append(Sos2(i, name or f"sos{len(self.sos2)}"))
        return len(self.sos2) - 1

    def set_objective(
        self, idx: ArrayLike, val: ArrayLike, maximize: bool = False, offset: float = 0.0
    ) -> None:
        """Objective ``offset + sum(val * x[idx])``, minimised (or maximised)."""
        i, v = self._terms(idx, val, "objective")
        self.objective = np.zeros(self.n_vars)
        self.objective[i] = v
        self.maximize = bool(maximize)
        self.offset = float(offset)

    # ---------------------------------------------------------------- analysis

    def activity_bounds(self, idx: ArrayLike, val: ArrayLike) -> tuple[float, float]:
        """Smallest and largest ``sum(val * x[idx])`` over the variable bounds (interval
        arithmetic; infinite when an unbounded variable has a nonzero coefficient)."""
        i, v = self._terms(idx, val, "activity")
        lb, ub = np.asarray(self.lb)[i], np.asarray(self.ub)[i]
        lo = np.where(v > 0, v * lb, v * ub)
        hi = np.where(v > 0, v * ub, v * lb)
        lo = np.where(v == 0, 0.0, lo)
        hi = np.where(v == 0, 0.0, hi)
        return float(np.sum(lo)), float(np.sum(hi))

    def objective_value(self, x: ArrayLike) -> float:
        return float(self.offset + self.objective @ np.asarray(x, dtype=float))

    def violations(self, x: ArrayLike) -> dict[str, float]:
        """How far ``x`` is from satisfying each kind of condition exactly (0: satisfied).

        ``bounds``, ``integrality`` (distance of ``B``/``I`` variables to an integer),
        ``rows``, ``indicators`` (the row's violation where ``x[z]`` rounds to ``active``),
        ``sos2`` (the largest member outside the best pair of adjacent members). Absolute
        values, in the model's units.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n_vars,):
            raise ModelError(f"{self.name}: a point has {self.n_vars} entries, got {x.shape}")
        lb, ub = np.asarray(self.lb), np.asarray(self.ub)
        out = {"bounds": 0.0, "integrality": 0.0, "rows": 0.0, "indicators": 0.0, "sos2": 0.0}
        if self.n_vars:
            out["bounds"] = float(max(0.0, np.max(lb - x), np.max(x - ub)))
            integer = np.array([k != "C" for k in self.kind])
            if integer.any():
                out["integrality"] = float(np.max(np.abs(x[integer] - np.round(x[integer]))))
        for r in self.rows:
            a = float(r.val @ x[r.idx])
            out["rows"] = max(out["rows"], r.lo - a, a - r.hi)
        for ind in self.indicators:
            if round(x[ind.z]) != ind.active:
                continue
            xi = x[ind.idx]
            viol = max(float(a @ xi) - b for a, b in ind.as_le())
            out["indicators"] = max(out["indicators"], viol)
        for s in self.sos2:
            v = np.abs(x[s.idx])
            if len(v) <= 2:
                continue
            pair = v[:-1] + v[1:]
            k = int(np.argmax(pair))
            rest = np.delete(v, [k, k + 1])
            out["sos2"] = max(out["sos2"], float(rest.max(initial=0.0)))
        return out

    def plain(self, name: str) -> MipModel:
        """A new model with this one's variables and rows (copied lists, rows shared: they
        are immutable) and a zero objective; no indicators, SOS2 sets or flags. The same
        indices: callers add rows, binaries (appended) or fix bounds on it."""
        out = MipModel(name)
        out.lb, out.ub = list(self.lb), list(self.ub)
        out.kind, out.var_names = list(self.kind), list(self.var_names)
        out.rows = list(self.rows)
        out.objective = np.zeros(self.n_vars)
        return out

    def fixed(self, x: ArrayLike) -> MipModel:
        """The LP left when the integer variables are fixed at ``round(x)``: indicators whose
        binary is at its active value become rows, the others are dropped, and SOS2 members
        outside the adjacent pair that carries most of ``|x|`` are fixed to 0. Same variables,
        same indices: a solution of it satisfies this model's conditions exactly (up to the LP
        solver's tolerance), which is how a big-M answer is polished."""
        x = np.asarray(x, dtype=float)
        out = self.plain(self.name + " (integers fixed)")
        out.kind = ["C"] * self.n_vars
        for j, k in enumerate(self.kind):
            if k != "C":
                out.lb[j] = out.ub[j] = float(np.round(x[j]))
        for ind in self.indicators:
            if round(x[ind.z]) == ind.active:
                out.add_constraint(ind.idx, ind.val, ind.sense, ind.rhs, ind.name)
        for s in self.sos2:
            v = np.abs(x[s.idx])
            if len(v) <= 2:
                continue
            k = int(np.argmax(v[:-1] + v[1:]))
            for j in np.delete(s.idx, [k, k + 1]):
                if out.lb[j] <= 0.0 <= out.ub[j]:  # else the LP is infeasible, as it should be
                    out.lb[j] = out.ub[j] = 0.0
        out.objective = self.objective.copy()
        out.maximize, out.offset = self.maximize, self.offset
        return out

    def summary(self) -> str:
        kinds = {k: self.kind.count(k) for k in KINDS}
        return (
            f"{self.name}: {self.n_vars} variables ({kinds['C']} continuous, {kinds['B']} binary, "
            f"{kinds['I']} integer), {len(self.rows)} rows, {len(self.indicators)} indicators, "
            f"{len(self.sos2)} SOS2 sets"
        )


def sos2_total(model: MipModel, s: Sos2) -> float | None:
    """``T`` where a row of ``model`` fixes ``sum x[s.idx] = T`` (its members, one equal
    coefficient each, no other variable; refinement's ``sum z = 1``); None if none does."""
    members = set(int(j) for j in s.idx)
    for r in model.rows:
        if r.lo != r.hi or len(r.idx) != len(members) or set(int(j) for j in r.idx) != members:
            continue
        v = float(r.val[0])
        if v != 0.0 and np.all(r.val == v):
            return float(r.lo) / v
    return None


def add_log_sos2(out: MipModel, model: MipModel, s: Sos2) -> bool:
    """Add to ``out`` the logarithmic encoding of ``model``'s SOS2 set ``s`` (Vielma and
    Nemhauser, Math. Program. 128, 2011): ``k = ceil(log2(n - 1))`` binaries ``y`` spell
    the chosen segment (members ``s``, ``s + 1``) in a reflected Gray code ``G(s) = s xor
    (s >> 1)``; per bit ``l`` the members all of whose segments have bit ``l`` = 1 sum to at
    most ``U y_l`` and those whose segments all have it 0 to at most ``U (1 - y_l)``.
    ``U`` is the members' fixed sum where a row fixes it (:func:`sos2_total`; the encoding
    is then the ideal one of the convex-combination SOS2), else the sum of their upper
    bounds. Needs members with ``0 <= lb`` and finite ``ub``; returns False (nothing added)
    otherwise. Consecutive Gray codes differ in one bit, so exactly the two members of the
    chosen segment stay free."""
    n = len(s.idx)
    lb, ub = np.asarray(model.lb)[s.idx], np.asarray(model.ub)[s.idx]
    if np.any(lb < 0) or not np.all(np.isfinite(ub)):
        return False
    total = sos2_total(model, s)
    segments = n - 1
    bits = max(1, math.ceil(math.log2(segments)))
    gray = [g ^ (g >> 1) for g in range(segments)]
    y = out.add_vars(bits, 0, 1, "B", f"{s.name}.y")
    for bit in range(bits):
        ones, zeros = [], []
        for j in range(n):
            segs = [g for g in (j - 1, j) if 0 <= g < segments]
            b = [(gray[g] >> bit) & 1 for g in segs]
            if all(b):
                ones.append(j)
            elif not any(b):
                zeros.append(j)
        if ones:  # sum(lambda[ones]) <= U1 y
            u1 = float(ub[ones].sum()) if total is None else min(total, float(ub[ones].sum()))
            out.add_row(np.append(s.idx[ones], y[bit]), np.append(np.ones(len(ones)), -u1),
                        -INF, 0.0, f"{s.name}.L{bit}")  # fmt: skip
        if zeros:  # sum(lambda[zeros]) <= U0 (1 - y)
            u0 = float(ub[zeros].sum()) if total is None else min(total, float(ub[zeros].sum()))
            out.add_row(np.append(s.idx[zeros], y[bit]), np.append(np.ones(len(zeros)), u0),
                        -INF, u0, f"{s.name}.R{bit}")  # fmt: skip
    return True
