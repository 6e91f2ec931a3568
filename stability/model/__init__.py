"""The 3D grasp model that the MIP methods (``no_mdp``, ``iterative``, ``refinement``,
``exact``) share.

* :mod:`~stability.model.problem`: the grasp model of thesis ch. 5 (springs with preload,
  hands with nonbackdrivable actuators, equilibrium) as one mixed-integer model,
  :class:`ExactProblem`, with bounds from the query's own force scale
  (:func:`scale_bounds`);
* :mod:`~stability.model.query`: a validated query, :class:`QueryData`, and its
  equilibrium and objective on a problem (:func:`add_query`, :func:`query_value`);
* :mod:`~stability.model.run`: the methods' options (:class:`MipOptions`), one checked MIP
  solve within the deadline (:func:`run`) and the Solution they return;
* :mod:`~stability.model.coulomb`: Coulomb friction with maximum dissipation stated
  exactly (:class:`CoulombModel`: circular cone, bilinear dissipation, for SCIP), polished
  to an exact point by one LP per contact-mode set;
* :mod:`~stability.model.slides`: the search over slide directions that turns a relaxed
  or SCIP point into an exact one (:func:`~stability.model.slides.slide_search`) and the
  certificate of a relaxation's answer (:func:`certify`).
"""

from .coulomb import CoulombModel, exact_conditions
from .problem import ExactBounds, ExactPoint, ExactProblem, hand_data, length_scale, scale_bounds
from .query import QueryData, add_query, query_value
from .run import CONDITIONS, MipOptions, Stop, run
from .slides import certify

__all__ = [
    "CONDITIONS",
    "CoulombModel",
    "ExactBounds",
    "ExactPoint",
    "ExactProblem",
    "MipOptions",
    "QueryData",
    "Stop",
    "add_query",
    "certify",
    "exact_conditions",
    "hand_data",
    "length_scale",
    "query_value",
    "run",
    "scale_bounds",
]
