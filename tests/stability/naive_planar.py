"""Naive exhaustive reference checker for planar grasp stability (thesis ch. 4).

Written straight from the thesis equations with numpy/scipy/highspy only; it
imports nothing from ``stability`` so that it is an independent check of the
polynomial-time planar solver.

Model (rigid hand, m point contacts with friction):

* contact ``i`` at ``p_i`` with unit normal ``n_i`` pointing INTO the object and
  tangent ``t_i = n_i`` rotated +90 degrees, ``t = (-n_y, n_x)``;
* object motion ``r = (x, y, theta)``; contact displacement in the contact frame
  ``d_in = n_i . (v + theta perp(p_i))``, ``d_it = t_i . (v + theta perp(p_i))``
  with ``v = (x, y)`` and ``perp(p) = (-p_y, p_x)`` (the rows of ``G^T``);
* forces ``c_i = (c_in, c_it)`` hand-on-object; equilibrium ``G c + w = 0``;
* unit virtual spring with preload ``p_i >= 0``:
  persist (``d_in - p_i <= 0``, ``c_in = p_i - d_in``) or detach
  (``d_in - p_i >= 0``, ``c_in = 0``);
* Coulomb friction with maximum dissipation: roll (``d_it = 0``,
  ``|c_it| <= mu c_in``), slip+ (``d_it >= 0``, ``c_it = -mu c_in``), slip-
  (``d_it <= 0``, ``c_it = +mu c_in``).

All inequalities are closed. The grasp is stable iff one of the ``6^m`` state
combinations admits ``(r, c)`` satisfying everything; each combination is one
feasibility LP. No geometric pruning: every combination is tried in
``itertools.product`` order until one is feasible.

Two LP backends give the same answers: ``"highspy"`` (default, fast: one HiGHS
model per call whose constraint matrix is fixed, each state only changes row
bounds, so the simplex warm-starts) and ``"scipy"`` (``scipy.optimize.linprog``
with ``method="highs"``, a fresh LP per state: slow but as plain as it gets).
"""

from __future__ import annotations

import itertools

import highspy
import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linprog

__all__ = ["STATES", "naive_stable", "naive_residuals"]

# (normal state, friction state) per contact, 6 in all (thesis table contact_states)
STATES: tuple[tuple[str, str], ...] = tuple(
    itertools.product(("persist", "detach"), ("roll", "slip+", "slip-"))
)

_INF = np.inf
_FEAS_TOL = 1e-9  # primal feasibility tolerance handed to HiGHS


def _setup(points: ArrayLike, normals: ArrayLike, mu, wrench: ArrayLike, preload):
    P = np.asarray(points, dtype=float).reshape(-1, 2)
    N = np.asarray(normals, dtype=float).reshape(-1, 2)
    m = P.shape[0]
    if N.shape != (m, 2):
        raise ValueError(f"normals shape {N.shape} does not match points shape {P.shape}")
    N = N / np.linalg.norm(N, axis=1, keepdims=True)
    T = np.stack([-N[:, 1], N[:, 0]], axis=1)
    mu_a = np.broadcast_to(np.asarray(mu, dtype=float), (m,)).copy()
    pre = np.broadcast_to(np.asarray(0.0 if preload is None else preload, dtype=float), (m,))
    pre = pre.copy()
    w = np.asarray(wrench, dtype=float).reshape(3)
    perp = np.stack([-P[:, 1], P[:, 0]], axis=1)
    # rows of G^T: d_in = Dn[i] . r, d_it = Dt[i] . r
    Dn = np.column_stack([N, np.einsum("ij,ij->i", N, perp)])  # (m, 3)
    Dt = np.column_stack([T, np.einsum("ij,ij->i", T, perp)])  # (m, 3)
    # grasp map: column for c_in is Dn[i], for c_it is Dt[i]  (p x f = f . perp(p))
    G = np.zeros((3, 2 * m))
    G[:, 0::2] = Dn.T
    G[:, 1::2] = Dt.T
    return m, Dn, Dt, G, mu_a, pre, w


def naive_residuals(points, normals, mu, wrench, preload, forces, motion) -> dict[str, float]:
    """Violation of every model condition by ``(forces, motion)``, computed from scratch."""
    m, Dn, Dt, G, mu_a, pre, w = _setup(points, normals, mu, wrench, preload)
    c = np.asarray(forces, dtype=float).reshape(m, 2)
    r = np.asarray(motion, dtype=float).reshape(3)
    dn, dt = Dn @ r, Dt @ r
    cn, ct = c[:, 0], c[:, 1]
    return {
        "equilibrium": float(np.max(np.abs(G @ c.reshape(-1) + w))),
        "spring_law": float(np.max(np.abs(cn - np.maximum(0.0, pre - dn)))),
        "friction_cone": float(np.max(np.maximum(0.0, np.abs(ct) - mu_a * cn))),
        "max_dissipation": float(np.max(np.abs(ct * dt + mu_a * cn * np.abs(dt)))),
    }


