"""The constraints a grasp shield enforces (:class:`ShieldLimits`): the QP shield's
(:mod:`shields.qp`) and, read off a simulation instead of a prediction, the lookahead
shield's (:mod:`shields.lookahead`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shields.compliance import ShieldError

__all__ = ["ShieldLimits"]


@dataclass(frozen=True)
class ShieldLimits:
    """The shield's constraints (module docstring).

    c_min : least normal force of a shielded contact [N]
    edges : edges ``k`` of the inscribed friction pyramid (>= 3)
    box_low, box_high : object origin box, world [m] (the four-finger env drops below
        ``z = 0.05`` or outside 0.045 m from the palm axis; the object rests at ``z`` 0.077)
    tilt_low, tilt_high : bounds on ``r_x`` and ``r_y`` [rad]
    relax_contacts : off (default, the thesis): a shielded contact must end the step inside
        its constraints. On: a contact row the current state already violates (a contact
        sliding on MuJoCo's cone lies outside the inscribed pyramid) only must not get
        worse, as the box and tilt bounds (an ablation; docs/shields.md)
    soft_closure : off (default): force closure of a link set is tested with point contacts
        (the polygon's vertices only), so at least three contacts are needed. On: with the
        torsional rays of condim-4 contacts too (soft fingers), so two fingertips can be a
        candidate. Measured: on, the shield releases more and drops more (docs/shields.md)
    contacts : on (default, the thesis): a force-closure set of links must hold (the contact
        rows). Off: only the object's box and tilt rows remain (one QP, all servos free)
    friction : on (default, the thesis): the shielded contacts' friction rows. Off: their
        normal-force rows only (the set must keep pressing; its contacts may slide)
    tilt : on (default, the thesis): the tilt rows. Off: none (an object whose tilt does not
        matter, the sphere)

    The same limits are the lookahead shield's criteria (:mod:`shields.lookahead`).
    """

    c_min: float = 0.05
    edges: int = 8
    box_low: tuple[float, float, float] = (-0.03, -0.03, 0.06)
    box_high: tuple[float, float, float] = (0.03, 0.03, 0.12)
    tilt_low: float = -0.5
    tilt_high: float = 0.5
    relax_contacts: bool = False
    soft_closure: bool = False
    contacts: bool = True
    friction: bool = True
    tilt: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.c_min) and self.c_min >= 0):
            raise ShieldError(f"c_min must be a finite number >= 0 [N], got {self.c_min!r}")
        if isinstance(self.edges, bool) or not isinstance(self.edges, int) or self.edges < 3:
            raise ShieldError(f"edges must be an integer >= 3, got {self.edges!r}")
        lo, hi = np.asarray(self.box_low, float), np.asarray(self.box_high, float)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo) & np.isfinite(hi)):
            raise ShieldError("box_low and box_high must be 3 finite numbers [m]")
        if np.any(lo >= hi):
            raise ShieldError(f"box_low {lo.tolist()} must be below box_high {hi.tolist()}")
        if not (np.isfinite(self.tilt_low) and np.isfinite(self.tilt_high)):
            raise ShieldError("tilt_low and tilt_high must be finite [rad]")
        if not -np.pi < self.tilt_low < self.tilt_high < np.pi:
            raise ShieldError("need -pi < tilt_low < tilt_high < pi [rad]")
        for name in ("relax_contacts", "soft_closure", "contacts", "friction", "tilt"):
            if not isinstance(getattr(self, name), bool):
                raise ShieldError(f"{name} must be True or False, got {getattr(self, name)!r}")
