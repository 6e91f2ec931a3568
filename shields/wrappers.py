"""Gymnasium wrappers that put a shield between the agent and the env (thesis Fig. "Shield RL").

Every action the agent sends through :meth:`step` is first clipped to the env's Box action
space, ``clip(a_t) = clip(a_t, low, high)`` (what the env would do with it anyway), and then
goes through the shield ``a~_t = Psi(clip(a_t), s_t)`` (thesis eq. shield) before it reaches the
inner env; the inner env receives ``a~_t``, which lies in the action box, so it applies it as it
is. The shield thus answers for the step the env would actually take. Each step's ``info``
carries

- ``agent_action``: ``a_t`` as the agent sent it (float64 copy, not clipped),
- ``executed_action``: ``a~_t``, what the inner env received and applied (float64): the step
  actually taken, always inside the action box,
- ``shield_intervened``: ``True`` when the shield changed the in-box action ``clip(a_t)`` for
  safety; clipping alone is not an intervention (a safe out-of-box action is executed as its
  clipped value with ``shield_intervened=False``),
- ``shield_step_seconds``: the shield's wall time in this step [s],
- ``shield_episode_interventions``, ``shield_episode_seconds``: the interventions and the
  shield's wall time [s] since the last reset, this step included (what a ``Monitor`` with
  these ``info_keywords`` logs per episode).

The executed action is passed on in float64 (not cast to the action space's float32) so that the
smart shield's exact projection is not perturbed by a float32 rounding of ~1e-8.

Interface the wrapped env must expose on ``env.unwrapped``:

================  ========================================================  ===============
name              meaning                                                   used by
================  ========================================================  ===============
``state``         current state ``s`` (2,), float64                         both
``predict``       ``predict(s, a) -> s_{t+1}`` one-step model               both
``safe_distance`` ``M(s)``, signed distance to the region's edge (>=0 safe)  both
``safe_pieces``   convex pieces (``Disc``/``Box``) whose union is safe      ``SmartShield``
``action_scale``  ``k``: ``predict(s, a) = s + k clip(a, low, high)``        ``SmartShield``
================  ========================================================  ===============
"""

from __future__ import annotations

import time
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from shields.compliance import ShieldError
from shields.islands_shields import simple_shield, smart_shield
from shields.lookahead import Lookahead, LookaheadResult
from shields.qp import GraspQP, ShieldLimits, ShieldResult

__all__ = [
    "DRIFT_STEPS",
    "HORIZON",
    "SHIELDS",
    "GraspShield",
    "GuardedShield",
    "LookaheadShield",
    "SimpleShield",
    "SmartShield",
    "drop_limits",
    "make_shield",
]


class _ShieldWrapper(gym.Wrapper):
    """Common part: interface checks and the ``info`` bookkeeping."""

    _required: tuple[str, ...] = ("state", "predict", "safe_distance")

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        if not isinstance(env.action_space, spaces.Box):
            raise TypeError(
                f"{type(self).__name__} needs a Box action space, got {env.action_space!r}"
            )
        missing = [n for n in self._required if not hasattr(env.unwrapped, n)]
        if missing:
            raise TypeError(
                f"{type(self).__name__} needs env.unwrapped to expose {list(self._required)}; "
                f"{type(env.unwrapped).__name__} lacks {missing}"
            )
        #: The action box ``[low, high]`` (float64) that agent actions are clipped to.
        self._low = np.array(env.action_space.low, dtype=np.float64)
        self._high = np.array(env.action_space.high, dtype=np.float64)
        self._episode: list[Any] = [0, 0.0]  # this episode's interventions, shield time [s]

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """``(a~, intervened)`` for an in-box action ``clip(a)`` in the current state."""
        raise NotImplementedError

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Clip the action to the action box, shield it, step the inner env with the result,
        record the agent's and the executed action in ``info``."""
        agent_action = np.array(action, dtype=np.float64)
        clipped = np.minimum(np.maximum(agent_action, self._low), self._high)  # np.clip, faster
        t0 = time.perf_counter()
        executed, intervened = self.shield(clipped)
        seconds = time.perf_counter() - t0
        self._episode[0] += bool(intervened)
        self._episode[1] += seconds
        extra = self.shield_info()
        obs, reward, terminated, truncated, info = self.env.step(executed)
        info = dict(info)
        info["agent_action"] = agent_action
        info["executed_action"] = np.array(executed, dtype=np.float64)
        info["shield_intervened"] = bool(intervened)
        info["shield_step_seconds"] = seconds
        info["shield_episode_interventions"] = int(self._episode[0])
        info["shield_episode_seconds"] = float(self._episode[1])
        info.update(extra)
        return obs, reward, terminated, truncated, info

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset the inner env and the episode's shield counters."""
        self._episode = [0, 0.0]
        return self.env.reset(**kwargs)

    def shield_info(self) -> dict[str, Any]:
        """Extra ``info`` entries of the last :meth:`shield` call (none by default)."""
        return {}


