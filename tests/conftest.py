"""Shared test constants."""

# the grasp scenes the thesis analyses (issue 3), in the order the CLI tests try them
THESIS_SCENES = (
    "barrett_box",
    "barrett_box_3d",
    "barrett_flask",
    "barrett_cube",
    "tendon_box",
    "four_finger_sphere",
    "four_finger_cylinder",
    "four_finger_cube",
)
