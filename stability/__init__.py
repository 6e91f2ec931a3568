"""Passive grasp stability: one grasp model, one ``solve`` entry point, many methods.

>>> import numpy as np
>>> from stability import Grasp, Existence, solve
>>> g = Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)
>>> solve(g, Existence(wrench=[0, -1, 0]), method="planar").stable
True
"""

from . import exact, gws, iterative, modesearch, no_mdp, planar, refinement  # noqa: F401  (registers the methods)
from .api import available_methods, register, solve
from .errors import GraspError, MethodError, ModelError, SolverError
from .grasp import Grasp
from .queries import Existence, MaxDisturbance, OptimalCommands, Query
from .solution import Solution

__all__ = [
    "Existence",
    "Grasp",
    "GraspError",
    "MaxDisturbance",
    "MethodError",
    "ModelError",
    "OptimalCommands",
    "Query",
    "Solution",
    "SolverError",
    "available_methods",
    "register",
    "solve",
]