class SimpleShield(_ShieldWrapper):
    """Thesis ``Psi_simple`` on the clipped action: ``a~ = clip(a) if M(predict(s, clip(a)))
    >= 0 else 0`` (a zero step).

    Works for any Box action space whose env exposes ``state``, ``predict`` and
    ``safe_distance`` on ``env.unwrapped``; raises ``TypeError`` otherwise.
    """

    _required = ("state", "predict", "safe_distance")

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """See :func:`shields.islands_shields.simple_shield`."""
        u = self.env.unwrapped
        return simple_shield(u.state, action, u.predict, u.safe_distance)


class SmartShield(_ShieldWrapper):
    """Thesis ``Psi_smart``: ``a~ = argmin ||a~ - clip(a)|| s.t. M(s + k a~) >= 0, a~ in the
    action box`` -- the safe action nearest to the clipped one, computed exactly
    (:func:`shields.islands_shields.smart_shield`).

    Needs a 2D Box action space and ``state``, ``predict``, ``safe_distance``, ``safe_pieces``,
    ``action_scale`` on ``env.unwrapped`` (affine model ``predict(s, a) = s + k clip(a)``);
    raises ``TypeError`` otherwise.
    """

    _required = ("state", "predict", "safe_distance", "safe_pieces", "action_scale")

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        if env.action_space.shape != (2,):
            raise TypeError(
                f"SmartShield needs a 2D Box action space, got shape {env.action_space.shape}"
            )

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """See :func:`shields.islands_shields.smart_shield`."""
        u = self.env.unwrapped
        return smart_shield(
            u.state, action, u.safe_pieces, float(u.action_scale), self._low, self._high
        )


def _result_info(r: ShieldResult | LookaheadResult | None) -> dict[str, Any]:
    """The ``info`` entries every grasp shield gives: ``shield_correction``,
    ``shield_subset``, ``shield_status``, ``shield_solve_time_s`` (none before a step)."""
    if r is None:
        return {}
    return {
        "shield_correction": r.correction,
        "shield_subset": r.links,
        "shield_status": r.status,
        "shield_solve_time_s": r.solve_time_s,
    }


def _grasp_qp(
    env: gym.Env, limits: ShieldLimits | None, backend: str, drift_steps: float
) -> GraspQP:
    """A :class:`shields.qp.GraspQP` for the four-finger env ``env`` (its model, setpoint
    step and policy period)."""
    u = env.unwrapped
    return GraspQP(
        u.model,
        max_setpoint_step=float(u.max_setpoint_step),
        horizon=float(u.dt),
        limits=limits,
        backend=backend,
        drift_steps=drift_steps,
    )


class GraspShield(_ShieldWrapper):
    """The linearised-compliance QP shield (:class:`shields.qp.GraspQP`) around the
    four-finger env (``ihm/FourFingerRotate-v0`` or any env whose ``unwrapped`` exposes
    ``model``, ``data``, ``max_setpoint_step`` [rad] and ``dt`` [s]).

    Each step the clipped agent action goes through the QP at the env's current state; the
    inner env executes the result. Besides the common keys (module docstring) ``info``
    carries

    - ``shield_correction``: ``||a~ - clip(a)||``,
    - ``shield_subset``: the shielded links (tuple of MJCF body names),
    - ``shield_status``: ``"safe"``, ``"corrected"``, ``"fallback"`` or ``"no_closure"``
      (:mod:`shields.qp`),
    - ``shield_solve_time_s``: the shield's wall time for this step [s].

    ``shield_intervened`` is True for ``"corrected"`` and ``"fallback"``. The shield never
    raises inside ``step`` for an infeasible situation (it takes the fallback); a NaN action
    raises the env's error as without the shield.

    Parameters
    ----------
    env : the env.
    backend : QP backend, ``"daqp"`` (default, faster) or ``"osqp"``.
    limits : :class:`shields.qp.ShieldLimits` (``c_min``, friction pyramid edges, object
        box and tilt).
    drift_steps : the object keeps its velocity for this many policy periods in the
        prediction (:class:`shields.qp.GraspQP`; 0: the thesis' model).
    """

    _required = ("model", "data", "max_setpoint_step", "dt")

    def __init__(
        self,
        env: gym.Env,
        backend: str = "daqp",
        limits: ShieldLimits | None = None,
        drift_steps: float = 0.0,
    ) -> None:
        super().__init__(env)
        self.qp = _grasp_qp(env, limits, backend, drift_steps)
        self.last_result: ShieldResult | None = None

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """``(a~, intervened)`` from :class:`shields.qp.GraspQP` at the current state."""
        if not np.all(np.isfinite(action)):
            return np.asarray(action, dtype=np.float64), False  # the env raises its error
        res = self.qp(self.env.unwrapped.data, action)
        self.last_result = res
        return res.action, res.status in ("corrected", "fallback")

    def shield_info(self) -> dict[str, Any]:
        """``shield_correction``, ``shield_subset``, ``shield_status``,
        ``shield_solve_time_s`` of the last step."""
        return _result_info(self.last_result)


