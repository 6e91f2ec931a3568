"""``method="spatial"``: the exact nonconvex problem solved globally by SCIP's spatial
branch-and-bound (the thesis' "future work" alternative to ch. 6; our accuracy reference).

The exact model of ch. 5 (:class:`~stability.exact.ExactProblem`: unilateral springs with
preload, nonbackdrivable actuators, object and hand equilibrium, the binaries ``y`` and
``z``) with Coulomb friction and maximum dissipation stated *exactly* per contact ``i``,
with no linearisation of the cone::

    |c_t|^2 <= mu^2 c_n^2                  (the circular cone; a second-order cone)
    |d_t|^2 <= s_i^2,  s_i >= 0            (s_i bounds the tangential slide)
    c_t . d_t + mu c_n s_i <= 0            (maximum dissipation; bilinear)

with ``d_t = G_t^T r - J_t q`` the tangential motion of the object at the contact. Since
``c_t . d_t >= -|c_t| |d_t| >= -mu c_n |d_t| >= -mu c_n s_i``, the last row holds only with
equality throughout: either ``c_n = 0`` (an open or unloaded contact, no friction), or
``d_t = 0 = s_i`` (sticking, ``c_t`` anywhere in the cone), or ``|d_t| = s_i > 0``,
``|c_t| = mu c_n`` and ``c_t`` opposite to ``d_t`` (sliding with maximum dissipation: thesis
eq. mdp). SCIP handles the cones as convex and the bilinear row by spatial branching on
``c_t, d_t, c_n, s`` with McCormick envelopes, so every variable there needs finite
bounds: forces from :func:`~stability.exact.scale_bounds` (``|c_t| <= mu B``), tangential
motions ``|d_t| <= motion_bound * 2 B`` (the same box as ``refinement``'s edge weights;
an answer at it is flagged ``stats["at_bound"]``).

Queries: ``Existence``, ``MaxDisturbance`` (maximise ``s``), ``OptimalCommands`` (the
objectives and limits of ``refinement``), all in one solve. Options: ``time_limit`` (a
time-out returns ``status="timeout"`` with SCIP's incumbent and dual bound in
``stats["incumbent"]``/``stats["dual_bound"]``), ``bound_factor``, ``verbose``,
``normal_uncertainty`` (eta: the spring law uses ``d_n cos eta + s_i sin eta``, the
worst normal within eta, as ``refinement`` does), ``motion_bound``, ``feastol`` (SCIP's
feasibility tolerance, default 1e-9 relative). Backend: SCIP only (HiGHS has no nonlinear
rows).

Every answer is checked against the exact conditions (the linear model's, the cone and
maximum dissipation) before it is returned: one that fails them beyond ``1e-6 (1 + B)``
(B the force bound) is ``status="error"``, never a silent wrong answer. This is global
optimisation: exact up to SCIP's tolerances, and its time grows quickly with the number of
contacts (``python -m stability.bench tradeoff``).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._mipcommon import CONDITIONS, MipOptions, Stop, bounds_stats, solution, stopped
from .api import register
from .errors import GraspError, MethodError
from .exact import ExactProblem, length_scale, scale_bounds
from .grasp import Grasp
from .mip import INF, MipResult
from .mip.model import Row
from .queries import Existence, MaxDisturbance, OptimalCommands
from .refinement import _Data, _value, add_query
from .solution import Solution

__all__: list[str] = []

_SPATIAL_OPTIONS = ("normal_uncertainty", "motion_bound", "feastol", "gap")


class _Exact:
    """The exact model: ExactProblem (no friction polygon) plus the tangential motions
    ``d_t`` (``self.dt``, (m, 2)) and slide bounds ``s`` (``self.slide``) as linear
    variables; the nonlinear rows are added on SCIP's model by :meth:`scip_model`."""

    def __init__(self, grasp: Grasp, data: _Data, bounds: Any, eta: float,
                 motion_bound: float) -> None:  # fmt: skip
        self.grasp, self.eta = grasp, eta
        prob = ExactProblem(grasp, data.preload, data.hand, bounds, friction=False,
                            name="spatial", command_range=data.command_range)  # fmt: skip
        self.prob = prob
        M, m, B = prob.model, grasp.m, bounds.force
        if data.max_normal_force is not None:
            for j in prob.c[:, 0]:
                M.ub[j] = min(M.ub[j], data.max_normal_force)
        D = self.D = motion_bound * 2.0 * B
        self.dt = M.add_vars(2 * m, -D, D, "C", "dt").reshape(m, 2)
        self.slide = M.add_vars(m, 0.0, math.sqrt(2.0) * D, "C", "slide")
        # the motions in the same box: translations D, rotations D / L, joints D / |J_j|
        L = length_scale(grasp)
        for k, j in enumerate(prob.r):
            M.lb[j], M.ub[j] = (-D, D) if k < 3 else (-D / L, D / L)
        if prob.q is not None:
            cols = np.linalg.norm(prob.J, axis=0)
            for k, j in enumerate(prob.q):
                lim = D / cols[k] if cols[k] > 0 else D
                M.lb[j], M.ub[j] = -lim, lim
        Gt = prob.G.T.reshape(m, 3, -1)
        Jt = None if prob.J is None else prob.J.reshape(m, 3, -1)
        for i in range(m):
            for t in range(2):  # d_t - G_t^T r + J_t q = 0
                idx, val = prob._extend([int(self.dt[i, t])], [-1.0], prob.r, Gt[i, 1 + t])
                if Jt is not None:
                    idx, val = prob._extend(idx, val, prob.q, -Jt[i, 1 + t])
                M.add_row(idx, val, 0.0, 0.0, f"tangent{i}.{t}")
            # the cone's outer square, implied by the SOC: helps the first LP relaxations
            cn, ct = int(prob.c[i, 0]), prob.c[i, 1:]
            mu = float(grasp.mu[i])
            for j in ct:
                M.add_row([int(j), cn], [1.0, -mu], -INF, 0.0, f"square{i}+")
                M.add_row([int(j), cn], [1.0, mu], 0.0, INF, f"square{i}-")
        if eta > 0.0:  # d_n' = d_n cos(eta) + s sin(eta): the worst normal within eta
            cols = set(prob.r.tolist()) | (set() if prob.q is None else set(prob.q.tolist()))
            for i, r in enumerate(prob.spring_rows):
                row = M.rows[r]
                val = np.array([v * math.cos(eta) if j in cols else v
                                for j, v in zip(row.idx, row.val, strict=True)])  # fmt: skip
                M.rows[r] = Row(np.r_[row.idx, self.slide[i]].astype(np.int64),
                                np.r_[val, math.sin(eta)], row.lo, row.hi, row.name)  # fmt: skip

    def scip_model(
        self, time_limit: float | None, verbose: bool, feastol: float, gap: float
    ) -> tuple:
        from .mip._scip import build_scip

        m, x = build_scip(self.prob.model, time_limit, verbose, gap)
        m.setParam("numerics/feastol", feastol)
        g, c = self.grasp, self.prob.c
        for i in range(g.m):
            mu = float(g.mu[i])
            cn, t1, t2 = (x[int(j)] for j in c[i])
            d1, d2 = (x[int(j)] for j in self.dt[i])
            s = x[int(self.slide[i])]
            m.addCons(t1 * t1 + t2 * t2 <= mu * mu * cn * cn, name=f"cone{i}")
            m.addCons(d1 * d1 + d2 * d2 <= s * s, name=f"slide{i}")
            m.addCons(t1 * d1 + t2 * d2 + mu * cn * s <= 0.0, name=f"dissipation{i}")
        return m, x

    def violations(self, xv: NDArray[np.float64]) -> dict[str, float]:
        """The linear model's exact-condition violations plus ``cone`` (``|c_t| - mu c_n``)
        and ``dissipation`` (``c_t . d_t + mu c_n |d_t|`` with the true ``|d_t|``)."""
        out = self.prob.model.violations(xv)
        c = xv[self.prob.c]
        dt = xv[self.dt]
        ctn = np.linalg.norm(c[:, 1:], axis=1)
        out["cone"] = float(np.max(ctn - self.grasp.mu * c[:, 0], initial=0.0))
        diss = np.einsum("ij,ij->i", c[:, 1:], dt) + self.grasp.mu * c[:, 0] * np.linalg.norm(
            dt, axis=1
        )
        out["dissipation"] = float(np.max(np.abs(diss), initial=0.0))
        return out


