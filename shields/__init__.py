"""Shields for safe RL (thesis Sec. "Islands and Bridges"): ``a~_t = Psi(a_t, s_t)``.

- :func:`simple_shield` / :class:`SimpleShield`: thesis ``Psi_simple`` (unsafe -> zero step).
- :func:`smart_shield` / :class:`SmartShield`: thesis ``Psi_smart`` (nearest safe action, exact).
- :class:`GraspShield` (:mod:`shields.qp`, :mod:`shields.compliance`): the four-finger hand's
  linearised-compliance QP shield (thesis sec. "Constructing a shield for in-hand manipulation").
"""

from shields.compliance import GraspLinearization, ShieldError, linearize
from shields.islands_shields import (
    project_disc_box,
    project_piece_box,
    project_union_box,
    simple_shield,
    smart_shield,
)
from shields.qp import GraspQP, ShieldLimits, ShieldResult
from shields.wrappers import GraspShield, SimpleShield, SmartShield

__all__ = [
    "GraspLinearization",
    "GraspQP",
    "GraspShield",
    "ShieldError",
    "ShieldLimits",
    "ShieldResult",
    "SimpleShield",
    "SmartShield",
    "linearize",
    "project_disc_box",
    "project_piece_box",
    "project_union_box",
    "simple_shield",
    "smart_shield",
]
