"""The result of :func:`stability.solve`, with the residuals that prove it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .grasp import Grasp
from .queries import Existence, MaxDisturbance, Query

__all__ = ["Solution", "model_residuals"]


def model_residuals(
    grasp: Grasp,
    wrench: NDArray[np.float64],
    forces: NDArray[np.float64],
    motion: NDArray[np.float64] | None = None,
    preload: NDArray[np.float64] | None = None,
    hand_motion: NDArray[np.float64] | None = None,
) -> dict[str, float]:
    """Violation of every model condition by ``(forces, motion)``; all are 0 for a solution.

    * ``equilibrium``: ``max |G c + w|`` [N, N m].
    * ``normal_sign``: ``max(0, -c_n)``.
    * ``friction_cone``: ``max(0, |c_t| - mu c_n)``.
    * ``spring_law`` (needs ``motion``): ``max |c_n - max(0, p - d_n)|`` with
      ``d = G^T r - J q`` (thesis eq. normal_compliance).
    * ``max_dissipation`` (needs ``motion``): ``max(c_t . d_t + mu c_n |d_t|)``,
      zero iff friction opposes sliding at full magnitude (thesis eq. cone);
      non-negative whenever the cone holds.
    """
    k = grasp.dim
    c = np.asarray(forces, dtype=float).reshape(grasp.m, k)
    cn, ct = c[:, 0], c[:, 1:]
    ctn = np.linalg.norm(ct, axis=1)
    res = {
        "equilibrium": float(np.max(np.abs(grasp.G @ c.reshape(-1) + wrench))),
        "normal_sign": float(np.max(np.maximum(0.0, -cn))),
        "friction_cone": float(np.max(np.maximum(0.0, ctn - grasp.mu * cn))),
    }
    if motion is not None:
        d = grasp.G.T @ np.asarray(motion, dtype=float)
        if hand_motion is not None and grasp.J is not None:
            d = d - grasp.J @ hand_motion
        d = d.reshape(grasp.m, k)
        dn, dt = d[:, 0], d[:, 1:]
        p = np.zeros(grasp.m) if preload is None else preload
        res["spring_law"] = float(np.max(np.abs(cn - np.maximum(0.0, p - dn))))
        diss = np.einsum("ij,ij->i", ct, dt) + grasp.mu * cn * np.linalg.norm(dt, axis=1)
        res["max_dissipation"] = float(np.max(np.abs(diss)))
    return res


@dataclass
class Solution:
    """Answer of one method to one query.

    Attributes
    ----------
    stable : bool
        Existence: an equilibrium exists. MaxDisturbance: some ``s`` in
        ``[0, cap]`` is stable, and ``value`` is the largest such ``s`` (the
        supremum of the stable set along the ray, which need not be an
        interval starting at 0; with an unbalanced preload ``s = 0`` itself
        can be unstable).
    forces : (m, 2) or (m, 3) array or None
        Contact forces on the object in contact frames, ``[c_n, c_t]`` planar,
        ``[c_n, c_t1, c_t2]`` spatial [N].
    motion : array or None
        Object motion ``r`` (planar ``(x, y, theta)``); virtual, since springs
        have unit stiffness. None where the method has no motion (``gws``).
    value : float or None
        Optimisation queries: the optimum (MaxDisturbance: largest ``s``).
    states : (m,) array of str or None
        Per-contact state: ``"roll"``, ``"slip+"``, ``"slip-"``, ``"detach"``.
    stats : dict
        At least ``time_s``; methods add counts (states visited, LPs solved, ...).
    """

    stable: bool
    method: str
    grasp: Grasp
    query: Query
    forces: NDArray[np.float64] | None = None
    motion: NDArray[np.float64] | None = None
    hand_motion: NDArray[np.float64] | None = None
    value: float | None = None
    states: NDArray[np.str_] | None = None
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def wrench(self) -> NDArray[np.float64]:
        """The external wrench this solution balances."""
        q = self.query
        if isinstance(q, MaxDisturbance):
            s = 0.0 if self.value is None else self.value
            return s * np.asarray(q.direction, dtype=float)
        return np.asarray(q.wrench, dtype=float)

    def residuals(self) -> dict[str, float]:
        """Violation of each model condition by the returned forces and motion.

        See :func:`model_residuals`. Methods without a passive model
        (``gws``) return no motion, so only equilibrium and cone terms appear.
        Raises ``ValueError`` when there is no solution to check.
        """
        if self.forces is None:
            raise ValueError(f"no forces to check: the {self.method!r} answer is unstable")
        q = self.query
        preload = None
        if isinstance(q, Existence | MaxDisturbance) and self.motion is not None:
            preload = self.grasp.per_contact(q.preload, "preload")
        return model_residuals(
            self.grasp, self.wrench, self.forces, self.motion, preload, self.hand_motion
        )

    def max_residual(self) -> float:
        """Largest entry of :meth:`residuals`."""
        return max(self.residuals().values())