# ----------------------------------------------------------------------------------
# backend 1: scipy.optimize.linprog, a fresh LP per state
# ----------------------------------------------------------------------------------
def _stable_scipy(m, Dn, Dt, G, mu_a, pre, w):
    nv = 3 + 2 * m  # x = [r (3), c_1n, c_1t, c_2n, c_2t, ...]
    zero = np.zeros(nv)
    # constant parts
    eq_rows_G = np.hstack([np.zeros((3, 3)), G])
    row_dn, row_dt = [], []
    row_cn, row_ct = [], []
    for i in range(m):
        a = zero.copy()
        a[:3] = Dn[i]
        row_dn.append(a)
        a = zero.copy()
        a[:3] = Dt[i]
        row_dt.append(a)
        a = zero.copy()
        a[3 + 2 * i] = 1.0
        row_cn.append(a)
        a = zero.copy()
        a[4 + 2 * i] = 1.0
        row_ct.append(a)
    bounds = [(None, None)] * nv
    opts = {"primal_feasibility_tolerance": _FEAS_TOL, "presolve": True}
    for combo in itertools.product(range(6), repeat=m):
        A_eq, b_eq = [*eq_rows_G], [*(-w)]
        A_ub, b_ub = [], []
        for i, k in enumerate(combo):
            normal, fric = STATES[k]
            if normal == "persist":  # d_n - p <= 0, c_n + d_n = p
                A_ub.append(row_dn[i])
                b_ub.append(pre[i])
                A_eq.append(row_cn[i] + row_dn[i])
                b_eq.append(pre[i])
            else:  # d_n - p >= 0, c_n = 0
                A_ub.append(-row_dn[i])
                b_ub.append(-pre[i])
                A_eq.append(row_cn[i])
                b_eq.append(0.0)
            if fric == "roll":  # d_t = 0, |c_t| <= mu c_n
                A_eq.append(row_dt[i])
                b_eq.append(0.0)
                A_ub.append(row_ct[i] - mu_a[i] * row_cn[i])
                b_ub.append(0.0)
                A_ub.append(-row_ct[i] - mu_a[i] * row_cn[i])
                b_ub.append(0.0)
            elif fric == "slip+":  # d_t >= 0, c_t = -mu c_n
                A_ub.append(-row_dt[i])
                b_ub.append(0.0)
                A_eq.append(row_ct[i] + mu_a[i] * row_cn[i])
                b_eq.append(0.0)
            else:  # slip-: d_t <= 0, c_t = +mu c_n
                A_ub.append(row_dt[i])
                b_ub.append(0.0)
                A_eq.append(row_ct[i] - mu_a[i] * row_cn[i])
                b_eq.append(0.0)
        res = linprog(
            zero,
            A_ub=np.array(A_ub),
            b_ub=np.array(b_ub),
            A_eq=np.array(A_eq),
            b_eq=np.array(b_eq),
            bounds=bounds,
            method="highs",
            options=opts,
        )
        if res.status == 0:
            return combo, res.x
        if res.status != 2:  # 2 = infeasible; anything else is a backend failure
            raise RuntimeError(f"linprog failed on states {combo}: {res.status} {res.message}")
    return None, None


