"""The tests' shared hand-built problems: see :mod:`stability.examples`."""

from stability.examples import *  # noqa: F403
from stability.examples import (  # noqa: F401
    PINCH_HALF_WIDTH,
    PINCH_LEVER,
    PINCH_MAX_Z,
    PINCH_MU,
    PINCH_TORQUE,
    TENDON_ARMS,
    TENDON_FORCE,
    THREE_TABLE,
    WEDGE_FORCE_DIR,
    embed_wrench,
    pinch,
    random_fingers,
    random_wrench,
    tendon_finger,
    three_embedded,
    three_planar,
    wedge,
)
