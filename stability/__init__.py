"""Passive grasp stability: one grasp model, one ``solve`` entry point, many methods.

>>> import numpy as np
>>> from stability import Grasp, Existence, solve
>>> g = Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)
>>> solve(g, Existence(wrench=[0, -1, 0]), method="planar").stable
True

Each method's options are a frozen dataclass (``method_info(name).options``), which
``solve(..., **options)`` builds and checks once.
"""

from . import exact, gws, iterative, modesearch, no_mdp, planar, refinement  # noqa: F401  (registers the methods)
from .api import available_methods, method_info, register, solve
from .errors import GraspError, MethodError, ModelError, SolverError
from .grasp import Grasp
from .options import Deadline, MethodOptions
from .queries import Existence, MaxDisturbance, MotionLimit, OptimalCommands, Query
from .solution import Solution, Stats

__all__ = [
    "Existence",
    "Grasp",
    "GraspError",
    "MaxDisturbance",
    "MethodError",
    "ModelError",
    "MotionLimit",
    "OptimalCommands",
    "Query",
    "Deadline",
    "MethodOptions",
    "Solution",
    "SolverError",
    "Stats",
    "available_methods",
    "method_info",
    "register",
    "solve",
]
