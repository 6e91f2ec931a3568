"""Exact points with each contact's mode fixed, over the slide directions: the certificates
of ``refinement``'s relaxed answers and ``modesearch``'s polish.

:func:`slide_search`: the best exact point with a point's contact modes (open; sticking,
friction in :func:`inscribed_friction`'s polygon; sliding at an angle), the slide angles
moved by sequential linear programming on the mode LP (:func:`_modes_lp`).
:func:`certify`: an exact solution near a relaxation's answer (:func:`slide_search` with
each of :data:`CERTIFY_TRIES`' mode transfers in turn). :func:`stuck_point`: the query's
optimum with every contact sticking and every actuator locked, one LP.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..grasp import Grasp
from ..mip import INF
from ..mip import solve as mip_solve
from .coulomb import CoulombModel, mode_scales
from .problem import ExactBounds, ExactPoint, ExactProblem
from .query import QueryData, add_query, query_value

__all__ = [
    "CERTIFY_TRIES",
    "certify",
    "slide_search",
    "stuck_point",
]


def certify(
    grasp: Grasp, data: QueryData, bounds: ExactBounds, relaxed: ExactProblem,
    x: NDArray[np.float64], var: int | None, eta: float, motion_bound: float,
    target: float | None = None, gap: float = 0.0,
) -> tuple[CoulombModel, ExactPoint, float | None] | None:  # fmt: skip
    """An exact solution near a relaxation's answer ``x`` (of ``relaxed``'s model, ``var``
    its query variable): each contact keeps the relaxation's mode (open; sliding; sticking)
    and the exact problem with those modes is solved for the query's optimum over the slide
    directions (:func:`slide_search`, at most :data:`CERTIFY_STEPS` LP pairs, stopping
    early once the value is within ``gap`` of ``target``, the relaxation's bound). Returns
    the exact model, its point and query value, or None when no exact solution with those
    modes was found. A certificate: Existence is then stable; a MaxDisturbance's value is a
    lower bound on the exact optimum (the relaxation's an upper one); an OptimalCommands' an
    upper bound."""
    ex = CoulombModel(grasp, data, bounds, eta, motion_bound)
    qvar = add_query(ex.prob, data)
    prob = ex.prob
    if prob.n_base != relaxed.n_base:
        raise AssertionError("certify: the exact and relaxed models' base variables differ")
    y = np.zeros(prob.model.n_vars)
    y[: prob.n_base] = x[: relaxed.n_base]
    d = prob.G.T @ y[prob.r]
    if prob.J is not None:
        d = d - prob.J @ y[prob.q]
    dt = d.reshape(grasp.m, 3)[:, 1:]
    y[ex.dt] = dt
    y[ex.slide] = np.linalg.norm(dt, axis=1)
    if qvar is not None and qvar >= 0 and var is not None and var >= 0:
        y[qvar] = x[var]
    got = None
    for promote, source in CERTIFY_TRIES:  # the first that gives an exact point
        got = slide_search(ex, y, target, gap, CERTIFY_STEPS, promote=promote, source=source)
        if got is not None:
            break
    if got is None:
        return None
    pt = prob.point(got)
    return ex, pt, query_value(ex, pt, qvar, data)


def stuck_point(
    grasp: Grasp, data: QueryData, bounds: ExactBounds, eta: float, motion_bound: float,
) -> tuple[CoulombModel, ExactPoint, float | None] | None:  # fmt: skip
    """The query's optimum with every contact closed and sticking and every actuator locked
    (one LP, friction in :func:`inscribed_friction`'s polygon): an exact solution when there
    is one, as :func:`certify` returns it; None otherwise. A cheap first certificate: a
    grasp that holds without slipping needs no MIP to say "stable", and a MaxDisturbance
    starts from its value as a lower bound."""
    ex = CoulombModel(grasp, data, bounds, eta, motion_bound)
    qvar = add_query(ex.prob, data)
    prob = ex.prob
    x = np.zeros(prob.model.n_vars)
    x[prob.y] = 1.0
    if prob.z is not None:
        x[prob.z] = np.where(prob.backdrivable, 0.0, 1.0)  # a backdrivable actuator never locks
    x[prob.c[:, 0]] = 1.0  # loaded: "stick" below, not "open"
    modes = [("stick", 0.0)] * grasp.m
    lp = _modes_lp(ex, x, modes, {})
    res = mip_solve(lp, backend="highs", polish=False)
    if res.status != "optimal" or res.x is None:
        return None
    y = prob.tidy(res.x, lp=lp)
    y = (res.x if y is None else y)[: prob.model.n_vars]
    if max(ex.violations(y, box=False).values()) > 1e-7 * (1.0 + bounds.force):
        return None
    pt = prob.point(y)
    return ex, pt, query_value(ex, pt, qvar, data)


def slide_search(
    ex: CoulombModel, x: NDArray[np.float64], target: float | None = None, gap: float = 0.0,
    steps: int = 8, promote: bool = False, source: str = "motion",
) -> NDArray[np.float64] | None:  # fmt: skip
    """The best exact point with ``x``'s contact modes, over the slide directions.

    ``source``: where a sliding contact's first slide angle comes from, its motion ``d_t``
    (``"motion"``) or its friction, ``-c_t`` (``"force"``). A relaxation's motion and
    friction share a sector but can differ within it, and only one of them may admit an
    exact point with the other contacts' modes (the MuJoCo Barrett cube pushed along +z with
    the thumb unloaded: a finest-level answer's slide gives an infeasible mode LP, its
    friction's angle an exact point; tests/stability/test_refinement.py).

    ``promote``: a contact that sticks in ``x`` with friction within :data:`PROMOTE_RTOL`
    of the cone's boundary slides instead, at the angle of ``-c_t`` (``sigma_i >= 0``: it
    may still stick, with friction on the boundary). A relaxation's answer can stick a
    contact at the cone's edge that the exact optimum slides by a little.

    Modes from ``x`` (binaries fixed): a contact without normal force is open (``c = 0``),
    one whose tangential motion ``d_t`` is nonzero slides at angle ``phi_i`` (``d_t =
    sigma_i u(phi_i)``, ``c_t = -mu c_n u(phi_i)``, ``sigma_i >= 0``), the others stick
    (``d_t = 0``, friction in :func:`inscribed_friction`'s polygon). With the angles fixed
    that is an LP whose points satisfy every exact condition (:func:`_modes_lp`). The
    angles start at ``x``'s slide directions and move by sequential linear programming: the
    LP linearised in ``delta_i`` about the last exact point (``c_t = -mu (c_n u +
    c_n^0 delta u_perp)``, ``d_t = sigma u + sigma^0 delta u_perp``) within a trust radius
    ``|delta| <= rho``, then the exact LP at ``phi + delta``, elastic in misaligned friction
    (``c_t = -mu c_n u + e u_perp``, ``|e|`` penalised by :data:`ELASTIC_PENALTY` per
    newton), accepted when that merit does not get worse (else ``rho`` shrinks by 4); then
    up to :data:`RESTORE_STEPS` Newton steps (least ``|delta|`` that aligns friction to
    first order) put the point back on the exact modes. A point counts as exact when its
    misalignment is below ``1e-9 (1 + B)``. The least-motion point of the best one
    (:meth:`ExactProblem.tidy`) is returned, checked against the exact conditions within
    ``1e-7 (1 + B)`` (motions unboxed); None if none was found."""
    prob = ex.prob
    search = _SlideSearch(ex, x, _read_modes(ex, x, promote, source), target, gap)
    phi = {i: search.modes[i][1] for i in search.sliding}
    cur = search.exact_lp(phi)
    if cur is None:
        return None
    if search.rehint(cur.x):
        cur = search.exact_lp(phi) or cur
    search.best = cur if cur.misalignment <= search.feas else None
    search.best_phi = dict(phi)
    cur, phi = search.descend(cur, phi, steps)
    search.restore(cur, phi)
    search.refine_best()
    if search.best is None:
        return None
    lp, xb = search.best.lp, search.best.x
    for j in lp.elastic:  # the misalignment, below feas, is none
        lp.lb[int(j)] = lp.ub[int(j)] = 0.0
    n = prob.model.n_vars
    y = prob.tidy(xb, lp=lp)
    y = (xb if y is None else y)[:n]
    if max(ex.violations(y, box=False).values()) > search.tol:
        y = xb[:n]
        if max(ex.violations(y, box=False).values()) > search.tol:
            return None
    return y


def _read_modes(
    ex: CoulombModel, x: NDArray[np.float64], promote: bool, source: str
) -> list[tuple[str, float]]:
    """Each contact's mode in ``x`` with its angle [rad] (:func:`slide_search`): ``("open",
    angle of d_t or nan)`` without normal force; ``("slide", angle of d_t)`` (or of
    ``-c_t`` with ``source="force"``) where ``d_t`` is nonzero; ``("slide", angle of
    -c_t)`` where ``promote`` and friction lies within :data:`PROMOTE_RTOL` of the cone;
    else ``("stick", angle of c_t or 0)``, the friction hint of
    :func:`inscribed_friction`."""
    g = ex.grasp
    c, dt = x[ex.prob.c], x[ex.dt]
    dscale, fscale = mode_scales(ex, x)
    modes: list[tuple[str, float]] = []
    for i in range(g.m):
        nt, nd = float(np.linalg.norm(c[i, 1:])), float(np.linalg.norm(dt[i]))
        if c[i, 0] <= fscale:
            modes.append(("open", math.atan2(dt[i, 1], dt[i, 0]) if nd > dscale else math.nan))
        elif nd > dscale and source == "force" and nt > fscale:
            modes.append(("slide", math.atan2(-c[i, 2], -c[i, 1])))
        elif nd > dscale:
            modes.append(("slide", math.atan2(dt[i, 1], dt[i, 0])))
        elif promote and nt >= (1.0 - PROMOTE_RTOL) * float(g.mu[i]) * c[i, 0]:
            modes.append(("slide", math.atan2(-c[i, 2], -c[i, 1])))
        else:
            modes.append(("stick", math.atan2(c[i, 2], c[i, 1]) if nt > fscale else 0.0))
    return modes


class _ModePoint(NamedTuple):
    """The optimum of :func:`_modes_lp` (elastic) at fixed slide angles."""

    lp: Any  # the LP solved
    x: NDArray[np.float64]  # its optimum (the LP's variables, the model's first)
    value: float  # the query's objective, larger is better (0 for Existence)
    misalignment: float  # sum of the elastic friction misalignments [N]

    def merit(self) -> float:
        """``value - ELASTIC_PENALTY * misalignment``: what a trust-region step must not
        make worse."""
        return self.value - ELASTIC_PENALTY * self.misalignment


class _SlideSearch:
    """The state of one :func:`slide_search`: the contacts' ``modes`` (sticking contacts'
    friction hints move, :meth:`rehint`), the best exact point so far (``best``, at slide
    angles ``best_phi``) and the tolerances: ``feas`` [N], the misalignment taken as none,
    ``1e-9 (1 + B)``; ``tol``, the exact conditions' ``1e-7 (1 + B)``."""

    def __init__(
        self, ex: CoulombModel, x: NDArray[np.float64], modes: list[tuple[str, float]],
        target: float | None, gap: float,
    ) -> None:  # fmt: skip
        M = ex.prob.model
        self.ex, self.x, self.modes, self.target, self.gap = ex, x, modes, target, gap
        self.sliding = [i for i, (mode, _) in enumerate(modes) if mode == "slide"]
        self.fscale = mode_scales(ex, x)[1]
        self.has_obj = bool(np.any(M.objective))
        self.sign = 1.0 if M.maximize else -1.0
        self.tol = 1e-7 * (1.0 + ex.prob.bounds.force)
        self.feas = 1e-9 * (1.0 + ex.prob.bounds.force)  # misalignment [N] taken as none
        self.best: _ModePoint | None = None
        self.best_phi: dict[int, float] = {}

    def exact_lp(self, angles: dict[int, float]) -> _ModePoint | None:
        """The elastic mode LP's optimum at slide angles ``angles``; None if it has none."""
        M = self.ex.prob.model
        lp = _modes_lp(self.ex, self.x, self.modes, angles, elastic=ELASTIC_PENALTY)
        res = mip_solve(lp, backend="highs", polish=False)
        if res.status != "optimal" or res.x is None:
            return None
        mis = float(np.sum(res.x[lp.elastic])) if lp.elastic else 0.0
        val = self.sign * M.objective_value(res.x[: M.n_vars]) if self.has_obj else 0.0
        return _ModePoint(lp, res.x, val, mis)

    def done(self, got: _ModePoint | None) -> bool:
        """``got`` is exact and (with a target) within ``gap`` of it."""
        if got is None or got.misalignment > self.feas:
            return False
        if self.target is None or not self.has_obj:
            return True
        t = self.target
        return got.value >= self.sign * t - self.gap * (1.0 + abs(t)) - 1e-12

    def keep(self, got: _ModePoint, phi: dict[int, float]) -> None:
        """``got`` (at angles ``phi``) as the best point when exact and no worse."""
        if got.misalignment <= self.feas and (self.best is None or got.value >= self.best.value):
            self.best, self.best_phi = got, dict(phi)

    def rehint(self, point: NDArray[np.float64]) -> bool:
        """Centre the fine polygon vertices of each sticking contact whose friction lies on
        its polygon's boundary at that friction's direction (the relaxation's hint was only
        a guess: an inscribed polygon loses up to 1 - cos(pi / 32) of the cone away from
        its fine vertices); True if any moved."""
        prob, g = self.ex.prob, self.ex.grasp
        moved = False
        for i, (mode, hint) in enumerate(self.modes):
            ct, cn = point[prob.c[i, 1:]], float(point[prob.c[i, 0]])
            if mode != "stick" or cn <= self.fscale:
                continue
            if np.linalg.norm(ct) >= (1.0 - 1e-3) * float(g.mu[i]) * cn:
                a = math.atan2(ct[1], ct[0])
                if abs(math.remainder(a - hint, 2.0 * math.pi)) > STICK_FINE[1]:
                    self.modes[i] = ("stick", a)
                    moved = True
        return moved

    def linearised_lp(
        self, ref: NDArray[np.float64], phi: dict[int, float], rho: float, restore: bool
    ) -> tuple[Any, Any]:
        """The mode LP linearised in the angle steps ``delta`` (``|delta| <= rho``) about
        the point ``ref`` at angles ``phi``, and its solution; ``restore``: least
        ``sum |delta|`` instead of the query's objective."""
        prob, dt = self.ex.prob, self.ex.dt
        lin = {i: (float(ref[prob.c[i, 0]]), float(np.linalg.norm(ref[dt[i]])))
               for i in self.sliding}  # fmt: skip
        lp = _modes_lp(self.ex, self.x, self.modes, phi, lin, rho, restore=restore)
        return lp, mip_solve(lp, backend="highs", polish=False)

    def descend(
        self, cur: _ModePoint, phi: dict[int, float], steps: int
    ) -> tuple[_ModePoint, dict[int, float]]:
        """At most ``steps`` trust-region steps of sequential linear programming on the
        slide angles from ``cur`` (at ``phi``), stopping once :meth:`done`; the last
        accepted point and its angles."""
        rho = 0.05
        for _ in range(steps if self.sliding else 0):
            if self.done(self.best):
                break
            lp, res = self.linearised_lp(cur.x, phi, rho, restore=False)
            if res.status != "optimal" or res.x is None:
                rho /= 4.0
                if rho < 1e-9:
                    break
                continue
            delta = {i: float(res.x[j]) for i, j in lp.deltas.items()}
            trial = {i: phi[i] + delta[i] for i in self.sliding}
            got = self.exact_lp(trial)
            if got is not None and got.merit() >= cur.merit() - 1e-12 * (1.0 + abs(cur.merit())):
                cur, phi = got, trial
                if self.rehint(cur.x):
                    cur = self.exact_lp(phi) or cur
                self.keep(cur, phi)
                rho = min(4.0 * rho, 0.5)
            else:
                rho /= 4.0
            if rho < 1e-9 or max(abs(v) for v in delta.values()) < 1e-12:
                break
        return cur, phi

    def restore(self, start: _ModePoint, phi: dict[int, float]) -> None:
        """Newton steps onto the exact modes' manifold (least angle change that aligns
        friction to first order) from ``start`` (at ``phi``), at most
        :data:`RESTORE_STEPS`, while the misalignment falls; quadratic convergence."""
        for _ in range(RESTORE_STEPS if self.sliding else 0):
            if start.misalignment <= self.feas:
                break
            lp, res = self.linearised_lp(start.x, phi, 0.5, restore=True)
            if res.status != "optimal" or res.x is None:
                break
            trial = {i: phi[i] + float(res.x[j]) for i, j in lp.deltas.items()}
            got = self.exact_lp(trial)
            if got is None or got.misalignment >= start.misalignment:
                break
            start, phi = got, trial
            self.keep(got, phi)

    def refine_best(self) -> None:
        """The best point's sticking friction on its polygon: the fine vertices moved
        there (:meth:`rehint`) and the LP solved again, kept while exact and no worse (at
        most 3 times)."""
        for _ in range(3):
            if self.best is None or not self.rehint(self.best.x):
                break
            got = self.exact_lp(self.best_phi)
            if got is None or got.misalignment > self.feas or got.value < self.best.value:
                break
            self.best = got


RESTORE_STEPS = 4
CERTIFY_STEPS = 8  # certify's slide_search steps (LP pairs) per mode transfer
# certify's mode transfers, in order (slide_search's promote, source): the relaxation's own
# modes and slide directions; slides along friction; and contacts stuck at the cone's edge
# sliding. Later ones run only where the earlier found no exact point.
CERTIFY_TRIES = ((False, "motion"), (False, "force"), (True, "force"))
PROMOTE_RTOL = 1e-3  # slide_search(promote=True): sticking friction this close to the cone
ELASTIC_PENALTY = 1e4  # per newton of misaligned friction, in the query's objective units


def _modes_lp(
    ex: CoulombModel, x: NDArray[np.float64], modes: list[tuple[str, float]],
    angles: dict[int, float], lin: dict[int, tuple[float, float]] | None = None,
    rho: float = 0.0, elastic: float | None = None, restore: bool = False,
) -> Any:  # fmt: skip
    """The LP of :func:`slide_search`: binaries fixed at ``x``, the contacts in ``modes``
    (``"open"``, ``"stick"`` with a friction hint angle, ``"slide"``) with slide angles
    ``angles``; with ``lin`` (per sliding contact ``(c_n^0, sigma^0)``) linearised in a
    variable ``delta_i in [-rho, rho]`` per sliding contact (``lp.deltas``: contact ->
    index)."""
    prob, g = ex.prob, ex.grasp
    lp = prob.model.fixed(x)
    lp.deltas, lp.elastic = {}, []
    if elastic is not None and not np.any(lp.objective):
        lp.maximize = False  # Existence: the least misalignment
    # the motions are free here (not in the relaxation's box): an exact point beyond the box
    # shows that the box cut the relaxation's optimum off (stability.refinement enlarges it)
    ex.free_motion(lp)

    def fix(js: Any) -> None:
        for j in js:
            lp.lb[int(j)] = lp.ub[int(j)] = 0.0

    for i, (mode, hint) in enumerate(modes):
        ci, ti = int(prob.c[i, 0]), [int(j) for j in prob.c[i, 1:]]
        di = [int(j) for j in ex.dt[i]]
        mu = float(g.mu[i])
        if mode == "open":
            fix(prob.c[i])
            if ex.eta > 0.0:  # the slide enters the spring law: keep its direction
                if math.isnan(hint):
                    fix((*di, ex.slide[i]))
                else:
                    u = (math.cos(hint), math.sin(hint))
                    sig = lp.add_var(0.0, INF, "C", f"sigma{i}")
                    for t in range(2):
                        lp.add_row([di[t], sig], [1.0, -u[t]], 0.0, 0.0)
                    lp.add_row([int(ex.slide[i]), sig], [1.0, -1.0], 0.0, 0.0)
        elif mode == "stick":
            fix((*di, ex.slide[i]))
            inscribed_friction(lp, ti, ci, mu, hint)
        else:
            th = angles[i]
            u = (math.cos(th), math.sin(th))
            up = (-math.sin(th), math.cos(th))
            sig = lp.add_var(0.0, INF, "C", f"sigma{i}")
            lp.add_row([int(ex.slide[i]), sig], [1.0, -1.0], 0.0, 0.0)
            if lin is None and elastic is not None:
                # d_t = sigma u, c_t = -mu c_n u + (e+ - e-) u_perp: misaligned friction
                # |e+ - e-| [N] is penalised (elastic), so the LP always has a point
                ep, em = lp.add_var(0.0, INF, "C", f"e+{i}"), lp.add_var(0.0, INF, "C", f"e-{i}")
                lp.elastic += [ep, em]
                pen = -elastic if lp.maximize else elastic
                lp.objective[ep] = lp.objective[em] = pen
                for t in range(2):
                    lp.add_row([di[t], sig], [1.0, -u[t]], 0.0, 0.0)
                    lp.add_row([ti[t], ci, ep, em], [1.0, mu * u[t], -up[t], up[t]], 0.0, 0.0)
            elif lin is None:
                for t in range(2):  # d_t = sigma u, c_t = -mu c_n u
                    lp.add_row([di[t], sig], [1.0, -u[t]], 0.0, 0.0)
                    lp.add_row([ti[t], ci], [1.0, mu * u[t]], 0.0, 0.0)
            else:
                cn0, sig0 = lin[i]
                dl = lp.add_var(-rho, rho, "C", f"delta{i}")
                lp.deltas[i] = dl
                if restore:  # objective: sum |delta| (set below)
                    ab = lp.add_var(0.0, INF, "C", f"|delta{i}|")
                    lp.add_row([ab, dl], [1.0, -1.0], 0.0, INF)
                    lp.add_row([ab, dl], [1.0, 1.0], 0.0, INF)
                    lp.restore_terms = [*getattr(lp, "restore_terms", []), ab]
                for t in range(2):
                    lp.add_row([di[t], sig, dl], [1.0, -u[t], -sig0 * up[t]], 0.0, 0.0)
                    lp.add_row([ti[t], ci, dl], [1.0, mu * u[t], mu * cn0 * up[t]], 0.0, 0.0)
    if restore:
        terms = getattr(lp, "restore_terms", [])
        lp.set_objective(terms, np.ones(len(terms)))
    return lp


STICK_VERTICES = 32  # the inscribed polygon's uniform vertices (a sticking contact)
STICK_FINE = (8, 2.0 * math.pi / 2048)  # and 2 x 8 more this far apart about the hint [rad]


def inscribed_friction(lp: Any, ti: list[int], ci: int, mu: float, phi: float) -> None:
    """``c_t`` (variables ``ti``) in the polygon inscribed in the cone ``|c_t| <= mu c_n``
    (``ci``) with :data:`STICK_VERTICES` uniform vertices and :data:`STICK_FINE` more about
    direction ``phi`` [rad]: ``c_t = sum_k lambda_k v_k``, ``sum lambda <= mu c_n``,
    ``lambda >= 0`` with ``v_k`` unit vectors. Every such ``c_t`` lies in the exact cone; the
    fine vertices keep a friction force near ``phi`` (the relaxation's) within
    ``1 - cos(pi / 2048)`` (1e-6) of the boundary."""
    n, step = STICK_FINE
    th = np.r_[2.0 * math.pi * np.arange(STICK_VERTICES) / STICK_VERTICES,
               phi + step * np.arange(-n, n + 1)]  # fmt: skip
    lam = lp.add_vars(th.size, 0.0, INF, "C", "lambda")
    for t, f in enumerate((np.cos, np.sin)):
        lp.add_row([ti[t], *lam], [1.0, *(-f(th))], 0.0, 0.0)
    lp.add_row([*lam, ci], [1.0] * th.size + [-mu], -INF, 0.0)
