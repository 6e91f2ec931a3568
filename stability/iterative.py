"""``method="iterative"``: the thesis' movement-constrained scheme (ch. 5, sec. iterative).

Object equilibrium is dropped; instead each step solves the *movement constrained
existence problem* (thesis Algorithm iterative): the exact model
(:class:`~stability.model.problem.ExactProblem`: springs, nonbackdrivable actuators, friction cone)
with the object's motion restricted to a ray along the previous net wrench,

    r^k = r^{k-1} + s M^{-1} w^{k-1},   0 <= s <= gamma            (eq. movement)

minimising the net wrench ``w^k = w + G c^k`` (its 1-norm, torques divided by the grasp
size ``L``, so a MILP). The outer loop (Algorithm loop) starts at ``r^0``, ``w^0 = w`` and
stops once ``|w^{k-1} - w^k| < epsilon S``; the grasp is stable when the converged net
wrench is below ``net_tol S``, with ``S`` the load's force scale (the largest applied force
or torque / ``L``, preload, or contact force of a command; see
:func:`~stability.model.problem.scale_bounds`): ``net_tol = 1e-3`` is the thesis' 1e-3 N for its
loads of about 1 N, made relative so that a small load is not "held" by no force at all. An
iteration cap reached first is the status ``"not_converged"`` with ``stable=None``, never a
guess (``stats["message"]`` says where).

A stop above ``net_tol`` is first checked down the ray (``stats["far_steps"]``,
``"far_moves"``): the net wrench can stop changing on a *plateau*, where the hand follows
the object at its commanded forces so the net wrench is the same all along the ray, and the
least-motion optimum is then no step at all (step 0, "converged") while an equilibrium lies
beyond ``gamma`` times the small net wrench. One step with the ray as long as a contact can
move in the model (``2 B / min k``) decides: a lower net wrench there and the loop goes on from it,
else "unstable". Commanded preloads of random grasps stall on such plateaus, so without the
look their queries would be answered "unstable" where ``exact`` holds the commands.

Commands are applied first: the scheme runs with ``w = 0`` from ``r = 0`` to the commanded
preload's state ``(r_pre, q_pre)`` (``stats["preload_trace"]``), then with the disturbance
from ``r_pre``, the nonbackdrivable transmissions now locking where the preload left them:
``R^T (q - q_pre) >= 0`` (``Solution.hand_reference = q_pre``). In the thesis' one-shot
model (``no_mdp``) they lock at ``q = 0``, so a transmission loaded beyond its command must
first return to where the springs were at rest, a jump this scheme's small object steps
cannot make. ``MaxDisturbance`` bisects on ``s`` in ``[0, cap]``: ``cap`` first, then a
decade search down from it, then bisection until ``hi - lo <= rtol * hi + atol``
(``bisection_rtol = 1e-3``, ``atol = 1e-9 cap``); the result is the largest stable ``s``
found (a lower bound within that tolerance of the stability boundary of the scheme).
When the commanded preload alone is not stable for the scheme, a MaxDisturbance has no
answer (status ``"not_converged"``, ``stats["message"]``): the disturbance is applied from
the preload's state, and the stable set along the ray need not contain ``s = 0`` (``exact``
can hold the cap where ``s = 0`` is unstable), nor does the scheme's stop prove ``s = 0``
unstable, so "unstable" for every ``s`` would be a guess. An ``Existence`` query answers
"unstable" there (the scheme's own answer).

Units and the metric ``M``: the thesis' springs have unit stiffness, so motion is measured in
newtons (with contact stiffness ``k``, ``Grasp.stiffness``, motions are divided by ``min k``).
The thesis moves the object along ``w^{k-1}`` itself, which mixes N and N m; here the
rotation part is divided by ``L^2`` (``M = diag(1, 1, 1, L^2, L^2, L^2) min k``: a torque
``tau`` turns a grasp of size ``L`` by about ``tau / L^2``), and ``L = 1`` gives the thesis'
scheme exactly (option ``length_scale``). ``s = 1`` fully loads a single spring; each step picks
the best ``s`` on its ray, so ``gamma`` (default 10) only caps how far: on ``barrett_box``
``gamma = 1`` needs 83 steps where 10 needs 19, for the same answers. Model bounds
(:func:`~stability.model.problem.scale_bounds`) follow each applied wrench, so a bisection probe at
a small ``s`` is not solved with the big-M of ``cap``.

The scheme has no convergence guarantee (thesis) and is not the exact problem's answer: it
approximates maximum dissipation by letting the object move only where it is pushed. It is
right where ``no_mdp`` is wrong (the wedge) and agrees with the exact planar solver on the
thesis' table; see ``tests/stability/test_no_mdp_iterative.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import register
from .errors import MethodError
from .grasp import Grasp
from .model.problem import ExactBounds, ExactPoint, ExactProblem, length_scale, scale_bounds
from .model.query import QueryData
from .model.run import MipOptions, Stop, bounds_stats, run, solution, stopped
from .options import Deadline, check_ranges, finite
from .queries import Existence, MaxDisturbance
from .solution import Solution

__all__ = ["IterativeOptions"]


@dataclass(frozen=True)
class IterativeOptions(MipOptions):
    """Options of ``method="iterative"``: :class:`~stability.model.run.MipOptions` and
    ``gamma`` (the ray's length per step), ``epsilon`` and ``net_tol`` (Algorithm loop's
    step and net-wrench tolerances, ``epsilon < net_tol``), ``max_iter`` (steps per loop),
    ``length_scale`` [m] (torques to forces; default the grasp's), ``bisection_rtol``
    (MaxDisturbance's bisection, relative)."""

    gamma: float = 10.0
    epsilon: float = 1e-6
    net_tol: float = 1e-3
    max_iter: int = 100
    length_scale: float | None = None
    bisection_rtol: float = 1e-3

    def check(self) -> None:
        super().check()
        L = self.length_scale
        positive = "finite and > 0"
        check_ranges(self, {
            "gamma": (finite(self.gamma) and self.gamma > 0, positive),
            "epsilon": (finite(self.epsilon) and self.epsilon > 0, positive),
            "net_tol": (finite(self.net_tol) and self.net_tol > self.epsilon,
                        f"finite and above epsilon ({self.epsilon})"),
            "max_iter": (self.max_iter >= 1, "a positive integer"),
            "length_scale": (L is None or (finite(L) and L > 0), "finite and > 0 [m]"),
            "bisection_rtol": (finite(self.bisection_rtol) and self.bisection_rtol > 0,
                               positive),
        })  # fmt: skip


class _Scheme:
    """One grasp, one set of commands: runs Algorithm loop for any applied wrench."""

    def __init__(
        self,
        grasp: Grasp,
        data: QueryData,
        opts: IterativeOptions,
        deadline: Deadline,
        L: float,
        stats: dict[str, Any],
    ) -> None:
        self.grasp, self.data, self.opts, self.deadline = grasp, data, opts, deadline
        k = 2 if grasp.planar else 3
        nw = grasp.wrench_dim
        self.weights = np.r_[np.ones(k), np.full(nw - k, 1.0 / L)]  # wrench -> force units
        # wrench -> motion: a force w moves the softest contact's spring by w / min k
        soft = 1.0 / float(grasp.stiffness.min())
        self.metric = np.r_[np.ones(k), np.full(nw - k, 1.0 / L**2)] * soft
        self.stats = stats
        self.q_ref: NDArray[np.float64] | None = None  # where the actuators lock

    def norm(self, w: NDArray[np.float64]) -> float:
        return float(np.linalg.norm(self.weights * w))

    def step(
        self,
        w: NDArray[np.float64],
        bounds: ExactBounds,
        r_prev: NDArray[np.float64],
        w_prev: NDArray[np.float64],
        gamma: float | None = None,
    ) -> tuple[ExactProblem, ExactPoint | None, float]:
        """Algorithm iterative: the movement constrained existence problem (the ray's
        length ``gamma``, default the option's)."""
        prob = ExactProblem(self.grasp, self.data.preload, self.data.hand, bounds,
                            self.opts.edges, name="iterative step",
                            hand_reference=self.q_ref)  # fmt: skip
        prob.add_net_wrench(w, self.weights)
        s = prob.add_motion_ray(r_prev, self.metric * w_prev, gamma or self.opts.gamma)
        pt = run(prob, self.opts, self.deadline, self.stats)
        return prob, pt, (math.nan if pt is None else float(pt.x[s]))

    def look_down_ray(
        self,
        w: NDArray[np.float64],
        bounds: ExactBounds,
        r: NDArray[np.float64],
        w_net: NDArray[np.float64],
        below: float,
    ) -> tuple[tuple[ExactProblem, ExactPoint, float], NDArray[np.float64]] | None:
        """One step from ``r`` along the net wrench ``w_net`` with the ray as long as a contact
        can move in the model (``bounds.displacement``, not ``gamma``); the step and its net
        wrench when that is below ``below``, else None. ``stats["far_steps"]`` counts the looks, and
        ``stats["far_moves"]`` those that found a lower net wrench."""
        direction = self.metric * w_net
        reach = float(np.abs(self.grasp.G.T @ direction).max(initial=0.0))
        if reach <= 0.0:
            return None
        gamma = bounds.displacement / reach
        if gamma <= self.opts.gamma:
            return None
        self.stats["far_steps"] = self.stats.get("far_steps", 0) + 1
        prob, pt, s = self.step(w, bounds, r, w_net, gamma)
        if pt is None:
            return None
        w_k = self.grasp.G @ pt.forces.reshape(-1) + w
        if self.norm(w_k) >= below:
            return None
        self.stats["far_moves"] = self.stats.get("far_moves", 0) + 1
        return (prob, pt, s), w_k

    def loop(
        self, w: NDArray[np.float64], r0: NDArray[np.float64]
    ) -> tuple[str, ExactProblem | None, ExactPoint | None, list[dict[str, float]]]:
        """Algorithm loop from ``r0``: ``(outcome, problem, point, trace)`` with outcome
        ``"stable"``, ``"unstable"``, ``"infeasible"`` (no hand equilibrium on the ray: the
        commands cannot be balanced) or ``"not_converged"``."""
        d = self.data
        bounds = scale_bounds(self.grasp, w, d.preload, d.hand, self.opts.bound_factor)
        scale = bounds.scale  # N: the load this loop carries
        r_prev, w_prev = r0, w
        trace: list[dict[str, float]] = []
        while len(trace) < self.opts.max_iter:
            prob, pt, s = self.step(w, bounds, r_prev, w_prev)
            if pt is None:
                return "infeasible", None, None, trace
            w_k = self.grasp.G @ pt.forces.reshape(-1) + w
            net = self.norm(w_k)
            trace.append({"net": net, "step": s})
            if self.norm(w_prev - w_k) < self.opts.epsilon * scale:
                if net < self.opts.net_tol * scale:
                    return "stable", prob, pt, trace
                # The net wrench stopped changing above the tolerance. That may be a
                # plateau, not an object pushed away: the hand follows the object at its
                # commanded forces, the net wrench is the same all along the ray, and the
                # least-motion optimum is no step at all, while an equilibrium lies beyond
                # gamma. So look down the ray as far as a contact can move in the model
                # (bounds.displacement) before answering "unstable"; a lower net wrench
                # there goes on.
                far = self.look_down_ray(w, bounds, pt.motion, w_k, net - self.opts.epsilon * scale)
                if far is None:
                    return "unstable", prob, pt, trace
                (prob, pt, s), w_k = far
                trace.append({"net": self.norm(w_k), "step": s, "far": True})
            r_prev, w_prev = pt.motion, w_k
        return "not_converged", prob, pt, trace


@register(
    "iterative",
    queries=(Existence, MaxDisturbance),
    planar=True,
    spatial=True,
    options=IterativeOptions,
    hand=True,
    compliance=True,
    summary="thesis ch. 5: movement-constrained MIP steps along the net wrench (no guarantee)",
)
def _solve_iterative(grasp: Grasp, query: Existence | MaxDisturbance, opts: IterativeOptions,
                     deadline: Deadline) -> Solution:  # fmt: skip
    data = QueryData.of(grasp, query)
    if np.any(data.preload < 0):
        raise MethodError("iterative does not take a negative preload (a gap); use modesearch, "
                          "refinement, exact or no_mdp")  # fmt: skip
    L = opts.length_scale or length_scale(grasp)
    bounds = scale_bounds(grasp, data.wrench_max, data.preload, data.hand, opts.bound_factor)
    stats: dict[str, Any] = {"backend": opts.backend, "length_scale": L}
    bounds_stats(bounds, stats)
    sch = _Scheme(grasp, data, opts, deadline, L, stats)
    zero = np.zeros(grasp.wrench_dim)
    try:
        # the commanded preload first (Algorithm loop with w = 0 from r = 0)
        out, prob, pt, trace = sch.loop(zero, zero)
        stats["preload_trace"] = trace
        if out != "stable":
            stats["reason"] = f"the commanded preload alone is {out.replace('_', ' ')}"
            if out == "not_converged":
                return _not_converged(grasp, query, stats)
            if data.direction is not None:
                # MaxDisturbance: the bisection applies the disturbance from the preload's
                # state, and the stable set along the ray need not contain s = 0 (an
                # unbalanced command can be held by a disturbance against it); nor does the
                # scheme's stop prove s = 0 unstable. So no answer, rather than "unstable"
                # for every s in [0, cap].
                stats["reason"] += (
                    "; the scheme starts the disturbance from the commands' "
                    "equilibrium, so it cannot answer this MaxDisturbance"
                )
                return _not_converged(grasp, query, stats)
            return solution("iterative", grasp, query, False, stats)
        r_pre = pt.motion
        sch.q_ref = pt.hand_motion  # the transmissions lock where the preload left them
        if data.direction is None:
            out, prob, pt, trace = sch.loop(data.wrench, r_pre)
            stats["trace"], stats["iterations"] = trace, len(trace)
            if out == "not_converged":
                stats["reason"] = f"the scheme did not converge in {len(trace)} steps"
                return _not_converged(grasp, query, stats)
            if out != "stable":
                return solution("iterative", grasp, query, False, stats)
            return solution("iterative", grasp, query, True, stats, prob, pt)
        return _bisect(sch, grasp, query, data, (prob, pt, trace), stats, opts.bisection_rtol)
    except Stop as e:
        return stopped("iterative", grasp, query, stats, e)


def _bisect(sch, grasp, query, data, preload, stats, rtol) -> Solution:
    """MaxDisturbance: the largest stable ``s`` in ``[0, cap]``, see the module docstring.
    ``preload`` is the converged ``(problem, point, trace)`` of the commands alone, the
    answer for ``s = 0``."""
    cap, d = data.cap, data.direction
    base = np.zeros_like(d) if data.base is None else data.base
    r_pre = preload[1].motion
    probes: list[dict[str, Any]] = []
    best: tuple[float, Any, Any, list] | None = None

    def probe(s: float) -> bool:
        nonlocal best
        out, prob, pt, trace = sch.loop(base + s * d, r_pre)
        probes.append({"s": s, "outcome": out, "iterations": len(trace)})
        if out == "not_converged":
            raise _NotConverged(s)
        if out == "stable" and (best is None or s > best[0]):
            best = (s, prob, pt, trace)
        return out == "stable"

    stats["bisection"] = probes
    try:
        if base.any() and not probe(0.0):  # the base load alone is not held
            stats["capped"] = False
            stats["reason"] = "the base load alone is not stable"
            return solution("iterative", grasp, query, False, stats)
        if probe(cap):
            lo, hi = cap, cap
        else:
            lo, hi = 0.0, cap
            s = cap
            atol = 1e-9 * cap
            while s > atol:  # decade search down from cap for a stable bracket
                s /= 10.0
                if probe(s):
                    lo = s
                    break
                hi = s
            while hi - lo > rtol * hi + atol:
                mid = 0.5 * (lo + hi)
                if probe(mid):
                    lo = mid
                else:
                    hi = mid
    except _NotConverged as e:
        stats["reason"] = f"the scheme did not converge at s = {e.s:g}"
        return _not_converged(grasp, query, stats)
    stats["capped"] = bool(best is not None and best[0] >= cap)
    stats["bracket"] = (lo, hi)
    if best is None:  # only s = 0, the preload's own state, is stable
        best = (0.0, *preload)
    s, prob, pt, trace = best
    stats["trace"], stats["iterations"] = trace, len(trace)
    return solution("iterative", grasp, query, True, stats, prob, pt, value=float(s))


def _not_converged(grasp: Grasp, query: Any, stats: dict[str, Any]) -> Solution:
    """No answer: status ``"not_converged"``, ``stats["message"]`` the reason."""
    stats["message"] = stats["reason"]
    return solution("iterative", grasp, query, None, stats, status="not_converged")


class _NotConverged(Exception):
    def __init__(self, s: float) -> None:
        super().__init__(s)
        self.s = s
