"""Exception types of the stability package.

Every error a user can provoke with bad input, an unknown method or a failing
backend is one of these, with a message that names what is wrong.
"""

from __future__ import annotations


class GraspError(ValueError):
    """Invalid grasp or query data: shapes, NaN/inf, negative friction, bad frames, ..."""


class MethodError(GraspError):
    """Unknown method, or a method that cannot answer the given query / grasp."""


class SolverError(RuntimeError):
    """A numerical backend failed (status not optimal/infeasible, time-out, ...)."""


class ModelError(GraspError):
    """An invalid optimisation model (stability.mip): bad indices or bounds, an indicator or
    SOS2 constraint whose big-M reformulation needs a bound that is infinite, ..."""
