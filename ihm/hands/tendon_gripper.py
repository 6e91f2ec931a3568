"""Two-finger tendon-driven underactuated gripper (thesis ch. 5, grasp example 3).

Model: ``assets/tendon_gripper/tendon_gripper.xml`` (dimensions and sign conventions
in its header comment). Two opposing planar fingers, each with a proximal and a distal
hinge (positive = closing), driven by two tendon motors through fixed tendons that
span both fingers (the differential). Actuator forces are tendon tensions [N]; joint
torques are ``tau = R f`` (thesis eq. torqueRatio) with the moment arms below.
"""

from __future__ import annotations

from pathlib import Path

XML = Path(__file__).resolve().parents[2] / "assets" / "tendon_gripper" / "tendon_gripper.xml"

JOINT_NAMES = ("left_proximal", "left_distal", "right_proximal", "right_distal")
ACTUATOR_NAMES = ("proximal", "distal")  # tendon motors, force [N], positive closes
TENDON_NAMES = ("proximal_tendon", "distal_tendon")
BODY_NAMES = ("left_proximal", "left_distal", "right_proximal", "right_distal")

NQ = 4
NV = 4
NU = 2
NTENDON = 2
NGEOM = 9  # palm (visual) + per link one visual and one collision capsule

# Moment arms [m] (thesis: 5 mm proximal tendon at the proximal joints; distal tendon
# 1.6 mm at the proximal and 5 mm at the distal joints).
PROXIMAL_TENDON_ARM = 0.005  # proximal tendon at each proximal joint [m]
DISTAL_TENDON_PROXIMAL_ARM = 0.0016  # distal tendon at each proximal joint [m]
DISTAL_TENDON_DISTAL_ARM = 0.005  # distal tendon at each distal joint [m]

# R per finger: rows (proximal, distal joint), columns ACTUATOR_NAMES [m].
R_FINGER = (
    (PROXIMAL_TENDON_ARM, DISTAL_TENDON_PROXIMAL_ARM),
    (0.0, DISTAL_TENDON_DISTAL_ARM),
)
# R of the hand: rows JOINT_NAMES, columns ACTUATOR_NAMES [m]; tau = R f.
R = R_FINGER + R_FINGER

PROXIMAL_LENGTH = 0.060  # proximal link, joint to joint [m]
DISTAL_LENGTH = 0.040  # distal link, distal joint to the centre of the tip [m]
LINK_RADIUS = 0.008  # capsule radius of both links [m]
JOINT_SPACING = 0.110  # distance between the two proximal joints [m] (XML header: why)
PALM_WIDTH = 0.140  # palm width, visual only [m]

# Contact skin [MuJoCo solref (timeconst [s], damping ratio), solimp]: the hand's collision
# class and every scene object carry the same values, so each contact simulates exactly these
# (MuJoCo mixes a pair's parameters; tests/ihm/test_contact_params.py reads them back).
SKIN_SOLREF = (0.005, 1.0)
SKIN_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
