"""Four-finger in-hand rotation (thesis ch. 7, sec. "In-hand manipulation with pure RL"):
the gymnasium env ``ihm/FourFingerRotate-v0``.

- :mod:`~envs.four_finger.physics`: the scene's model with the env's physics settings
  (timestep, solver, torsional friction, explicit contact pairs) and :class:`Physics`, the
  model, data and fast contact observation;
- :mod:`~envs.four_finger.cache`: the starting states, a disk cache of varied stable grasps
  (:func:`generate_grasps`, :func:`grasp_cache`);
- :mod:`~envs.four_finger.env`: the env :class:`FourFingerRotate` (its spaces, reward and
  episode end are documented there) and :func:`yaw_rate`;
- :mod:`~envs.four_finger.mixed`: :class:`MixedObjectRotate`, one env over several objects
  drawn per episode (``ihm/FourFingerRotateMixed-v0``);
- :mod:`~envs.four_finger.settings`: the env's settings in groups (reward, simulation, starts,
  observation, rendering: :class:`RewardSettings`, :class:`SimSettings`,
  :class:`StartSettings`, :class:`ObservationSettings`, :class:`RenderSettings`);
- :mod:`~envs.four_finger.randomize`: randomised physics (friction, torsional friction, mass,
  servo gains, latency, sensor noise; :class:`Randomization`, :func:`corners`);
- :mod:`~envs.four_finger.states`: saved env states and one policy step from them under given
  physics (:func:`save_state`, :func:`policy_step_outcomes`).

Every public name of these modules is importable from ``envs.four_finger``.
"""

from envs.four_finger.cache import (
    FIRM_LIFT,
    FIRM_SQUEEZE,
    GRASP_SETS,
    GRIPS,
    START_CLEARANCE,
    VERIFY_STEPS,
    GraspCache,
    generate_grasps,
    grasp_cache,
    worst_hold,
)
from envs.four_finger.env import (
    HEIGHT_FROM,
    HOLD_Z,
    N_OBS,
    N_PRIVILEGED,
    REPLAY_SIZE,
    TURNED,
    FourFingerRotate,
    check_start_sampling,
    cube_turn,
    yaw_rate,
    z_tilt,
    z_twist,
)
from envs.four_finger.mixed import MixedObjectRotate
from envs.four_finger.physics import (
    CONTACT_LINKS,
    DROP_Z,
    FRAME_SKIP,
    HELDOUT_OBJECTS,
    MAX_FORCE,
    OBJECTS,
    OUT_RADIUS,
    SOLVER_TOLERANCE,
    SOLVERS,
    TIMESTEP,
    TORSIONAL_FRICTION,
    TRAIN_OBJECTS,
    FourFingerError,
    Physics,
    dynamic_pairs,
    mixed_contact,
    scene_name,
)
from envs.four_finger.randomize import (
    ModelScaler,
    PhysicsSample,
    Randomization,
    centre,
    corners,
)
from envs.four_finger.settings import (
    ObservationSettings,
    RenderSettings,
    RewardSettings,
    SimSettings,
    StartSettings,
    apply_overrides,
)
from envs.four_finger.states import STATE_SPEC, policy_step_outcomes, save_state

__all__ = [
    "CONTACT_LINKS",
    "DROP_Z",
    "FIRM_LIFT",
    "FIRM_SQUEEZE",
    "FRAME_SKIP",
    "GRASP_SETS",
    "GRIPS",
    "HEIGHT_FROM",
    "HELDOUT_OBJECTS",
    "HOLD_Z",
    "MAX_FORCE",
    "N_OBS",
    "N_PRIVILEGED",
    "OBJECTS",
    "OUT_RADIUS",
    "REPLAY_SIZE",
    "SOLVERS",
    "SOLVER_TOLERANCE",
    "START_CLEARANCE",
    "STATE_SPEC",
    "TIMESTEP",
    "TORSIONAL_FRICTION",
    "TRAIN_OBJECTS",
    "TURNED",
    "VERIFY_STEPS",
    "FourFingerError",
    "FourFingerRotate",
    "GraspCache",
    "MixedObjectRotate",
    "ModelScaler",
    "ObservationSettings",
    "Physics",
    "PhysicsSample",
    "Randomization",
    "RenderSettings",
    "RewardSettings",
    "SimSettings",
    "StartSettings",
    "apply_overrides",
    "centre",
    "check_start_sampling",
    "corners",
    "cube_turn",
    "dynamic_pairs",
    "generate_grasps",
    "grasp_cache",
    "mixed_contact",
    "policy_step_outcomes",
    "save_state",
    "scene_name",
    "worst_hold",
    "yaw_rate",
    "z_tilt",
    "z_twist",
]
