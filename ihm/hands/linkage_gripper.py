"""Parallel-jaw gripper with closed four-bar fingers (``assets/linkage_gripper``).

Our own model, built like MuJoCo Menagerie's Robotiq 2F-85: per finger a driver (on the
base, actuated), a coupler (on the driver), a spring link (on the base, passive, with a
joint spring) and a follower (on the spring link, carrying the pad), the four-bar closed
by a ``connect`` equality; a ``joint`` equality ties the two drivers; one rescaled
position servo (``gain != kp``) pulls a fixed tendon over both drivers and saturates at its
``forcerange`` in a pinch. Frames, dimensions and measurements: the XML header.
"""

from __future__ import annotations

from pathlib import Path

XML = Path(__file__).resolve().parents[2] / "assets" / "linkage_gripper" / "linkage_gripper.xml"

SIDES = ("right", "left")
LINKS = ("driver", "coupler", "spring_link", "follower")
JOINT_NAMES = tuple(f"{s}_{k}" for s in SIDES for k in LINKS)
ACTUATOR_NAMES = ("fingers",)  # saturating position servo on tendon "split" [N m of tendon]
EQUALITY_NAMES = ("right_closure", "left_closure", "drivers")
PAD_BODIES = ("right_pad", "left_pad")

NQ = 8
NV = 8
NU = 1
NEQ = 3
# independent coordinates after folding the equalities: 8 joints - rank 5 (2 per connect
# in the plane of the four-bar, 1 for the drivers) = 3
N_INDEPENDENT = 3

FORCE_LIMIT = 2.0  # the servo's forcerange bound: the pinch's commanded tendon force
SPRING_STIFFNESS = 0.05  # spring links [N m / rad]

# Contact skin (as every hand of the project; tests/ihm/test_contact_params.py)
SKIN_SOLREF = (0.005, 1.0)
SKIN_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
