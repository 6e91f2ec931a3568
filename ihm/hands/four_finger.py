"""Four-finger, 12-DOF hand of thesis ch. 7 (fig. ffh): constants of ``assets/four_finger``.

Four identical fingers 90 deg apart around an upward-facing palm; per finger a
base abduction joint ``j0`` and two flexion joints ``j1`` (proximal) and ``j2``
(distal), each driven through a series-elastic coupling by a position servo
(MuJoCo ``<position>``: torque = ``KP (ctrl - q)`` [N m]). Sign convention:
positive flexion closes the finger (a positive actuator force squeezes);
positive abduction moves the fingertip counter-clockwise about +z seen from
above. Fully actuated: ``R`` is the 12 x 12 identity.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

XML = Path(__file__).resolve().parents[2] / "assets" / "four_finger" / "four_finger.xml"

FINGERS = ("f1", "f2", "f3", "f4")  # at azimuth 0, 90, 180, 270 deg about +z
JOINTS_PER_FINGER = ("j0", "j1", "j2")  # abduction, proximal flexion, distal flexion
JOINT_NAMES = tuple(f"{f}_{j}" for f in FINGERS for j in JOINTS_PER_FINGER)
ACTUATOR_NAMES = JOINT_NAMES  # one position servo per joint, named after it
TENDON_NAMES: tuple[str, ...] = ()
BODY_NAMES = tuple(f"{f}_{link}" for f in FINGERS for link in ("proximal", "distal"))
DISTAL_BODY_NAMES = tuple(f"{f}_distal" for f in FINGERS)  # the fingertips holding the objects

NQ = 12
NV = 12
NU = 12
NTENDON = 0
# catch plane, palm (visual + collision), per finger: knuckle, 2 visual + 2 collision capsules
NGEOM = 23

# servo (series-elastic coupling) stiffness [N m / rad], every joint
KP = 1.0
FORCE_LIMIT = 0.5  # actuator forcerange +-[N m]
DAMPING = 0.02  # joint damping [N m s / rad]

# joint ranges [rad] per finger joint (also the servos' ctrlrange)
JOINT_RANGE = {
    "j0": (-0.4, 0.4),
    "j1": (-0.6, 1.4),
    "j2": (-0.3, 1.6),
}
JOINT_RANGES = np.array([JOINT_RANGE[j] for _ in FINGERS for j in JOINTS_PER_FINGER])  # (12, 2)

# default hand pose of the scenes' ``init`` keyframes [rad]: tips 2-3 mm off a 70 mm object
DEFAULT_FINGER_POSE = (0.0, 0.0, 0.7)
DEFAULT_POSE = np.tile(DEFAULT_FINGER_POSE, len(FINGERS))  # (12,), order of JOINT_NAMES

# dimensions [m]
PALM_RADIUS = 0.085  # disc, top at z = 0, collides with objects
FLOOR_Z = -0.08  # catch plane below the palm [m]
FINGER_BASE_RADIUS = 0.07  # finger bases on this circle about the palm centre
FINGER_AZIMUTHS = (0.0, np.pi / 2, np.pi, 3 * np.pi / 2)  # [rad] about +z
LINK_RADIUS = 0.01  # capsule radius of both links (finger breadth 20 mm)
PROXIMAL_LENGTH = 0.05  # base (j0, j1) to distal joint (j2)
DISTAL_LENGTH = 0.035  # distal joint to the centre of the hemispherical tip

# Contact skin [MuJoCo solref (timeconst [s], damping ratio), solimp]: the hand's collision
# class and every scene object carry the same values, so each contact simulates exactly these
# (MuJoCo mixes a pair's parameters; tests/ihm/test_contact_params.py reads them back).
SKIN_SOLREF = (0.01, 1.0)
SKIN_SOLIMP = (0.9, 0.9, 0.001, 0.5, 2.0)