def _solve_exact(grasp: Grasp, query: Any, **options: Any) -> Solution:
    got = {k: options.pop(k) for k in list(options) if k in _SPATIAL_OPTIONS}
    eta = float(got.get("normal_uncertainty", 0.0))
    if not (math.isfinite(eta) and 0.0 <= eta < math.pi / 2):
        raise GraspError(f"normal_uncertainty must be in [0, pi/2) rad, got {eta!r}")
    motion_bound = float(got.get("motion_bound", 4.0))
    if not (math.isfinite(motion_bound) and motion_bound >= 1.0):
        raise GraspError(f"motion_bound must be a finite number >= 1, got {motion_bound!r}")
    feastol = float(got.get("feastol", 1e-6))
    if not (math.isfinite(feastol) and 0.0 < feastol <= 1e-3):
        raise GraspError(f"feastol must be in (0, 1e-3], got {feastol!r}")
    gap = float(got.get("gap", 1e-4))
    if not (math.isfinite(gap) and 0.0 <= gap < 0.5):
        raise GraspError(f"gap must be in [0, 0.5), got {gap!r}")
    if options.get("backend") not in (None, "scip"):
        raise MethodError(
            f"method 'spatial' needs SCIP's spatial branch-and-bound (backend='scip'), got "
            f"backend={options['backend']!r}: HiGHS has no nonlinear constraints"
        )
    options["backend"] = "scip"
    opts = MipOptions.of("spatial", options)
    if grasp.planar:
        raise GraspError("method 'spatial' takes spatial grasps; use 'planar' for planar ones")
    data = _Data.of(grasp, query, opts.bound_factor)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"backend": "scip", "normal_uncertainty": eta, "feastol": feastol}
    bounds_stats(bounds, stats)
    conditions = CONDITIONS + ("max_dissipation",)
    if eta > 0:
        conditions = tuple(c for c in conditions if c != "spring_law")
    t0 = time.perf_counter()
    ex = _Exact(grasp, data, bounds, eta, motion_bound)
    var = add_query(ex.prob, data)
    try:
        res = _run(ex, opts, feastol, gap, stats)
    except Stop as e:
        return stopped("spatial", grasp, query, stats, e)
    finally:
        stats["solve_time_s"] = time.perf_counter() - t0
    if res is None:
        if data.direction is not None:
            stats["capped"] = False
        return solution("spatial", grasp, query, False, stats, conditions=conditions)
    pt = ex.prob.point(res)
    pt.at_bound = pt.at_bound or bool(np.any(np.abs(res[ex.dt]) >= 0.99 * ex.D))
    value = _value(ex, pt, var, data)
    if data.direction is not None:
        stats["capped"] = value >= data.cap * (1 - 1e-8)
    sol = solution("spatial", grasp, query, True, stats, ex.prob, pt, value,
                   conditions=conditions)  # fmt: skip
    if data.command_range is not None:
        sol.commands = pt.x[ex.prob.fc]
    return sol


