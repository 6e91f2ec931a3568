"""Planar passive grasp stability in polynomial time (thesis chapter 4).

Model (rigid hand, point contacts with friction, thesis sec. 2dmodel): object
motion ``r = (x, y, theta)``; contact motion ``d = G^T r``, per contact
``d_n = N_i r`` and ``d_t = T_i r`` with ``N_i = [n_i, p_i x n_i]`` and
``T_i = [t_i, p_i x t_i]``. Unit virtual springs with preload ``p_i``:

* persist: ``d_n - p <= 0`` and ``c_n = p - d_n``; detach: ``d_n - p >= 0``, ``c_n = 0``;
* roll: ``d_t = 0``, ``|c_t| <= mu c_n``; slip+: ``d_t >= 0``, ``c_t = -mu c_n``;
  slip-: ``d_t <= 0``, ``c_t = mu c_n`` (maximum dissipation);
* equilibrium ``G c + w = 0``.

Inequalities are closed: on a boundary both neighbouring states give the same
forces, so a solution found for either is a solution of the model.

Algorithm (thesis Alg. complete, with exact geometry instead of one LP per
enumeration step): the candidate contact states are the faces of the
arrangement of the ``m`` central tangential planes (slip states, all faces) and
the ``m`` affine normal planes (detachment states, regions only), enumerated
*jointly* so that only combinations that co-occur for some motion ``r`` are
formed (see :mod:`stability.planar._arrangement`). For every candidate state the
equations are linear in ``r`` restricted to the slip face plus the free
friction forces of rolling contacts; they reduce to a 3 x 3 system
``M z = -h - s d`` solved in batch (eq. linear_system), and the state's
inequalities are checked. States whose system is singular or has more than
three unknowns get the LP of the thesis (HiGHS). Stable iff some state admits
a solution. ``MaxDisturbance`` is exact: along ``w = s d`` each state's
solution is affine in ``s``, so its inequalities give an interval of ``s``
(an LP for singular states); the answer is the largest stable ``s``.
:func:`max_disturbance_map` answers many directions at once against the same states.

Modules: :mod:`~stability.planar.enumeration` (slip, detachment and joint contact states),
:mod:`~stability.planar.system` (each state's linear system, its interval of ``s``, the
LP of the thesis, the final check), :mod:`~stability.planar.solve` (the ``Existence`` and
``MaxDisturbance`` queries; registers ``method="planar"``), :mod:`~stability.planar.sweep`
(:func:`max_disturbance_map`) and :mod:`~stability.planar.thesis` (the thesis' own
slip-state enumeration, the benchmark's and the tests' reference).
"""

from . import solve  # noqa: F401  (registers method "planar")
from .enumeration import (
    STATE_NAMES,
    contact_states,
    count_slip_faces,
    detachment_states,
    motion_planes,
    slip_states,
)
from .sweep import max_disturbance_map
from .thesis import slip_states_thesis

__all__ = [
    "STATE_NAMES",
    "slip_states",
    "detachment_states",
    "contact_states",
    "count_slip_faces",
    "motion_planes",
    "slip_states_thesis",
    "max_disturbance_map",
]
