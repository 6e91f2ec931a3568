"""``python -m stability.bench nodelp``: the node LP of ``modesearch`` on three solvers, side by
side on the same LPs.

The LPs: the first ``--repeats`` (default 300) node LPs of ``modesearch``'s search on four
benchmark queries (``python -m stability.bench grasps``: grasps (a), (f), (j), (l), max
disturbance 0; 3 to 6 contacts), recorded as the search solves them (rows, bounds,
objective, in the order taken). Replayed on:

* ``highs warm``: one persistent HiGHS model, bounds and coefficients changed from one LP
  to the next, its basis kept (what the search does);
* ``highs cold``: a new HiGHS model per LP;
* ``daqp``: one DAQP workspace (:class:`daqp.Model`, dual active set, proximal iterations
  for an LP), its data updated per LP and its working set kept (a hot start).

Per solver and query: the median time per LP [ms], and how many LPs end with the same status
as HiGHS's and, where both are optimal, an objective within 1e-6 relative (``agree``).
Writes ``nodelp.csv``.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._lp import quiet_highs
from ..api import solve
from ..io import write_csv
from . import grasps as bench_grasps

QUERIES = (("a", 0), ("f", 0), ("j", 0), ("l", 0))


def record(label: str, k: int, limit: int) -> list[dict[str, Any]]:
    """The first ``limit`` node LPs of modesearch on the max disturbance ``k`` of grasp
    ``label``: per LP its matrix, row and column bounds, objective, and HiGHS's result."""
    from ..modesearch import node as modesearch

    g, f = next((g, f) for lab, g, f in bench_grasps.grasps() if lab == label)
    q = next(q for t, kk, q in bench_grasps.queries_of(label, f)
             if t == "max_disturbance" and kk == k)  # fmt: skip
    lps: list[dict[str, Any]] = []
    original = modesearch.NodeLP.solve

    def recording(self: Any, node: Any) -> Any:
        out = original(self, node)
        if len(lps) < limit:
            h = self.h
            ok = h.getModelStatus() == modesearch.OPTIMAL
            val = h.getInfo().objective_function_value if ok else None
            lps.append({"A": self.A.copy(), "rlo": self.rlo.copy(), "rhi": self.rhi.copy(),
                        "lb": self.lb.copy(), "ub": self.ub.copy(), "cost": self.cost.copy(),
                        "optimal": ok, "objective": val})  # fmt: skip
        return out

    modesearch.NodeLP.solve = recording
    try:
        solve(g, q, method="modesearch", time_limit=60)
    finally:
        modesearch.NodeLP.solve = original
    return lps


def highs_cold(lps: list[dict[str, Any]]) -> list[tuple[float, bool, float | None]]:
    import highspy

    out = []
    for lp in lps:
        t0 = time.perf_counter()
        h = quiet_highs()
        h.setOptionValue("presolve", "off")
        n = lp["A"].shape[1]
        h.addVars(n, lp["lb"], lp["ub"])
        h.changeColsCost(n, np.arange(n, dtype=np.int32), lp["cost"])
        h.changeObjectiveSense(highspy.ObjSense.kMaximize)
        rows, cols = np.nonzero(lp["A"])
        starts = np.searchsorted(rows, np.arange(lp["A"].shape[0]))
        h.addRows(lp["A"].shape[0], lp["rlo"], lp["rhi"], rows.size, starts.astype(np.int32),
                  cols.astype(np.int32), lp["A"][rows, cols])  # fmt: skip
        h.run()
        ok = h.getModelStatus() == highspy.HighsModelStatus.kOptimal
        val = h.getInfo().objective_function_value if ok else None
        out.append((time.perf_counter() - t0, ok, val))
    return out