def _run(ex: _Exact, opts: MipOptions, feastol: float, gap: float,
         stats: dict[str, Any]) -> NDArray[np.float64] | None:  # fmt: skip
    """Solve; the point (None: infeasible), :class:`Stop` on a time-out or an error."""
    from .mip._scip import optimize_scip

    t0 = time.perf_counter()
    try:
        m, x = ex.scip_model(opts.time_limit, opts.verbose, feastol, gap)
        raw = optimize_scip(m, x, ex.prob.model, t0)
    except Exception as e:  # noqa: BLE001  (a solver's internal failure is a status)
        raise Stop("error", f"scip failed: {type(e).__name__}: {e}") from None
    res = MipResult(raw["status"], "scip", raw["x"], raw["objective"], raw["bound"],
                    raw["time_s"], raw["nodes"], raw["message"])  # fmt: skip
    stats["mips"] = 1
    stats["mip_time_s"] = res.time_s
    stats["nodes"] = res.nodes
    stats["dual_bound"] = res.bound
    if res.status in ("infeasible", "infeasible_or_unbounded"):
        return None
    if res.status == "timeout":
        stats["incumbent"] = res.objective
        raise Stop("timeout", f"time_limit {opts.time_limit} s reached ({res.message}; "
                   f"incumbent {res.objective}, dual bound {res.bound})")  # fmt: skip
    if res.status == "optimal" and res.x is not None:
        x = _polish(ex, res.x, gap, stats)
        viol = ex.violations(x)
        stats["violations"] = viol
        # force conditions within 1e-6 of the force bound; dissipation (force x motion)
        # within that times the motion's scale
        B = ex.prob.bounds.force
        dmax = 1.0 + float(np.abs(x[ex.dt]).max(initial=0.0))
        lim = {k: 1e-6 * (1.0 + B) * (dmax if k == "dissipation" else 1.0) for k in viol}
        bad = {k: v for k, v in viol.items() if v > lim[k]}
        if bad:
            raise Stop("error", f"SCIP's answer fails the exact conditions {bad}")
        return x
    raise Stop("error", f"scip: {res.status}: {res.message}")


