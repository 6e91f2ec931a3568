"""Barrett BH8-280 hand: names, counts and dimensions of ``assets/barrett/bh280.xml``.

Sources of the dimensions are in the header comment of the model file.
"""

from __future__ import annotations

from pathlib import Path

XML = Path(__file__).resolve().parent.parent.parent / "assets" / "barrett" / "bh280.xml"

JOINT_NAMES = (
    "f1_spread",
    "f1_prox",
    "f1_dist",
    "f2_spread",
    "f2_prox",
    "f2_dist",
    "f3_prox",
    "f3_dist",
)
# independent coordinates after the joint equalities (ihm.contacts.hand_coordinates)
INDEPENDENT_JOINT_NAMES = ("f1_spread", "f1_prox", "f2_prox", "f3_prox")
ACTUATOR_NAMES = ("spread", "f1", "f2", "f3")
TENDON_NAMES: tuple[str, ...] = ()
BODY_NAMES = ("palm", "f1_prox", "f1_dist", "f2_prox", "f2_dist", "f3_prox", "f3_dist")
COLLISION_GEOM_NAMES = (
    "palm_pad",
    "f1_prox",
    "f1_dist",
    "f2_prox",
    "f2_dist",
    "f3_prox",
    "f3_dist",
)

NQ = 8
NV = 8
NU = 4
NTENDON = 0
NGEOM = 10
N_INDEPENDENT = 4  # l: spread + three finger flexions

COUPLING = 1.0 / 3.0  # distal angle / proximal angle [rad/rad] (125/93.75 - 1, drivetrain)
SPREAD_MIRROR = 1.0  # f2_spread / f1_spread [rad/rad]
SPREAD_KP = 20.0  # stiffness of the spread position servo [N m/rad] (the spread is rigid)

AW = 0.025  # palm centre to finger-1/2 spread axis [m]
A1 = 0.050  # spread axis to proximal flexion axis [m]
A2 = 0.070  # proximal (inner) link, flexion axis to distal axis [m]
A3 = 0.050  # distal (outer) link, distal axis to fingertip reference [m]
PHI3 = 0.7330383  # fixed inward bend of the outer link [rad] (42 deg)
DW = 0.084  # palm height, wrist to palm face [m]
PALM_RADIUS = 0.045  # palm face disc [m]

PROX_RANGE = (0.0, 2.4435)  # [rad] 0-140 deg
DIST_RANGE = (0.0, 0.8378)  # [rad] 0-48 deg
SPREAD_RANGE = (0.0, 3.1416)  # [rad] 0-180 deg

# Contact skin [MuJoCo solref (timeconst [s], damping ratio), solimp]: the hand's collision
# class and every scene object carry the same values, so each contact simulates exactly these
# (MuJoCo mixes a pair's parameters; tests/ihm/test_contact_params.py reads them back).
SKIN_SOLREF = (0.02, 1.0)
SKIN_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
