"""The exact problem with Coulomb friction and maximum dissipation, stated for any query:
shared by ``exact`` (solved globally by SCIP) and ``refinement`` (whose relaxed answers
:mod:`~stability.model.slides` certifies, or repairs, as exact solutions).

:class:`CoulombModel`: the exact model's linear part, an
:class:`~stability.model.problem.ExactProblem` without friction polygon plus the tangential
motions ``d_t`` and slide bounds ``s`` as variables (the nonlinear rows, circular cone and
maximum dissipation, go on SCIP's model: :meth:`CoulombModel.scip_model`). The query's
equilibrium and objective come from :func:`stability.model.query.add_query`.
:func:`mode_lp` / :func:`polish`: with each contact's mode (open, sticking, sliding along
``u``) fixed, the exact problem is one LP: a point of it satisfies every condition exactly.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..grasp import Grasp
from ..mip import INF, build_scip
from ..mip import solve as mip_solve
from ..mip.model import Row
from .problem import ExactProblem, length_scale
from .query import QueryData
from .run import CONDITIONS

__all__ = [
    "CoulombModel",
    "exact_conditions",
    "exact_point",
    "mode_lp",
    "mode_scales",
    "polish",
]


def exact_conditions(eta: float) -> tuple[str, ...]:
    """The :func:`~stability.solution.model_residuals` keys an exact answer satisfies: all,
    maximum dissipation included, as a product (``max_dissipation``) and as friction aligned
    against each slide (``slide_alignment``); with a normal uncertainty ``eta > 0`` the
    spring law of the *nominal* normals is not what was solved, so not ``spring_law``."""
    out = (*CONDITIONS, "max_dissipation", "slide_alignment")
    return out if eta == 0 else tuple(c for c in out if c != "spring_law")


class CoulombModel:
    """The exact model with Coulomb friction and maximum dissipation: ExactProblem (no
    friction polygon) plus the tangential motions ``d_t`` (``self.dt``, (m, 2)) and slide
    bounds ``s`` (``self.slide``) as linear variables; the nonlinear rows (circular cone,
    ``|d_t| <= s``, ``c_t . d_t + mu c_n s <= 0``) are added on SCIP's model by
    :meth:`scip_model`."""

    def __init__(self, grasp: Grasp, data: QueryData, bounds: Any, eta: float,
                 motion_bound: float) -> None:  # fmt: skip
        self.grasp, self.eta = grasp, eta
        prob = ExactProblem(grasp, data.preload, data.hand, bounds, friction=False,
                            name="exact", command_range=data.command_range)  # fmt: skip
        self.prob = prob
        M, m = prob.model, grasp.m
        if data.max_normal_force is not None:
            for j in prob.c[:, 0]:
                M.ub[j] = min(M.ub[j], data.max_normal_force)
        D = self.D = motion_bound * bounds.displacement
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
                idx, val = prob.extend([int(self.dt[i, t])], [-1.0], prob.r, Gt[i, 1 + t])
                if Jt is not None:
                    idx, val = prob.extend(idx, val, prob.q, -Jt[i, 1 + t])
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
                                np.r_[val, grasp.stiffness[i] * math.sin(eta)], row.lo, row.hi,
                                row.name)  # fmt: skip

    def scip_model(
        self, time_limit: float | None, verbose: bool, feastol: float, gap: float
    ) -> tuple:
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
            if self.eta > 0.0:  # s enters the spring law: it must be |d_t| itself, also
                # where the contact is unloaded (nonconvex; SCIP branches on it)
                m.addCons(s * s <= d1 * d1 + d2 * d2, name=f"slide{i}.exact")
            m.addCons(t1 * d1 + t2 * d2 + mu * cn * s <= 0.0, name=f"dissipation{i}")
        return m, x

    def free_motion(self, model: Any) -> None:
        """Lift the box on the motions (``r``, ``q``, ``d_t``, ``s``, ``v``) of ``model`` (this
        model or an LP with its variables): a point of the exact problem may lie beyond it."""
        prob = self.prob
        for j in [*prob.r, *self.dt.reshape(-1), *([] if prob.q is None else prob.q)]:
            model.lb[int(j)], model.ub[int(j)] = -INF, INF
        for j in [*self.slide, *([] if prob.v is None else prob.v)]:
            model.ub[int(j)] = INF

    def violations(self, xv: NDArray[np.float64], box: bool = True) -> dict[str, float]:
        """The linear model's exact-condition violations plus ``cone`` (``|c_t| - mu c_n``)
        and ``dissipation`` (``c_t . d_t + mu c_n |d_t|`` with the true ``|d_t|``);
        ``box=False`` ignores the box on the motions (:meth:`free_motion`)."""
        model = self.prob.model
        if not box:
            model = copy.copy(model)
            model.lb, model.ub = list(model.lb), list(model.ub)
            self.free_motion(model)
        out = model.violations(xv)
        c = xv[self.prob.c]
        dt = xv[self.dt]
        ctn = np.linalg.norm(c[:, 1:], axis=1)
        out["cone"] = float(np.max(ctn - self.grasp.mu * c[:, 0], initial=0.0))
        diss = np.einsum("ij,ij->i", c[:, 1:], dt) + self.grasp.mu * c[:, 0] * np.linalg.norm(
            dt, axis=1
        )
        out["dissipation"] = float(np.max(np.abs(diss), initial=0.0))
        if self.eta > 0.0:  # the robust spring law uses s: it must equal |d_t|
            gap = np.abs(xv[self.slide] - np.linalg.norm(dt, axis=1))
            out["slide"] = float(np.max(gap, initial=0.0))
        return out


def polish(
    ex: CoulombModel, x: NDArray[np.float64], gap: float, stats: dict[str, Any]
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
    (:func:`mode_lp`); ``stats["polished"]`` says which. SCIP's point is kept when both
    LPs fail or are worse by more than the gap."""
    got = exact_point(ex, x, ("motion", "force"), gap)
    stats["polished"] = False if got is None else got[1]
    return x if got is None else got[0]