class GuardedShield(GraspShield):
    """The thesis' QP shield, engaged only near danger: a guard QP on the drop criteria
    (:func:`drop_limits` with the box shrunk by ``margin`` on every side, the object's drift
    over ``drift_steps`` policy periods in its model) first checks the agent's action; if
    the guard finds it safe, it passes unchanged (``shield_status`` ``"safe"``), otherwise the
    thesis' QP (:class:`GraspShield`'s, ``limits``) shields it. The QP shield's force-closure
    rows then act only where the object is predicted to leave the inner box, instead of at
    every step of the gait. ``info`` adds ``shield_guard``: whether the guard passed the action.
    """

    def __init__(
        self,
        env: gym.Env,
        backend: str = "daqp",
        limits: ShieldLimits | None = None,
        margin: float = 0.005,
        drift_steps: float = 4.0,
    ) -> None:
        super().__init__(env, backend=backend, limits=limits)
        if not (np.isfinite(margin) and 0 <= margin < 0.01):
            raise ShieldError(f"margin must be in [0, 0.01) m, got {margin!r}")
        d = drop_limits(env)
        inner = ShieldLimits(
            contacts=False,
            tilt=d.tilt,
            box_low=tuple(np.add(d.box_low, margin).tolist()),
            box_high=tuple(np.subtract(d.box_high, margin).tolist()),
        )
        self.guard = _grasp_qp(env, inner, backend, drift_steps)
        self._guarded = False

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """The agent's action if the guard finds it safe, else the thesis' QP's answer."""
        if not np.all(np.isfinite(action)):
            return np.asarray(action, dtype=np.float64), False
        g = self.guard(self.env.unwrapped.data, action)
        self._guarded = g.status == "safe"
        if self._guarded:
            self.last_result = g
            return g.action, False
        return super().shield(action)

    def shield_info(self) -> dict[str, Any]:
        """:class:`GraspShield`'s entries and ``shield_guard``."""
        return {**super().shield_info(), "shield_guard": self._guarded}


