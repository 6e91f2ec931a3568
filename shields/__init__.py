"""Shields for safe RL (thesis Sec. "Islands and Bridges"): ``a~_t = Psi(a_t, s_t)``.

- :func:`simple_shield` / :class:`SimpleShield`: thesis ``Psi_simple`` (unsafe -> zero step).
- :func:`smart_shield` / :class:`SmartShield`: thesis ``Psi_smart`` (nearest safe action, exact).
- :class:`GraspShield` (:mod:`shields.qp`, :mod:`shields.compliance`): the four-finger hand's
  linearised-compliance QP shield (thesis sec. "Constructing a shield for in-hand manipulation").
- :class:`LookaheadShield` (:mod:`shields.lookahead`): a grasp shield's criteria judged on a
  MuJoCo simulation of the action (and, with a horizon, of holding still after it): the
  perfect-model yardstick, not deployable. :func:`make_shield` builds the shields
  ``python -m train.ppo --shield`` trains in (:data:`SHIELDS`).
"""

from shields.compliance import GraspLinearization, ShieldError, linearize
from shields.islands_shields import (
    project_disc_box,
    project_piece_box,
    project_union_box,
    simple_shield,
    smart_shield,
)
from shields.lookahead import Lookahead, LookaheadResult
from shields.qp import GraspQP, ShieldLimits, ShieldResult
from shields.wrappers import (
    SHIELDS,
    GraspShield,
    GuardedShield,
    LookaheadShield,
    SimpleShield,
    SmartShield,
    drop_limits,
    make_shield,
)

__all__ = [
    "SHIELDS",
    "GraspLinearization",
    "GraspQP",
    "GraspShield",
    "GuardedShield",
    "Lookahead",
    "LookaheadResult",
    "LookaheadShield",
    "ShieldError",
    "ShieldLimits",
    "ShieldResult",
    "SimpleShield",
    "SmartShield",
    "drop_limits",
    "linearize",
    "make_shield",
    "project_disc_box",
    "project_piece_box",
    "project_union_box",
    "simple_shield",
    "smart_shield",
]