def exact_point(
    ex: CoulombModel, x: NDArray[np.float64], sources: tuple[str, ...], gap: float | None = None
) -> tuple[NDArray[np.float64], str] | None:
    """The least-motion optimum of the first :func:`mode_lp` (by ``sources``) that has one,
    satisfies every exact condition (within ``1e-7 (1 + B)``) and, with ``gap``, is no worse
    than ``x``'s objective by more than ``gap`` relative; with the source used. None if
    none does."""
    M = ex.prob.model
    for source in sources:
        got = mode_lp(ex, x, source)
        if got is None:
            continue
        lp, res = got
        if gap is not None:
            old, new = M.objective_value(x), M.objective_value(res.x[: M.n_vars])
            worse = (old - new) if M.maximize else (new - old)
            if worse > (gap + 1e-6) * (1.0 + abs(old)):
                continue
        y = ex.prob.tidy(res.x, lp=lp)
        y = (res.x if y is None else y)[: M.n_vars]
        if max(ex.violations(y).values()) <= 1e-7 * (1.0 + ex.prob.bounds.force):
            return y, source
    return None


def mode_scales(ex: CoulombModel, x: NDArray[np.float64]) -> tuple[float, float]:
    """``(dscale, fscale)``: the motion [m] and force [N] below which ``x``'s tangential
    motions and contact forces count as zero, ``1e-7 (1 + max |.|)`` of each."""
    c, dt = x[ex.prob.c], x[ex.dt]
    dscale = 1e-7 * (1.0 + float(np.abs(dt).max(initial=0.0)))
    fscale = 1e-7 * (1.0 + float(np.abs(c).max(initial=0.0)))
    return dscale, fscale


def mode_lp(ex: CoulombModel, x: NDArray[np.float64], source: str) -> tuple[Any, Any] | None:
    """The LP of :func:`polish` (each contact's mode fixed at ``x``'s) and its optimum;
    None when it has none. Contacts with friction on the cone's boundary slide along
    ``x``'s motion (``source="motion"``: ``u = d_t / |d_t|`` where the contact clearly
    moves) or against its friction (``"force"``: ``u = -c_t / |c_t|``); SCIP's two differ by
    its tolerance, which one of them may not absorb. (A relaxation's answer is made exact
    by :func:`~stability.model.slides.certify` instead, whose slide directions are variables.)"""
    prob, g = ex.prob, ex.grasp
    M = prob.model
    lp = M.fixed(x)
    c, dt = x[prob.c], x[ex.dt]
    dscale, fscale = mode_scales(ex, x)

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
