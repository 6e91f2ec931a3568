"""The lookahead shield: a grasp shield's criteria judged on a simulation (the yardstick).

:class:`Lookahead` answers the question the QP shield (:mod:`shields.qp`) cannot separate:
is shielding the hand a bad idea, or is the linear model too poor? It judges an action by
simulating it on a private copy of the MuJoCo state (``mj_getState`` / ``mj_setState`` of
``mjSTATE_INTEGRATION``: positions, velocities, setpoints, the solver's warm start), so its
prediction of the next state is what the env will do, bit for bit (tested). It needs a
simulator of the hand: it is the yardstick for model-based shields, not a deployable
controller.

An action ``a`` (in ``[-1, 1]^l``; setpoints ``clip(ctrl + s a)`` to the ``ctrlrange``, ``s``
the env's ``max_setpoint_step`` [rad]) is **unsafe** when, at the end of its simulated
policy step,

1. the object is dropped or out of the hand (the env's termination: centre below
   ``drop_z`` or farther than ``out_radius`` from the palm axis), or
2. the object's origin leaves the box of :class:`shields.qp.ShieldLimits`, or (with
   ``tilt``) its tilt angles ``(r_x, r_y)`` (:func:`shields.qp.tilt_angles`) leave the tilt
   bounds; a bound the object violates before the step is relaxed to its value then (it
   must not get worse), as in the QP, or
3. (with ``contacts``) the grasp after it has no set of at least two touching links in
   force closure whose contacts all satisfy the QP's contact rows at the simulated contact
   forces: normal force ``>= c_min`` and (with ``friction``) inside the inscribed friction
   pyramid with torsion (the rows of :meth:`shields.qp.GraspQP.problem` at ``a~ = 0``).

With ``contacts``, when the grasp before the step has no force-closure set of touching links
the QP shield passes every action (``"no_closure"``); then only criterion 1 counts here.

With the same :class:`~shields.qp.ShieldLimits` these are the QP shield's constraints, read
off the simulated state instead of predicted by the linearisation, plus the env's
termination (1). What differs besides the model is the search: bisection on ``lambda a``
and a home action here, the nearest action under the linear constraints in the QP.

``horizon = H > 1`` also simulates ``H - 1`` further policy steps with the setpoints held
after the action and asks 1 and 2 (1 alone without a force-closure set before the step) at
the end of each: could the hand still hold the object if it stopped here? (A one-step
lookahead lets a random policy loosen the grasp step by step until no single step can save it.)

The search (``bisections = n``): simulate ``a``; if it is safe, return it unchanged
(``"safe"``). Otherwise simulate the fallback ``0`` (keep every setpoint, the QP shield's
fallback); if it is safe, bisect ``lambda`` in ``[0, 1]`` ``n`` times on the segment
``lambda a`` and return the largest safe point found (``"corrected"``). If the fallback is
unsafe and a home grasp is given (the wrapper passes the episode's start setpoints), try the
action that moves every setpoint towards it by up to one step, ``clip((ctrl_home - ctrl) /
s, -1, 1)`` (``"home"`` when safe). If nothing tried is safe, return the less severe of the
two (drop > box > tilt > contacts, then the larger margin to the termination):
``"fallback"``. A returned ``"safe"``, ``"corrected"`` or ``"home"`` action is always one
whose own simulation was safe; the agent's unsafe action is never executed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.four_finger import DROP_Z, OUT_RADIUS
from shields.compliance import ShieldError
from shields.qp import GraspQP, ShieldLimits, tilt_angles

__all__ = ["LOOKAHEAD_STATUSES", "Lookahead", "LookaheadResult"]

LOOKAHEAD_STATUSES = ("safe", "corrected", "home", "fallback")
_SEVERITY = {"": 0, "contacts": 1, "tilt": 2, "box": 3, "drop": 4}  # fallback: least severe
_TOL = 1e-6  # accepted constraint violation [N], as the QP's
_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


@dataclass
class LookaheadResult:
    """What the lookahead shield did in one step.

    action : (l,) the action to execute ``a~``
    status : one of :data:`LOOKAHEAD_STATUSES`
    links : the force-closure link set whose contacts hold after ``a~`` (empty when criterion
        3 was waived or ``a~`` is an unsafe fallback)
    correction : ``||a~ - a||`` (action units)
    scale : ``lambda`` with ``a~ = lambda a`` (1 for ``"safe"``, 0 for ``"fallback"``)
    sims : policy steps simulated
    reason : why the agent's action was unsafe (``""`` when safe): ``"drop"``, ``"box"``,
        ``"tilt"`` or ``"contacts"``
    solve_time_s : wall time of the call [s]
    """

    action: NDArray[np.float64]
    status: str
    links: tuple[str, ...]
    correction: float
    scale: float
    sims: int
    reason: str
    solve_time_s: float


class Lookahead:
    """The lookahead shield of the module docstring for one MuJoCo model.

    Parameters
    ----------
    model : the scene (the env's own ``MjModel``, randomised values included).
    max_setpoint_step : ``s`` [rad]: setpoints change by ``s a``.
    frame_skip : physics steps per policy step.
    limits : the QP shield's :class:`shields.qp.ShieldLimits` (``c_min``, pyramid, box, tilt).
    bisections : bisection steps on the segment to the fallback (>= 0).
    horizon : policy steps simulated per candidate, the action's and ``horizon - 1`` held
        (>= 1; module docstring).
    drop_z, out_radius : the env's termination [m].
    object_body : the object's body name.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        max_setpoint_step: float,
        frame_skip: int,
        limits: ShieldLimits | None = None,
        bisections: int = 3,
        horizon: int = 1,
        drop_z: float = DROP_Z,
        out_radius: float = OUT_RADIUS,
        object_body: str = "object",
    ) -> None:
        for name, v, least in (("frame_skip", frame_skip, 1), ("bisections", bisections, 0),
                               ("horizon", horizon, 1)):  # fmt: skip
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
                raise ShieldError(f"{name} must be an integer >= {least}, got {v!r}")
        self.horizon = int(horizon)
        self.model = model
        self.frame_skip = int(frame_skip)
        self.bisections = int(bisections)
        self.drop_z, self.out_radius = float(drop_z), float(out_radius)
        # the QP shield's constraint rows (its problem() at a~ = 0) are the contact criterion
        self.qp = GraspQP(
            model,
            max_setpoint_step=max_setpoint_step,
            horizon=model.opt.timestep * self.frame_skip,
            limits=limits,
            object_body=object_body,
        )
        self.limits = self.qp.limits
        if self.limits.relax_contacts:
            raise ShieldError(
                "the lookahead shield has no relax_contacts (it judges the state "
                "after the step, not a prediction from now)"
            )
        self.step = self.qp.step
        self.l = model.nu
        self.ctrl_low, self.ctrl_high = self.qp.ctrl_low, self.qp.ctrl_high
        jnt = model.body(object_body).jntadr[0]
        if jnt < 0 or model.jnt_type[jnt] != mujoco.mjtJoint.mjJNT_FREE:
            raise ShieldError(f"body {object_body!r} needs a free joint")
        self._adr = int(model.jnt_qposadr[jnt])
        self.sim = mujoco.MjData(model)
        self._state = np.empty(mujoco.mj_stateSize(model, _SPEC))
        self._mat = np.empty(9)

    # -- the model: one policy step on the copy ---------------------------------------------
    def simulate(self, data: mujoco.MjData, action: NDArray[np.float64]) -> mujoco.MjData:
        """The state one policy step after ``data`` with ``action`` (on :attr:`sim`, a private
        ``MjData``; ``data`` is only read). Call :meth:`load` first when ``data`` changed."""
        sim = self.sim
        mujoco.mj_setState(self.model, sim, self._state, _SPEC)
        ctrl = data.ctrl + action * self.step
        np.minimum(np.maximum(ctrl, self.ctrl_low, out=ctrl), self.ctrl_high, out=sim.ctrl)
        mujoco.mj_step(self.model, sim, nstep=self.frame_skip)
        return sim

    def load(self, data: mujoco.MjData) -> None:
        """Copy ``data``'s integration state into the shield (what :meth:`simulate` starts
        from)."""
        mujoco.mj_getState(self.model, data, self._state, _SPEC)

    # -- the criteria ----------------------------------------------------------------------
    def _pose(self, data: mujoco.MjData) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The object's origin (3,) [m] and tilt angles (2,) [rad] in ``data``'s ``qpos``."""
        q = data.qpos[self._adr : self._adr + 7]
        mujoco.mju_quat2Mat(self._mat, q[3:])
        r, _ = tilt_angles(self._mat.reshape(3, 3))
        return q[:3].copy(), r

    def _stable_links(self, data: mujoco.MjData) -> tuple[str, ...] | None:
        """The touching links whose contacts satisfy the QP's rows at ``data``'s contact
        forces, if they include a force-closure set; None otherwise."""
        try:
            prob = self.qp.problem(data)
        except ShieldError:
            return None
        if len(prob.groups) < 2 or not np.isfinite(prob.low_contact).all():
            return None
        ok_contact = prob.low_contact.max(axis=1) <= _TOL  # rows at a~ = 0: 0 >= low
        mask = 0
        for g, members in enumerate(prob.groups):
            if ok_contact[members].all():
                mask |= 1 << g
        if not prob.closure(mask):
            return None
        return tuple(prob.links[g] for g in prob.members(mask))

    def closure_now(self, data: mujoco.MjData) -> bool:
        """Whether the touching links at ``data`` include a force-closure set (the QP shield's
        test before it shields anything)."""
        try:
            prob = self.qp.problem(data)
        except ShieldError:
            return False
        n = len(prob.groups)
        return n >= 2 and prob.closure((1 << n) - 1)

    def verdict(
        self,
        after: mujoco.MjData,
        pose_now: tuple[NDArray[np.float64], NDArray[np.float64]],
        closure: bool = True,
        contacts: bool = True,
    ) -> tuple[str, tuple[str, ...]]:
        """``(reason, links)`` for the state ``after`` a step (module docstring): reason ``""``
        when safe; ``pose_now`` the object's origin and tilt before the step; ``closure``
        whether the grasp before it had a force-closure set (with ``limits.contacts`` and
        without one, only the termination counts, as the QP passes every action then);
        ``contacts=False`` skips criterion 3 (the held steps of the horizon)."""
        p, r = self._pose(after)
        if not np.all(np.isfinite(p)) or not np.all(np.isfinite(r)):
            return "drop", ()
        if p[2] < self.drop_z or math.hypot(p[0], p[1]) > self.out_radius:
            return "drop", ()
        lim = self.limits
        if lim.contacts and not closure:
            return "", ()
        p0, r0 = pose_now
        lo, hi = np.minimum(lim.box_low, p0), np.maximum(lim.box_high, p0)
        if np.any(p < lo - _TOL) or np.any(p > hi + _TOL):
            return "box", ()
        lo_r, hi_r = np.minimum(lim.tilt_low, r0), np.maximum(lim.tilt_high, r0)
        if lim.tilt and (np.any(r < lo_r - _TOL) or np.any(r > hi_r + _TOL)):
            return "tilt", ()
        if not lim.contacts or not contacts:
            return "", ()
        links = self._stable_links(after)
        return ("", links) if links is not None else ("contacts", ())

    # -- the shield ------------------------------------------------------------------------
    def __call__(
        self,
        data: mujoco.MjData,
        action: NDArray[Any],
        home_ctrl: NDArray[np.float64] | None = None,
    ) -> LookaheadResult:
        """Shield ``action`` (l,) in ``[-1, 1]`` at the state ``data`` (as the env leaves it
        after a step or a reset); ``home_ctrl``: the setpoints of a grasp to return towards
        when the fallback is unsafe (the episode's start grasp; module docstring). ``data`` is
        only read."""
        t0 = time.perf_counter()
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.l,):
            raise ShieldError(f"action must have shape ({self.l},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ShieldError(f"action contains NaN or inf: {a}")
        self.load(data)
        pose = self._pose(data)
        # the QP shield's test before it shields anything: without a force-closure set it
        # passes every action, and then only the termination counts here
        closure = self.closure_now(data) if self.limits.contacts else True
        sims = [0]

        def judge(x: NDArray[np.float64]) -> tuple[str, tuple[str, ...], float]:
            """(reason, links, margin): margin [m] to the drop height and the out radius."""
            after = self.simulate(data, x)
            sims[0] += 1
            reason, links = self.verdict(after, pose, closure)
            for _ in range(self.horizon - 1):  # then hold the setpoints: can it still hold?
                if reason:
                    break
                mujoco.mj_step(self.model, after, nstep=self.frame_skip)
                sims[0] += 1
                reason, _ = self.verdict(after, pose, closure, contacts=False)
            p = after.qpos[self._adr : self._adr + 3]
            margin = min(p[2] - self.drop_z, self.out_radius - math.hypot(p[0], p[1]))
            return reason, links, float(margin) if math.isfinite(margin) else -math.inf

        def done(x: NDArray, status: str, links: tuple, lam: float, why: str) -> LookaheadResult:
            return LookaheadResult(
                action=x, status=status, links=links, correction=float(np.linalg.norm(x - a)),
                scale=lam, sims=sims[0], reason=why, solve_time_s=time.perf_counter() - t0,
            )  # fmt: skip

        why, links, _ = judge(a)
        if not why:
            return done(a.copy(), "safe", links, 1.0, "")
        zero = np.zeros(self.l)
        reason0, links0, margin0 = judge(zero)
        if reason0:
            if home_ctrl is None:
                return done(zero, "fallback", (), 0.0, why)
            home = np.clip((np.asarray(home_ctrl, dtype=np.float64) - data.ctrl) / self.step, -1, 1)
            reason_h, links_h, margin_h = judge(home)
            if not reason_h:
                return done(home, "home", links_h, math.nan, why)
            worse = (_SEVERITY[reason_h], -margin_h) > (_SEVERITY[reason0], -margin0)
            return (
                done(zero, "fallback", (), 0.0, why)
                if worse
                else done(home, "fallback", (), math.nan, why)
            )
        lo, hi, best, best_links = 0.0, 1.0, 0.0, links0
        for _ in range(self.bisections):
            mid = 0.5 * (lo + hi)
            r_mid, l_mid, _ = judge(mid * a)
            if r_mid:
                hi = mid
            else:
                lo = best = mid
                best_links = l_mid
        return done(best * a, "corrected", best_links, best, why)
