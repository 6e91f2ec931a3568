"""Force closure of a set of contacts, from their primitive wrenches: one small QP (DAQP).

The QP shield (:mod:`shields.qp`) tests each candidate set of shielded links with
:func:`force_closure_wrenches`.
"""

from __future__ import annotations

from functools import lru_cache

import daqp
import numpy as np
from numpy.typing import NDArray

__all__ = ["force_closure_wrenches"]

_INF = 1e30  # DAQP's infinity


def force_closure_wrenches(W: NDArray[np.float64]) -> bool:
    """Whether the wrenches ``W`` (K, 6) positively span R^6: the origin is strictly inside
    their convex hull (force closure of the contacts whose primitive wrenches they are,
    :func:`stability.gws.primitive_wrenches`).

    Test: ``rank W = 6`` and some ``lambda >= 1`` has ``W^T lambda = 0`` (a strictly
    positive combination that cancels), decided by one small QP (DAQP). Scale torques to
    forces before calling (the test is invariant to that scaling, its tolerances are not).
    """
    W = np.asarray(W, dtype=np.float64)
    if W.ndim != 2 or W.shape[1] != 6 or len(W) < 7:
        return False
    ev = np.linalg.eigvalsh(W.T @ W)  # rank 6 <=> W^T W positive definite
    if not ev[0] > 1e-12 * max(float(ev[-1]), 1e-300):
        return False
    k = len(W)
    # lambda = 1 + mu: min 0.5 |mu|^2  s.t.  mu >= 0 (bounds), W^T mu = -W^T 1 (equalities).
    # (The minimiser starts from mu = 0, which satisfies the bounds: a few active-set steps,
    # where 0.5 |lambda|^2 with lambda >= 1 starts with every bound violated.)
    lo, hi, sense = _closure_bounds(k)
    b = -W.sum(axis=0)
    lo[k:] = b
    hi[k:] = b
    mu, _, flag, _ = daqp.solve(_eye(k), np.zeros(k), np.ascontiguousarray(W.T), hi, lo, sense)
    if flag < 1:
        return False
    lam = 1.0 + np.maximum(mu, 0.0)
    return bool(np.abs(W.T @ lam).max() <= 1e-7 * max(float(lam.sum()), 1.0))


@lru_cache(maxsize=64)
def _eye(n: int) -> NDArray[np.float64]:
    return np.eye(n)


def _closure_bounds(k: int) -> tuple[NDArray, NDArray, NDArray]:
    """Bounds ``mu >= 0`` then 6 equality rows (their values set by the caller)."""
    lo = np.zeros(k + 6)
    hi = np.concatenate([np.full(k, _INF), np.zeros(6)])
    return lo, hi, _closure_sense(k)


@lru_cache(maxsize=64)
def _closure_sense(k: int) -> NDArray[np.int32]:
    return np.concatenate([np.zeros(k, np.int32), np.full(6, 5, np.int32)])