def _polish(
    ex: _Exact, x: NDArray[np.float64], gap: float, stats: dict[str, Any]
) -> NDArray[np.float64]:
    """SCIP's point made exact and tidy. With the binaries and each loaded contact's mode
    fixed at SCIP's, every condition is linear:

    * friction on the cone's boundary (``|c_t| >= (1 - 1e-4) mu c_n``): a slide direction
      ``u``, ``d_t = sigma u``, ``s = sigma >= 0``, ``c_t = -mu c_n u``
      (sliding, or about to);
    * friction inside: ``d_t = 0``, ``s = 0``, ``c_t = kappa v`` with ``v`` SCIP's friction
      direction and ``0 <= kappa <= mu c_n`` (sticking);
    * unloaded (``c_n = 0``): ``c = 0``; the slide is free (its direction fixed when
      ``eta > 0``, where ``s`` enters the spring law).

    The LP optimises the query's objective over that, then :meth:`ExactProblem.tidy` takes
    its least virtual motion (spatial branch-and-bound leaves a slide's free scale anywhere
    in the box). The slide direction comes from SCIP's motion, or else from its friction
    (:func:`_polish_lp`); ``stats["polished"]`` says which. SCIP's point is kept when both
    LPs fail or are worse by more than the gap."""
    stats["polished"] = False
    for source in ("motion", "force"):
        got = _polish_lp(ex, x, source)
        if got is None:
            continue
        lp, res = got
        M = ex.prob.model
        old, new = M.objective_value(x), M.objective_value(res.x[: M.n_vars])
        worse = (old - new) if M.maximize else (new - old)
        if worse > (gap + 1e-6) * (1.0 + abs(old)):
            continue
        y = ex.prob.tidy(res.x, lp=lp)
        y = (res.x if y is None else y)[: M.n_vars]
        if max(ex.violations(y).values()) <= 1e-7 * (1.0 + ex.prob.bounds.force):
            stats["polished"] = source
            return y
    return x


def _polish_lp(ex: _Exact, x: NDArray[np.float64], source: str) -> tuple[Any, Any] | None:
    """The LP of :func:`_polish` with the slide directions of sliding contacts taken from
    SCIP's motion (``source="motion"``: ``u = d_t / |d_t|`` where the contact clearly moves)
    or from its friction (``"force"``: ``u = -c_t / |c_t|``), and its optimum; None when it
    has none. The two differ by SCIP's tolerance, which one of them may not absorb."""
    from .mip import solve as mip_solve

    prob, g = ex.prob, ex.grasp
    M = prob.model
    lp = M.fixed(x)
    c, dt = x[prob.c], x[ex.dt]
    dscale = 1e-7 * (1.0 + float(np.abs(dt).max(initial=0.0)))
    fscale = 1e-7 * (1.0 + float(np.abs(c).max(initial=0.0)))

    def slide(i: int, u: NDArray[np.float64]) -> None:  # d_t = sigma u, s = sigma >= 0
        sig = lp.add_var(0.0, INF, "C", f"sigma{i}")
        for t in range(2):
            lp.add_row([int(ex.dt[i, t]), sig], [1.0, -float(u[t])], 0.0, 0.0)
        lp.add_row([int(ex.slide[i]), sig], [1.0, -1.0], 0.0, 0.0)

    def fix(js: Any) -> None:
        for j in js:
            lp.lb[int(j)] = lp.ub[int(j)] = 0.0

    for i in range(g.m):
        ci, ti = int(prob.c[i, 0]), [int(j) for j in prob.c[i, 1:]]
        mu, cn = float(g.mu[i]), float(c[i, 0])
        nt, nd = float(np.linalg.norm(c[i, 1:])), float(np.linalg.norm(dt[i]))
        if cn <= fscale:  # unloaded
            fix(prob.c[i])
            if ex.eta > 0.0:
                if nd > dscale:
                    slide(i, dt[i] / nd)
                else:
                    fix((*ex.dt[i], ex.slide[i]))
        elif nt >= (1.0 - 1e-4) * mu * cn:  # on the boundary: slides along u (or is about to)
            moves = nd > 1e3 * dscale
            u = dt[i] / nd if source == "motion" and moves else -c[i, 1:] / nt
            slide(i, u)
            for t in range(2):  # c_t = -mu c_n u
                lp.add_row([ti[t], ci], [1.0, mu * float(u[t])], 0.0, 0.0)
        else:  # inside: sticks
            fix((*ex.dt[i], ex.slide[i]))
            if nt > fscale:
                kap = lp.add_var(0.0, INF, "C", f"kappa{i}")
                for t in range(2):
                    lp.add_row([ti[t], kap], [1.0, -float(c[i, 1 + t] / nt)], 0.0, 0.0)
                lp.add_row([kap, ci], [1.0, -mu], -INF, 0.0)
            else:
                fix(ti)
    res = mip_solve(lp, backend="highs", polish=False)
    if res.status != "optimal" or res.x is None:
        return None
    return lp, res


@register(
    "spatial",
    queries=(Existence, MaxDisturbance, OptimalCommands),
    planar=False,
    spatial=True,
    hand=True,
    summary="exact nonconvex problem (circular cone, bilinear maximum dissipation) solved "
    "globally by SCIP's spatial branch-and-bound: the accuracy reference for small grasps",
)
def _solve_spatial(grasp: Grasp, query: Any, **options: Any) -> Solution:
    return _solve_exact(grasp, query, **options)
