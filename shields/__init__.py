"""Shields for safe RL (thesis Sec. "Islands and Bridges"): ``a~_t = Psi(a_t, s_t)``.

- :func:`simple_shield` / :class:`SimpleShield`: thesis ``Psi_simple`` (unsafe -> zero step).
- :func:`smart_shield` / :class:`SmartShield`: thesis ``Psi_smart`` (nearest safe action, exact).
"""

from shields.islands import (
    project_disc_box,
    project_piece_box,
    project_union_box,
    simple_shield,
    smart_shield,
)
from shields.wrappers import SimpleShield, SmartShield

__all__ = [
    "SimpleShield",
    "SmartShield",
    "project_disc_box",
    "project_piece_box",
    "project_union_box",
    "simple_shield",
    "smart_shield",
]