def highs_warm(lps: list[dict[str, Any]]) -> list[tuple[float, bool, float | None]]:
    import highspy

    h = quiet_highs()
    h.setOptionValue("presolve", "off")
    first = lps[0]
    m, n = first["A"].shape
    h.addVars(n, first["lb"], first["ub"])
    h.changeColsCost(n, np.arange(n, dtype=np.int32), first["cost"])
    h.changeObjectiveSense(highspy.ObjSense.kMaximize)
    A = np.zeros_like(first["A"])
    h.addRows(m, first["rlo"], first["rhi"], 0, np.zeros(m, dtype=np.int32),
              np.zeros(0, dtype=np.int32), np.zeros(0))  # fmt: skip
    lb, ub, rlo, rhi = (np.full(n, np.nan), np.full(n, np.nan), np.full(m, np.nan),
                        np.full(m, np.nan))  # fmt: skip
    out = []
    for lp in lps:
        t0 = time.perf_counter()
        for r, c in zip(*np.nonzero(lp["A"] != A), strict=True):
            h.changeCoeff(int(r), int(c), float(lp["A"][r, c]))
        A = lp["A"]
        for j in np.flatnonzero((lp["lb"] != lb) | (lp["ub"] != ub)):
            h.changeColBounds(int(j), float(lp["lb"][j]), float(lp["ub"][j]))
        lb, ub = lp["lb"], lp["ub"]
        for r in np.flatnonzero((lp["rlo"] != rlo) | (lp["rhi"] != rhi)):
            h.changeRowBounds(int(r), float(lp["rlo"][r]), float(lp["rhi"][r]))
        rlo, rhi = lp["rlo"], lp["rhi"]
        h.run()
        ok = h.getModelStatus() == highspy.HighsModelStatus.kOptimal
        val = h.getInfo().objective_function_value if ok else None
        out.append((time.perf_counter() - t0, ok, val))
    return out


def daqp_hot(lps: list[dict[str, Any]]) -> list[tuple[float, bool, float | None]]:
    """DAQP: simple bounds first, then the rows; equality rows (lo == hi) flagged as such;
    infinite bounds as +-1e30; the LP as a QP with H = 0 (DAQP regularises a singular H by
    proximal iterations)."""
    import daqp

    big = 1e30

    def data(lp: dict[str, Any]) -> tuple:
        lo = np.r_[lp["lb"], lp["rlo"]]
        hi = np.r_[lp["ub"], lp["rhi"]]
        sense = np.where(lo == hi, 5, 0).astype(np.int32)  # 5: equality
        return (np.clip(hi, -big, big), np.clip(lo, -big, big), sense)

    d = daqp.Model()
    first = lps[0]
    hi, lo, sense = data(first)
    n = first["A"].shape[1]
    d.setup(np.zeros((n, n)), -first["cost"], first["A"], hi, lo, sense)
    out = []
    for lp in lps:
        t0 = time.perf_counter()
        hi, lo, sense = data(lp)
        d.update(f=-lp["cost"], A=lp["A"], bupper=hi, blower=lo, sense=sense)
        _, fval, flag, _ = d.solve()
        ok = flag >= 1
        out.append((time.perf_counter() - t0, ok, -float(fval) if ok else None))
    return out


SOLVERS = {"highs warm": highs_warm, "highs cold": highs_cold, "daqp": daqp_hot}


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench nodelp``: ``--repeats`` node LPs per query, ``--out``."""
    limit = args.repeats or 300
    rows = []
    for label, k in QUERIES:
        lps = record(label, k, limit)
        m = next(g.m for lab, g, _ in bench_grasps.grasps() if lab == label)
        for name, fn in SOLVERS.items():
            try:
                res = fn(lps)
            except Exception as e:  # noqa: BLE001  (a solver that cannot take the LPs: reported)
                rows.append({"query": f"{label}:{k}", "contacts": m, "solver": name,
                             "lps": len(lps), "median_ms": None, "agree": 0,
                             "note": f"{type(e).__name__}: {e}"})  # fmt: skip
                continue
            agree = 0
            for lp, (_, ok, val) in zip(lps, res, strict=True):
                if ok == lp["optimal"] and (not ok or math.isclose(
                        val, lp["objective"], rel_tol=1e-6, abs_tol=1e-9)):  # fmt: skip
                    agree += 1
            rows.append({"query": f"{label}:{k}", "contacts": m, "solver": name,
                         "lps": len(lps), "median_ms": 1e3 * float(np.median([r[0] for r in res])),
                         "agree": agree, "note": ""})  # fmt: skip
    print(f"{'query':>6} {'m':>2} {'solver':>11} | {'median ms':>9} | agree")
    for r in rows:
        ms = "-" if r["median_ms"] is None else f"{r['median_ms']:.3f}"
        print(f"{r['query']:>6} {r['contacts']:>2} {r['solver']:>11} | {ms:>9} | "
              f"{r['agree']}/{r['lps']} {r['note']}")  # fmt: skip
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"wrote {write_csv(out / 'nodelp.csv', rows)}")