# ----------------------------------------------------------------------------------
# backend 2: highspy, one model, each state only sets row bounds
# ----------------------------------------------------------------------------------
def _stable_highspy(m, Dn, Dt, G, mu_a, pre, w):
    nv = 3 + 2 * m
    # rows: 3 equilibrium, then per contact i (6 rows):
    #   A: d_n              persist (-inf, p]   detach [p, inf)
    #   B: c_n + d_n        persist [p, p]      detach free
    #   C: c_n              persist free        detach [0, 0]
    #   D: d_t              roll [0,0]  slip+ [0, inf)  slip- (-inf, 0]
    #   E: c_t - mu c_n     roll (-inf,0]  slip+ free   slip- [0, 0]
    #   F: c_t + mu c_n     roll [0, inf)  slip+ [0, 0]  slip- free
    A = np.zeros((3 + 6 * m, nv))
    A[:3, 3:] = G
    for i in range(m):
        cn, ct = 3 + 2 * i, 4 + 2 * i
        base = 3 + 6 * i
        A[base + 0, :3] = Dn[i]
        A[base + 1, :3] = Dn[i]
        A[base + 1, cn] = 1.0
        A[base + 2, cn] = 1.0
        A[base + 3, :3] = Dt[i]
        A[base + 4, ct], A[base + 4, cn] = 1.0, -mu_a[i]
        A[base + 5, ct], A[base + 5, cn] = 1.0, mu_a[i]
    nr = A.shape[0]

    # per-contact, per-state row bounds of the 6 contact rows
    lo_tab = np.empty((m, 6, 6))
    hi_tab = np.empty((m, 6, 6))
    for i in range(m):
        p = pre[i]
        for k, (normal, fric) in enumerate(STATES):
            if normal == "persist":
                lo_abc, hi_abc = (-_INF, p, -_INF), (p, p, _INF)
            else:
                lo_abc, hi_abc = (p, -_INF, 0.0), (_INF, _INF, 0.0)
            if fric == "roll":
                lo_def, hi_def = (0.0, -_INF, 0.0), (0.0, 0.0, _INF)
            elif fric == "slip+":
                lo_def, hi_def = (0.0, -_INF, 0.0), (_INF, _INF, 0.0)
            else:
                lo_def, hi_def = (-_INF, 0.0, -_INF), (0.0, 0.0, _INF)
            lo_tab[i, k] = lo_abc + lo_def
            hi_tab[i, k] = hi_abc + hi_def

    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", "off")
    h.setOptionValue("primal_feasibility_tolerance", _FEAS_TOL)
    h.setOptionValue("dual_feasibility_tolerance", _FEAS_TOL)
    lp = highspy.HighsLp()
    lp.num_col_ = nv
    lp.num_row_ = nr
    lp.col_cost_ = np.zeros(nv)
    lp.col_lower_ = np.full(nv, -highspy.kHighsInf)
    lp.col_upper_ = np.full(nv, highspy.kHighsInf)
    lo0 = np.concatenate([-w, lo_tab[np.arange(m), 0].reshape(-1)])
    hi0 = np.concatenate([-w, hi_tab[np.arange(m), 0].reshape(-1)])
    lp.row_lower_ = np.where(np.isinf(lo0), -highspy.kHighsInf, lo0)
    lp.row_upper_ = np.where(np.isinf(hi0), highspy.kHighsInf, hi0)
    csc_start, csc_index, csc_value = [0], [], []
    for j in range(nv):
        nz = np.flatnonzero(A[:, j])
        csc_index.extend(nz.tolist())
        csc_value.extend(A[nz, j].tolist())
        csc_start.append(len(csc_index))
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.array(csc_start, dtype=np.int32)
    lp.a_matrix_.index_ = np.array(csc_index, dtype=np.int32)
    lp.a_matrix_.value_ = np.array(csc_value, dtype=float)
    h.passModel(lp)

    rows = np.arange(3, nr, dtype=np.int32)
    big = highspy.kHighsInf
    feasible = highspy.HighsModelStatus.kOptimal
    infeasible = highspy.HighsModelStatus.kInfeasible
    for combo in itertools.product(range(6), repeat=m):
        lo = lo_tab[np.arange(m), combo].reshape(-1)
        hi = hi_tab[np.arange(m), combo].reshape(-1)
        lo = np.where(np.isinf(lo), -big, lo)
        hi = np.where(np.isinf(hi), big, hi)
        h.changeRowsBounds(rows.size, rows, lo, hi)
        h.run()
        st = h.getModelStatus()
        if st == feasible:
            return combo, np.array(h.getSolution().col_value)
        if st != infeasible:
            # rare simplex trouble: retry this state from scratch before giving up
            h.clearSolver()
            h.run()
            st = h.getModelStatus()
            if st == feasible:
                return combo, np.array(h.getSolution().col_value)
            if st != infeasible:
                raise RuntimeError(f"HiGHS failed on states {combo}: {h.modelStatusToString(st)}")
    return None, None


def naive_stable(
    points: ArrayLike,
    normals: ArrayLike,
    mu: float | ArrayLike,
    wrench: ArrayLike,
    preload: float | ArrayLike | None = 0.0,
    backend: str = "highspy",
    return_details: bool = False,
):
    """Exhaustive stability check: try all ``6^m`` contact-state combinations.

    Parameters
    ----------
    points, normals : (m, 2) arrays
        Contact points and normals (pointing into the object; normalised here).
    mu : float or (m,) array
        Friction coefficients.
    wrench : (3,) array
        External wrench ``(fx, fy, tz)`` on the object.
    preload : float or (m,) array
        Spring preloads ``p_i >= 0``.
    backend : "highspy" or "scipy"
    return_details : bool
        Also return the motion ``r`` and the state combination found.

    Returns
    -------
    (stable, forces)
        ``forces`` is ``(m, 2)`` ``[c_n, c_t]`` for the first feasible state
        combination (in ``itertools.product`` order), else ``None``. With
        ``return_details`` a 4-tuple ``(stable, forces, motion, states)``.
    """
    m, Dn, Dt, G, mu_a, pre, w = _setup(points, normals, mu, wrench, preload)
    if backend == "highspy":
        try:
            combo, x = _stable_highspy(m, Dn, Dt, G, mu_a, pre, w)
        except RuntimeError:  # a warm-started solve ended in an unknown status: start over
            combo, x = _stable_scipy(m, Dn, Dt, G, mu_a, pre, w)
    elif backend == "scipy":
        combo, x = _stable_scipy(m, Dn, Dt, G, mu_a, pre, w)
    else:
        raise ValueError(f"unknown backend {backend!r}: 'highspy' or 'scipy'")
    if combo is None:
        return (False, None, None, None) if return_details else (False, None)
    forces = x[3:].reshape(m, 2)
    if return_details:
        return True, forces, x[:3], tuple(STATES[k] for k in combo)
    return True, forces
