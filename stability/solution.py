"""The result of :func:`stability.solve`, with the residuals that prove it."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, MutableMapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .grasp import Grasp, actuator_compliance
from .queries import Existence, MaxDisturbance, MotionLimit, Query, checked_motion_limit

__all__ = [
    "MODEL_CONDITIONS",
    "SLIDE_TOL",
    "Solution",
    "Stats",
    "model_residuals",
    "motion_excess",
    "slide_alignment",
]

# every key model_residuals can return, in its order
MODEL_CONDITIONS = ("equilibrium", "normal_sign", "friction_cone", "spring_law", "max_dissipation",
              "slide_alignment", "hand_equilibrium", "actuator_command", "nonbackdrivable",
              "actuator_complementarity", "motion_limit")  # fmt: skip
# a contact slides when |d_t| > SLIDE_TOL (1 + max |d|) (slide_alignment; measured)
SLIDE_TOL = 1e-9


def model_residuals(
    grasp: Grasp,
    wrench: NDArray[np.float64],
    forces: NDArray[np.float64],
    motion: NDArray[np.float64] | None = None,
    preload: NDArray[np.float64] | None = None,
    hand_motion: NDArray[np.float64] | None = None,
    actuator_forces: NDArray[np.float64] | None = None,
    commands: NDArray[np.float64] | None = None,
    hand_reference: NDArray[np.float64] | None = None,
) -> dict[str, float]:
    """Violation of every model condition by ``(forces, motion)``; all are 0 for a solution.

    * ``equilibrium``: ``max |G c + w|`` [N, N m].
    * ``normal_sign``: ``max(0, -c_n)``.
    * ``friction_cone``: ``max(0, |c_t| - mu c_n)``.
    * ``spring_law`` (needs ``motion``): ``max |c_n - max(0, p - k d_n)|`` with
      ``d = G^T r - J q`` and ``k`` the contact stiffness (thesis eq. normal_compliance;
      ``k = 1`` there).
    * ``max_dissipation`` (needs ``motion``): ``max(c_t . d_t + mu c_n |d_t|)``,
      zero iff friction opposes sliding at full magnitude (thesis eq. cone);
      non-negative whenever the cone holds. A product [N x motion]: a small slide hides a
      misaligned friction (0.83 N off on a slide of 7e-5 is at most 6e-5 here).
    * ``slide_alignment`` (needs ``motion``) [N]: ``max |c_t + mu c_n d_t / |d_t||`` over
      the loaded contacts (``c_n > 0``) that slide, ``|d_t| > SLIDE_TOL (1 + max |d|)``
      (``SLIDE_TOL = 1e-9``; ``d`` is every contact's motion, normal parts included): the
      same maximum dissipation as a force, whatever the slide's size: friction opposes the
      slide at full magnitude. 0 when no contact slides. The threshold is relative to the
      motion's scale so that a sticking contact whose tangential motion is round-off is
      not a slide: over the test suite's exact answers (``planar``, ``exact``,
      ``refinement``'s certificates) such round-off slides reach 8e-15 of ``1 + max |d|``
      (planar), 4e-17 (exact) and 6e-16 (certificates), every real slide is aligned,
      and ``1e-9`` leaves five orders of margin while still flagging a slide of 7e-5
      against motions of order 1.

    Hand conditions (thesis eqs. hand_eq .. underactuation), for a grasp with ``J``, when
    ``actuator_forces`` ``f`` are given (``R`` defaults to the identity, ``commands`` ``f_c``
    to 0):

    * ``hand_equilibrium``: ``max |J^T c - R f|`` [N m or N per joint].
    * ``actuator_command``: ``max(0, -lambda)`` with ``lambda = f - f_c + K v`` the stop's
      reaction (``K`` the actuator stiffness, 0 in the thesis, ``v`` as below, taken 0
      without ``q``): an actuator never gives less than its command (less its spring's
      relief); ``|lambda|`` for a backdrivable one (``Grasp.backdrivable``: a constant
      force source or a spring, no stop). The two conditions below skip backdrivable
      actuators.
    * ``nonbackdrivable`` (needs ``hand_motion`` ``q``): ``max(0, -(v + g))`` with
      transmission motion ``v = R^T (q - q_ref)`` and ``g`` the stop gap (0 in the
      thesis): no transmission runs back past its stop. ``q_ref`` (``hand_reference``) is
      where the actuators lock, 0 unless the method applied a commanded preload first
      (``iterative``).
    * ``actuator_complementarity`` (needs ``q``): ``max min(lambda, v + g)`` over the
      actuators where both are >= 0: an actuator off its stop gives exactly its command
      less its spring; one loaded beyond that rests on its stop. Transmission motion is
      virtual, like ``r``.
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
        d = grasp.contact_motion(motion, hand_motion)
        dn, dt = d[:, 0], d[:, 1:]
        res["spring_law"] = float(np.max(np.abs(cn - grasp.spring_force(dn, preload))))
        diss = np.einsum("ij,ij->i", ct, dt) + grasp.mu * cn * np.linalg.norm(dt, axis=1)
        res["max_dissipation"] = float(np.max(np.abs(diss)))
        res["slide_alignment"] = slide_alignment(grasp.mu, c, d)
    if actuator_forces is not None and grasp.J is not None:
        f = np.asarray(actuator_forces, dtype=float)
        R = np.eye(grasp.J.shape[1]) if grasp.R is None else grasp.R
        fc = np.zeros(R.shape[1]) if commands is None else np.asarray(commands, dtype=float)
        back = getattr(grasp, "backdrivable", None)
        back = np.zeros(R.shape[1], dtype=bool) if back is None else np.asarray(back, bool)
        K, gap = actuator_compliance(grasp, R.shape[1])
        res["hand_equilibrium"] = float(np.max(np.abs(grasp.J.T @ c.reshape(-1) - R @ f)))
        v = np.zeros(R.shape[1])
        if hand_motion is not None:
            q = np.asarray(hand_motion, dtype=float)
            if hand_reference is not None:
                q = q - np.asarray(hand_reference, dtype=float)
            v = R.T @ q
        lam = f - fc + K * v  # the stop's reaction
        short = np.where(back, np.abs(lam), np.maximum(0.0, -lam))
        res["actuator_command"] = float(np.max(short, initial=0.0))
        if hand_motion is not None:
            w = np.where(back, 0.0, v + gap)  # a backdrivable transmission moves freely
            res["nonbackdrivable"] = float(np.max(np.maximum(0.0, -w), initial=0.0)) + 0.0
            both = np.minimum(np.maximum(lam, 0.0), np.maximum(w, 0.0))
            res["actuator_complementarity"] = float(np.max(both, initial=0.0))
    return res


def motion_excess(grasp: Grasp, limit: MotionLimit, motion: NDArray[np.float64]) -> float:
    """How far the object motion ``r`` exceeds ``limit`` (a validated
    :class:`~stability.queries.MotionLimit`): ``max(0, |v + omega x p| - shift,
    |omega| - turn)`` [the grasp's length unit, rad], 0 within it."""
    r = np.asarray(motion, dtype=float)
    k, p = grasp.dim, np.asarray(limit.point, dtype=float)
    v, w = r[:k], r[k:]
    if grasp.planar:
        shift = v + w[0] * np.array([-p[1], p[0]])
    else:
        shift = v + np.cross(w, p)
    over = max(float(np.linalg.norm(shift)) - limit.shift, float(np.linalg.norm(w)) - limit.turn)
    return max(0.0, over)


def slide_alignment(
    mu: NDArray[np.float64], forces: NDArray[np.float64], motion: NDArray[np.float64]
) -> float:
    """The ``slide_alignment`` residual of :func:`model_residuals`: ``max |c_t + mu c_n
    d_t / |d_t||`` [N] over the contacts with ``c_n > 0`` and ``|d_t| > SLIDE_TOL (1 +
    max |d|)``, 0 when none slides; ``forces`` and contact ``motion`` ``d`` are (m, k)."""
    c, d = np.asarray(forces, dtype=float), np.asarray(motion, dtype=float)
    cn, ct, dt = c[:, 0], c[:, 1:], d[:, 1:]
    dtn = np.linalg.norm(dt, axis=1)
    tol = SLIDE_TOL * (1.0 + float(np.max(np.abs(d), initial=0.0)))
    slides = (dtn > tol) & (cn > 0.0)
    u = dt[slides] / dtn[slides, None]
    miss = ct[slides] + (np.asarray(mu, dtype=float)[slides] * cn[slides])[:, None] * u
    return float(np.max(np.linalg.norm(miss, axis=1), initial=0.0))


class Stats(MutableMapping[str, Any]):
    """A solve's statistics: a dict of the method's own keys, with the keys every method
    shares read as typed attributes (None where the method did not set the key).

    ``stats["nodes"]`` and ``stats.nodes`` read the same entry; entries are written by key.
    Wrapping a dict does not copy it: what the method adds to it later is seen here.
    """

    def __init__(self, data: Mapping[str, Any] | None = None) -> None:
        self._data: dict[str, Any] = (
            data if isinstance(data, dict) else dict(data or {})
        )  # the method's dict itself, not a copy

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __setitem__(self, key: str, value: Any) -> None:
        self._data[key] = value

    def __delitem__(self, key: str) -> None:
        del self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"Stats({self._data!r})"

    def copy(self) -> dict[str, Any]:
        """A plain dict of the entries."""
        return dict(self._data)

    @property
    def time_s(self) -> float | None:
        """Wall time of the method call [s] (set by :func:`stability.solve`)."""
        return self._data.get("time_s")

    @property
    def message(self) -> str | None:
        """Why the status is not ``"solved"``, or what else to know about the answer."""
        return self._data.get("message")

    @property
    def reason(self) -> str | None:
        """Why the answer is what it is (an infeasible model, a limit reached, ...)."""
        return self._data.get("reason")

    @property
    def backend(self) -> str | None:
        """The solver the method used (``"highs"``, ``"scip"``, ``"gurobi"``)."""
        return self._data.get("backend")

    @property
    def certified(self) -> bool | None:
        """The bracket ``[lower, upper]`` is closed to the method's tolerance."""
        return self._data.get("certified")

    @property
    def capped(self) -> bool | None:
        """MaxDisturbance: the value reached the query's cap ("at least cap")."""
        return self._data.get("capped")

    @property
    def force_bound(self) -> float | None:
        """The model's force bound ``B`` [N] (the box's scale)."""
        return self._data.get("force_bound")

    @property
    def box_reached(self) -> bool | str | None:
        """The answer reaches the model's box (a string says how): its dual bound holds
        only inside the box."""
        return self._data.get("box_reached")

    @property
    def box_enlarged(self) -> list[str] | None:
        """One line per tenfold enlargement of the box (:func:`stability.options.enlarge_box`)."""
        return self._data.get("box_enlarged")

    @property
    def nodes(self) -> int | None:
        """Branch-and-bound nodes (the MIPs' or the mode search's)."""
        return self._data.get("nodes")


@dataclass
class Solution:
    """Answer of one method to one query.

    Attributes
    ----------
    stable : bool or None
        None when the method gave no answer (``status`` is not ``"solved"``).
        Existence: an equilibrium exists. MaxDisturbance: some ``s`` in
        ``[0, cap]`` is stable, and ``value`` is the largest such ``s`` (the
        supremum of the stable set along the ray, which need not be an
        interval starting at 0; with an unbalanced preload ``s = 0`` itself
        can be unstable).
    forces : (m, 2) or (m, 3) array or None
        Contact forces on the object in contact frames, ``[c_n, c_t]`` planar,
        ``[c_n, c_t1, c_t2]`` spatial [N].
    motion : array or None
        Object motion ``r`` (planar ``(x, y, theta)``); virtual with the thesis' unit
        springs (in newtons), in metres and radians with physical ``Grasp.stiffness``.
        None where the method has no motion (``gws``).
    value : float or None
        Optimisation queries: the optimum (MaxDisturbance: largest ``s``); set on every
        stable answer, None on an unstable one (no ``s`` in ``[0, cap]`` holds; no
        commands within the limits hold).
    states : (m,) array of str or None
        Per-contact state: planar ``"roll"``, ``"slip+"``, ``"slip-"``, ``"detach"``;
        the 3D MIP methods ``"stick"``, ``"slip"`` (tangential motion), ``"detach"``.
    stats : Stats
        A dict-like :class:`Stats`: at least ``time_s``; methods add counts (states
        visited, LPs solved, ...); the keys every method shares are typed attributes
        (``stats.time_s``, ``stats.certified``, ...).
    status : str
        ``"solved"`` (``stable`` is the answer), ``"timeout"`` (the method's ``time_limit``
        ran out), ``"not_converged"`` (an iterative scheme hit its iteration cap or
        stopped where it cannot answer) or ``"error"`` (a backend failed, or the answer
        lacked what it must carry); ``stats["message"]`` says why. Only ``"solved"``
        carries an answer: the others have ``stable=None``. A stable answer of an
        optimisation query (MaxDisturbance, OptimalCommands) always has a finite
        ``value``: :func:`stability.solve` turns one without into ``"error"``.
    actuator_forces : (a,) array or None
        Hands: actuator forces ``f`` with ``J^T c = R f`` [N or N m].
    commands : (a,) array or None
        OptimalCommands: the optimal actuator commands ``f_c``.
    lower, upper : float or None
        Optimisation queries of the methods that bracket their answer (``refinement``,
        ``exact``): the optimum lies in ``[lower, upper]``. The bound on the feasible side
        (MaxDisturbance: ``lower``; OptimalCommands: ``upper``) is the value of an exact
        solution (the returned one when ``value`` equals it, which then passes
        :meth:`residuals`); the other is proven by a relaxation (or SCIP's dual bound).
        None where no such bound is known. ``stats["certified"]`` is True when the bracket
        is closed to the method's tolerance. A time-out keeps the bracket reached so far.
    hand_reference : (l,) array or None
        Hands: the joint motion ``q_ref`` where the nonbackdrivable actuators lock
        (``R^T (q - q_ref) >= 0``); None means 0 (commands and disturbance applied at once).
    conditions : tuple of str or None
        The :func:`model_residuals` keys the method enforces (None: all of them), which
        ``max_residual(enforced=True)`` checks; plain :meth:`max_residual` checks every
        condition of the model. A baseline that drops a condition (``no_mdp`` has no
        maximum dissipation) still reports its residual, so the difference is visible.
    """

    stable: bool | None
    method: str
    grasp: Grasp
    query: Query
    forces: NDArray[np.float64] | None = None
    motion: NDArray[np.float64] | None = None
    hand_motion: NDArray[np.float64] | None = None
    value: float | None = None
    states: NDArray[np.str_] | None = None
    stats: Stats = field(default_factory=Stats)
    status: str = "solved"
    actuator_forces: NDArray[np.float64] | None = None
    hand_reference: NDArray[np.float64] | None = None
    conditions: tuple[str, ...] | None = None
    commands: NDArray[np.float64] | None = None
    lower: float | None = None
    upper: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.stats, Stats):
            self.stats = Stats(self.stats)

    @property
    def wrench(self) -> NDArray[np.float64]:
        """The external wrench this solution balances."""
        q = self.query
        if isinstance(q, MaxDisturbance):
            s = 0.0 if self.value is None else self.value
            w = s * np.asarray(q.direction, dtype=float)
            return w if q.base is None else w + np.asarray(q.base, dtype=float)
        return np.asarray(q.wrench, dtype=float)

    def residuals(self) -> dict[str, float]:
        """Violation of each model condition by the returned forces and motion.

        See :func:`model_residuals`; with a query's motion limit also ``motion_limit``
        (:func:`motion_excess`, and at the contacts the limit keeps open the larger of
        ``|c_n|`` [N] and ``max(0, p - k d_n)`` [N], the spring's push were it closed).
        Methods without a passive model (``gws``) return no motion, so only equilibrium and
        cone terms appear.
        Raises ``ValueError`` when there is no solution to check.
        """
        if self.forces is None:
            raise ValueError(f"no forces to check: the {self.method!r} answer is unstable")
        q = self.query
        preload = commands = None
        if isinstance(q, Existence | MaxDisturbance) and self.motion is not None:
            preload = self.grasp.per_contact(q.preload, "preload", nonneg=False)
        if isinstance(q, Existence | MaxDisturbance) and q.commands is not None:
            commands = np.asarray(q.commands, dtype=float)
        if self.commands is not None:  # OptimalCommands: the commands found
            commands = self.commands
        if not isinstance(q, Existence | MaxDisturbance) and self.motion is not None:
            preload = self.grasp.per_contact(q.preload, "preload", nonneg=False)
        res = model_residuals(
            self.grasp,
            self.wrench,
            self.forces,
            self.motion,
            preload,
            self.hand_motion,
            self.actuator_forces,
            commands,
            self.hand_reference,
        )
        limit = checked_motion_limit(self.grasp, q)
        if limit is not None and self.motion is not None:
            res["motion_limit"] = motion_excess(self.grasp, limit, self.motion)
            if np.any(limit.open):  # a contact kept open: c_n = 0 and k d_n >= p
                d = self.grasp.contact_motion(self.motion, self.hand_motion)[limit.open, 0]
                k = self.grasp.stiffness[limit.open]
                cn = np.asarray(self.forces, dtype=float).reshape(self.grasp.m, -1)[:, 0]
                closing = np.maximum(0.0, preload[limit.open] - k * d)
                worst = max(float(np.max(np.abs(cn[limit.open]))), float(np.max(closing)))
                res["motion_limit"] = max(res["motion_limit"], worst)
        return res

    def max_residual(
        self, conditions: Iterable[str] | None = None, *, enforced: bool = False
    ) -> float:
        """Largest entry of :meth:`residuals`: by default over *every* condition the model
        states (all its keys), whatever the method enforces, so a method that drops one
        (``no_mdp``: maximum dissipation; ``refinement``'s uncertified answer: the circular
        cone, exceeded by at most ``stats["cone_excess_bound"]``, and maximum dissipation)
        shows it here.

        ``conditions``: only these keys (:data:`MODEL_CONDITIONS`; one that needs data the
        answer lacks, e.g. ``spring_law`` without motion, is skipped). ``enforced=True``:
        only the method's own :attr:`conditions` (what it promises; all of them when None).
        Raises ``ValueError`` for an unknown key, for both arguments at once, or when none
        of the asked conditions can be checked."""
        if conditions is not None and enforced:
            raise ValueError("max_residual: give conditions or enforced=True, not both")
        res = self.residuals()
        if enforced:
            conditions = self.conditions
        if conditions is None:
            return max(res.values())
        keys = (conditions,) if isinstance(conditions, str) else tuple(conditions)
        bad = sorted(set(keys) - set(MODEL_CONDITIONS))
        if bad:
            raise ValueError(f"max_residual: unknown condition(s) {bad}; known: {MODEL_CONDITIONS}")
        have = [res[k] for k in keys if k in res]
        if not have:
            raise ValueError(f"max_residual: none of {list(keys)} can be checked on this "
                             f"answer (it has {sorted(res)})")  # fmt: skip
        return max(have)
