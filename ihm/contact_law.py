"""MuJoCo's static contact law as a convex piecewise-linear spring.

At rest a MuJoCo contact pressed ``r`` [m] into its margin carries the normal force
(:mod:`ihm.compliance`, module docstring)

    f(r) = A s(r),    s(r) = r imp(r)^2 / (1 - imp(r)),    A = sum_j k_j / c_j,

``imp`` the impedance of the contact's ``solimp`` (:func:`ihm.compliance.impedance`) and
``k_j``, ``c_j`` constants of its rows. The law is not linear: with the default ``solimp =
(0.9, 0.95, 0.001, 0.5, 2)`` its slope ``s'`` is 8.1 at first touch, 27.7 at 0.77 mm and
18.05 beyond the 1 mm width. The grasp model's contact is a linear spring ``c_n = max(0, p -
K d_n)`` (``d_n`` the separation, ``p`` the preload). A sum of such springs at one point,

    c_n = max(0, p - K_0 d_n) + sum_i max(0, -K_i (d_n + g_i)),    0 < g_1 < g_2 < ...,

is a law whose slope rises by ``K_i`` after ``g_i`` more penetration: a convex law, which
the methods already take (each term is a contact with the gap ``g_i``, preload ``-K_i
g_i``). :func:`fit_law` finds the convex law closest to ``s`` over ``span`` more
penetration from the state, in the largest relative error ``max |h - s| / s``, exact at
the state, with at most :data:`LAW_PIECES` knots (a linear program per choice of knots on a
grid every :data:`LAW_SPACING`). MuJoCo's law is convex up to 0.77 mm, concave to the width
and linear beyond, so no convex law follows it exactly: over 3 mm from the state the
one-knot fit is within 8.5-10.3 % from a depth of 0 to 0.3 mm and within 10.4 % from any
depth (``LawFit.error``, with this ``solimp``), where the slope at the state alone is off by
41-55 % (it gives half the force 2 mm deeper).

:func:`law_pieces` turns each contact of a grasp read off MuJoCo into its base spring and
its pieces, co-located contacts with their gaps (:func:`ihm.grasp_from_mujoco` with
``contact_law="fitted"``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from .compliance import impedance
from .patches import ContactGroup

__all__ = [
    "CONTACT_LAWS",
    "LAW_PIECES",
    "LAW_SPACING",
    "LAW_SPAN",
    "LawFit",
    "fit_law",
    "law_pieces",
    "law_shape",
]

#: the contact laws :func:`ihm.grasp_from_mujoco` reads with ``compliance="mujoco"``: the
#: linear spring of the slope at the state, or the fitted law of this module
CONTACT_LAWS = ("slope", "fitted")
#: how far past the state :func:`ihm.grasp_from_mujoco` fits the law [m]: the ramp's 2 mm at
#: the centre of mass, and its 0.05 rad at a contact 20 mm away
LAW_SPAN = 3e-3
#: at most this many slope steps per contact (:func:`fit_law`): each is a contact more for
#: the methods, and a second one gains 1.5 % at most
LAW_PIECES = 1
#: the knots' spacing of :func:`fit_law` [m]
LAW_SPACING = 1e-4


def law_shape(solimp: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """``s(r) = r imp(r)^2 / (1 - imp(r))`` [m] at penetrations ``r >= 0`` [m]: MuJoCo's
    static normal force per unit ``A`` (module docstring)."""
    r = np.asarray(r, dtype=float)
    imp = impedance(np.asarray(solimp, dtype=float), r)
    return r * imp**2 / (1.0 - imp)


@dataclass(frozen=True)
class LawFit:
    """A convex piecewise-linear law in units of the exact law's slope ``s'(depth)`` at the
    state: ``h(d) = s(depth) / s'(depth) + slope d + sum_i steps[i] max(0, d - knots[i])``
    for ``d >= 0`` more penetration [m]. ``error``: the largest ``|h - s| / s`` over the
    span (``s`` scaled the same way); ``knots`` [m] increasing, ``steps > 0``."""

    slope: float
    knots: NDArray[np.float64]
    steps: NDArray[np.float64]
    error: float


def fit_law(solimp: tuple[float, ...], depth: float, span: float, pieces: int = LAW_PIECES,
            spacing: float = LAW_SPACING) -> LawFit:  # fmt: skip
    """The convex piecewise-linear law closest to MuJoCo's (module docstring) over ``[depth,
    depth + span]`` [m] in the largest relative error, through the law's value at
    ``depth``, with at most ``pieces`` knots from a grid every ``spacing`` [m] inside the
    span: for each choice of knots a linear program (HiGHS) in the first slope, the slope
    steps ``>= 0`` and the error bound, on 401 points; the best choice is kept."""
    si = np.asarray(solimp[:5], dtype=float)
    r = depth + np.linspace(0.0, span, 401)
    s = law_shape(si, r)
    dr = max(1e-3 * spacing, 1e-9)
    scale = float((law_shape(si, np.array([depth + dr]))[0] - s[0]) / dr)  # s'(depth)
    grid = np.arange(spacing, span - 0.5 * spacing, spacing)
    best = _fit_knots(s, r - depth, np.zeros(0))
    for n in range(1, pieces + 1):
        for knots in itertools.combinations(grid, n):
            fit = _fit_knots(s, r - depth, np.array(knots))
            if fit.error < best.error - 1e-9:
                best = fit
    return LawFit(slope=best.slope / scale, knots=best.knots, steps=best.steps / scale,
                  error=best.error)  # fmt: skip


def _fit_knots(s: NDArray[np.float64], d: NDArray[np.float64],
               knots: NDArray[np.float64]) -> LawFit:  # fmt: skip
    """The fit of :func:`fit_law` with these knots, in the units of ``s`` (its steps of 0
    dropped)."""
    import scipy.optimize as so

    s0 = float(s[0])
    basis = np.column_stack([d, np.maximum(0.0, d[:, None] - knots[None, :])])
    w = np.maximum(s, 1e-12 * max(float(s.max()), 1e-30))  # relative error's weight
    n = basis.shape[1]
    a_ub = np.block([[basis, -w[:, None]], [-basis, -w[:, None]]])
    b_ub = np.r_[s - s0, s0 - s]
    bounds = [(None, None)] + [(0.0, None)] * (n - 1) + [(0.0, None)]
    res = so.linprog(np.r_[np.zeros(n), 1.0], A_ub=a_ub, b_ub=b_ub, bounds=bounds,
                     method="highs")  # fmt: skip
    if res.status != 0:  # pragma: no cover - a bounded LP with a feasible point
        raise RuntimeError(f"fit_law: the fit's LP ended with status {res.status}")
    x = res.x
    steps = x[1:n]
    keep = steps > 1e-6 * max(abs(x[0]), float(steps.max(initial=0.0)))
    return LawFit(slope=float(x[0]), knots=knots[keep], steps=steps[keep], error=float(x[n]))


@lru_cache(maxsize=256)
def _cached_fit(solimp: tuple[float, ...], depth: float, span: float) -> LawFit:
    return fit_law(solimp, depth, span)


def law_pieces(groups: list[ContactGroup], gaps: NDArray[np.float64], span: float,
               ) -> tuple[list[ContactGroup], NDArray[np.float64], NDArray[np.int64]]:  # fmt: skip
    """Each contact with a law (``ContactGroup.law``, :class:`ihm.patches.ContactLaw`) as its
    fitted law (:func:`fit_law` over ``span``): the contact with the first slope as its
    stiffness, then, after all contacts, one co-located contact per knot with the slope's
    step as its stiffness, no force, and the contact's gap plus the knot as its gap.
    Returns the contacts, their gaps [m] and, per contact, the index of the contact it is
    a piece of (its own index for the contacts read)."""
    base, pieces, piece_gaps, owner = [], [], [], []
    for k, (g, gap) in enumerate(zip(groups, gaps, strict=True)):
        if g.law is None:
            base.append(g)
            continue
        fit = _cached_fit(g.law.solimp, g.law.depth, float(span))
        base.append(replace(g, stiffness=g.stiffness * fit.slope))
        for knot, step in zip(fit.knots, fit.steps, strict=True):
            pieces.append(replace(g, force_world=np.zeros(3), ids=[],
                                  stiffness=g.stiffness * float(step)))  # fmt: skip
            piece_gaps.append(float(gap) + float(knot))
            owner.append(k)
    m = len(groups)
    return (base + pieces, np.r_[np.asarray(gaps, dtype=float), piece_gaps],
            np.r_[np.arange(m), np.array(owner, dtype=np.int64)].astype(np.int64))  # fmt: skip
