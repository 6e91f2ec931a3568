"""Backdrivable actuators (``Grasp.backdrivable``): constant force sources, ``f = f_c``
whatever the transmission does, beside the thesis' nonbackdrivable ones.

A cube of half-width ``a`` pinched along x by two slide fingers (each joint moves its
fingertip along its own inward normal), commands ``f_c`` each, friction ``mu``:

* a load along z (tangential at both contacts) is held by friction alone: ``2 mu f_c``
  with either transmission (the normal forces stay ``f_c``);
* a push along +x: nonbackdrivable fingers lock (the far finger cannot open) and hold
  any load; constant-force fingers move together with the cube, and nothing resists:
  the answer is 0 (analysis: ``c_1 - c_2 = s`` with ``c_1 = c_2 = f_c``).
"""

from __future__ import annotations

import numpy as np
import pytest

from stability import Grasp, GraspError, MaxDisturbance, solve

A, MU, FC = 0.02, 0.5, 2.0


def pinch(backdrivable=None) -> Grasp:
    J = np.zeros((6, 2))
    J[0, 0] = 1.0  # finger 1 closes along its normal +x
    J[3, 1] = 1.0  # finger 2 along its normal -x
    return Grasp([[-A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0]], MU, J=J, R=np.eye(2),
                 backdrivable=backdrivable)  # fmt: skip


@pytest.mark.parametrize("method", ["refinement", "exact", "no_mdp"])
@pytest.mark.parametrize("back", [None, [True, True]])
def test_tangential_load_is_friction(method, back):
    sol = solve(pinch(back), MaxDisturbance([0, 0, -1, 0, 0, 0], commands=[FC, FC], cap=100),
                method=method, time_limit=30)  # fmt: skip
    assert sol.status == "solved"
    assert sol.value == pytest.approx(2 * MU * FC, rel=1e-6)
    res = sol.residuals()
    assert max(res.values()) <= 1e-7, res


@pytest.mark.parametrize("method", ["refinement", "exact"])
def test_push_along_the_pinch(method):
    q = MaxDisturbance([1, 0, 0, 0, 0, 0], commands=[FC, FC], cap=100)
    locked = solve(pinch(), q, method=method, time_limit=30)
    free = solve(pinch([True, True]), q, method=method, time_limit=30)
    assert locked.value == pytest.approx(100.0) and locked.stats.get("capped")
    assert free.status == "solved" and free.value == pytest.approx(0.0, abs=1e-7)
    # one finger backdrivable, the other locked: the locked one holds the push toward it
    one = solve(pinch([True, False]), q, method=method, time_limit=30)
    assert one.value == pytest.approx(100.0)


def test_backdrivable_forces_equal_commands():
    sol = solve(pinch([True, True]), MaxDisturbance([0, 0, -1, 0, 0, 0], commands=[FC, FC],
                                                    cap=100), method="refinement")  # fmt: skip
    assert np.allclose(sol.actuator_forces, FC, atol=1e-9)


def test_bad_backdrivable():
    J = np.zeros((6, 2))
    with pytest.raises(GraspError, match="backdrivable must be 2 booleans"):
        Grasp([[-A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0]], MU, J=J, backdrivable=[True])
    with pytest.raises(GraspError, match="backdrivable must be 2 booleans"):
        Grasp([[-A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0]], MU, J=J, backdrivable=[2, 0])
    with pytest.raises(GraspError, match="without J"):
        Grasp([[-A, 0, 0], [A, 0, 0]], [[1, 0, 0], [-1, 0, 0]], MU, backdrivable=[True, True])