class LookaheadShield(_ShieldWrapper):
    """The lookahead shield (:class:`shields.lookahead.Lookahead`) around the four-finger env:
    the QP shield's criteria judged on a one-step simulation of each candidate action, on a
    copy of the env's MuJoCo state. It needs a simulator of the hand: the yardstick for
    model-based shields, not a deployable controller.

    ``env.unwrapped`` must expose ``model``, ``data``, ``max_setpoint_step`` [rad] and
    ``frame_skip``; an episode with one step of action latency (randomised physics) raises
    :class:`shields.ShieldError` (the shielded action would not be the one the step applies).
    ``info`` carries the common keys (module docstring) and ``shield_correction``,
    ``shield_subset``, ``shield_status`` (``"safe"``, ``"corrected"``, ``"home"``,
    ``"fallback"``), ``shield_solve_time_s`` as :class:`GraspShield`, plus ``shield_scale``
    (``lambda``, ``a~ = lambda clip(a)``; NaN for a home action), ``shield_sims`` (policy
    steps simulated) and ``shield_reason`` (why ``clip(a)`` was unsafe: ``"drop"``, ``"box"``,
    ``"tilt"``, ``"contacts"``, or ``""``). ``shield_intervened`` is True for every status but
    ``"safe"``: the agent's action was judged unsafe (also when the fallback happens to equal
    it, a zero action).

    Parameters
    ----------
    env : the env.
    limits : :class:`shields.qp.ShieldLimits`, the QP shield's.
    bisections : bisection steps on the segment ``lambda clip(a)``, ``lambda`` in [0, 1].
    horizon : policy steps simulated per candidate: the action, then ``horizon - 1`` with the
        setpoints held (:class:`shields.lookahead.Lookahead`).
    """

    _required = ("model", "data", "max_setpoint_step", "frame_skip")

    def __init__(
        self,
        env: gym.Env,
        limits: ShieldLimits | None = None,
        bisections: int = 3,
        horizon: int = 1,
    ) -> None:
        super().__init__(env)
        u = env.unwrapped
        self.lookahead = Lookahead(
            u.model,
            max_setpoint_step=float(u.max_setpoint_step),
            frame_skip=int(u.frame_skip),
            limits=limits,
            bisections=bisections,
            horizon=horizon,
        )
        self.last_result: LookaheadResult | None = None
        self._home: NDArray[np.float64] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset the inner env; its start setpoints become the shield's home grasp."""
        out = super().reset(**kwargs)
        self._home = np.array(self.env.unwrapped.data.ctrl, dtype=np.float64)
        return out

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """``(a~, intervened)`` from :class:`shields.lookahead.Lookahead` at the current
        state."""
        if not np.all(np.isfinite(action)):
            return np.asarray(action, dtype=np.float64), False  # the env raises its error
        u = self.env.unwrapped
        scaler = getattr(u, "scaler", None)
        if scaler is not None and scaler.current.latency:
            raise ShieldError(
                "LookaheadShield cannot shield an episode with action latency: the step "
                "applies the previous action"
            )
        res = self.lookahead(u.data, action, self._home)
        self.last_result = res
        return res.action, res.status != "safe"

    def shield_info(self) -> dict[str, Any]:
        """The ``shield_*`` entries of the last step (class docstring)."""
        r = self.last_result
        if r is None:
            return {}
        return {
            **_result_info(r),
            "shield_scale": r.scale,
            "shield_sims": r.sims,
            "shield_reason": r.reason,
        }


SHIELDS: dict[str, str] = {
    "none": "no shield",
    "qp": "the thesis' linearised-compliance QP shield (GraspShield, ShieldLimits())",
    "qp-drift": "the QP shield on the drop criteria (the object's box, and its tilt unless it "
    "is the sphere; no contact rows) with the object's drift in its model (drift_steps=4)",
    "qp-guard": "the thesis' QP shield engaged only where a guard QP on the drop criteria "
    "(box shrunk by 5 mm, the object's drift over 4 steps) rejects the action (GuardedShield)",
    "lookahead": "the drop criteria judged by simulating the action and then holding the "
    "setpoints for 3 more policy steps (LookaheadShield, horizon 4): the perfect-model "
    "yardstick, needs a simulator of the hand",
    "lookahead-qp": "the thesis' QP criteria judged by simulating the action one step "
    "(LookaheadShield(ShieldLimits()))",
}
"""The shields ``python -m train.ppo --shield NAME`` trains inside (:func:`make_shield`)."""

DRIFT_STEPS = 4.0  # qp-drift: policy periods the object keeps its velocity in the prediction
HORIZON = 4  # lookahead: policy steps simulated per candidate (the action, then 3 held)


def drop_limits(env: gym.Env) -> ShieldLimits:
    """The drop criteria of ``qp-drift`` and ``lookahead``: the QP shield's box and tilt
    bounds (tilt off for the sphere, whose tilt is no failure) without its contact rows
    (``ShieldLimits(contacts=False)``); the env's termination is the lookahead's as well."""
    return ShieldLimits(contacts=False, tilt=getattr(env.unwrapped, "object", "") != "sphere")


def make_shield(env: gym.Env, name: str, backend: str = "daqp") -> gym.Env:
    """``env`` inside the shield ``name`` of :data:`SHIELDS` (``"none"``: ``env`` itself);
    ``backend``: the QP backend of ``qp`` and ``qp-drift``. Raises :class:`ShieldError` for
    an unknown name."""
    if name == "none":
        return env
    if name == "qp":
        return GraspShield(env, backend=backend)
    if name == "qp-drift":
        return GraspShield(env, backend=backend, limits=drop_limits(env), drift_steps=DRIFT_STEPS)
    if name == "qp-guard":
        return GuardedShield(env, backend=backend)
    if name == "lookahead":
        return LookaheadShield(env, limits=drop_limits(env), horizon=HORIZON)
    if name == "lookahead-qp":
        return LookaheadShield(env)
    raise ShieldError(f"unknown shield {name!r}; choose one of {list(SHIELDS)}")
