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
  clipped value with ``shield_intervened=False``).

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

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from shields.islands_shields import simple_shield, smart_shield
from shields.qp import GraspQP, ShieldLimits, ShieldResult

__all__ = ["GraspShield", "SimpleShield", "SmartShield"]


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

    def shield(self, action: NDArray[Any]) -> tuple[NDArray[np.float64], bool]:
        """``(a~, intervened)`` for an in-box action ``clip(a)`` in the current state."""
        raise NotImplementedError

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Clip the action to the action box, shield it, step the inner env with the result,
        record the agent's and the executed action in ``info``."""
        agent_action = np.array(action, dtype=np.float64)
        clipped = np.minimum(np.maximum(agent_action, self._low), self._high)  # np.clip, faster
        executed, intervened = self.shield(clipped)
        extra = self.shield_info()
        obs, reward, terminated, truncated, info = self.env.step(executed)
        info = dict(info)
        info["agent_action"] = agent_action
        info["executed_action"] = np.array(executed, dtype=np.float64)
        info["shield_intervened"] = bool(intervened)
        info.update(extra)
        return obs, reward, terminated, truncated, info

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
    """

    _required = ("model", "data", "max_setpoint_step", "dt")

    def __init__(
        self, env: gym.Env, backend: str = "daqp", limits: ShieldLimits | None = None
    ) -> None:
        super().__init__(env)
        u = env.unwrapped
        self.qp = GraspQP(
            u.model,
            max_setpoint_step=float(u.max_setpoint_step),
            horizon=float(u.dt),
            limits=limits,
            backend=backend,
        )
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
        r = self.last_result
        if r is None:
            return {}
        return {
            "shield_correction": r.correction,
            "shield_subset": r.links,
            "shield_status": r.status,
            "shield_solve_time_s": r.solve_time_s,
        }
