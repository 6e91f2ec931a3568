"""MuJoCo's static contact law as a convex piecewise-linear spring (ihm.contact_law): the fit
against the law written out, and the grasp's law against MuJoCo's own static forces as a
sphere is pressed 3 mm into a plane."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ihm
from ihm.compliance import impedance
from ihm.contact_law import LAW_SPAN, fit_law, law_shape
from ihm.sim_maps import MapError, MapSpec
from stability import GraspError

DEFAULT = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's default solimp


def _fitted(fit, depth: float, d: np.ndarray) -> np.ndarray:
    """The fit's law at ``d`` more penetration, in units of ``s'(depth)``."""
    s0 = law_shape(np.array(DEFAULT), np.array([depth]))[0] / _slope(depth)
    hinge = np.maximum(0.0, d[:, None] - fit.knots[None, :]) @ fit.steps
    return s0 + fit.slope * d + hinge


def _slope(depth: float, h: float = 1e-9) -> float:
    s = law_shape(np.array(DEFAULT), np.array([depth, depth + h]))
    return float((s[1] - s[0]) / h)


@pytest.mark.parametrize("depth", [0.0, 5e-6, 2e-4, 3e-4, 6e-4])
def test_fit_is_convex_exact_at_the_state_and_within_its_error(depth: float) -> None:
    fit = fit_law(DEFAULT, depth, LAW_SPAN)
    assert np.all(fit.steps > 0) and np.all(np.diff(fit.knots) > 0)
    assert np.all((fit.knots > 0) & (fit.knots < LAW_SPAN))
    d = np.linspace(0.0, LAW_SPAN, 1237)  # not the fit's own points
    exact = law_shape(np.array(DEFAULT), depth + d) / _slope(depth)
    err = np.abs(_fitted(fit, depth, d) - exact) / np.maximum(exact, 1e-300)
    assert err[0] < 1e-9 or exact[0] == 0.0
    assert err.max() <= fit.error + 3e-3  # between the fit's points: 1.5e-3 at first touch
    assert fit.error < 0.105  # measured 0.085-0.103 to 0.3 mm deep, 0.104 at 0.5 mm
    linear = np.abs(exact[0] + d - exact) / np.maximum(exact, 1e-300)  # the slope alone
    assert linear.max() > 2 * fit.error  # measured 2.4x (0.6 mm) to 10x (shallow)


def test_beyond_the_width_the_law_is_linear() -> None:
    """Past ``solimp``'s width the impedance is constant: one spring, exact."""
    fit = fit_law(DEFAULT, 1.2e-3, LAW_SPAN)
    assert fit.knots.size == 0 and fit.slope == pytest.approx(1.0, rel=1e-6)
    assert fit.error < 1e-6


def test_law_shape_is_mujocos_impedance_law() -> None:
    r = np.array([1e-4, 5e-4, 2e-3])
    imp = impedance(np.array(DEFAULT), r)
    np.testing.assert_allclose(law_shape(np.array(DEFAULT), r), r * imp**2 / (1 - imp))
    assert law_shape(np.array(DEFAULT), np.array([2e-3]))[0] == pytest.approx(
        2e-3 * 0.95**2 / 0.05, rel=1e-12
    )


PLANE = """
<mujoco>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" jacobian="dense"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" friction="0.7 0.02 0.001"/>
    <body name="object" pos="0 0 0.0498">
      <freejoint/>
      <geom type="sphere" size="0.05" mass="0.4" friction="0.7 0.02 0.001"/>
    </body>
  </worldbody>
</mujoco>
"""


def _settled() -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(PLANE)
    data = mujoco.MjData(model)
    for _ in range(1500):
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    return model, data


def _mujoco_force(model: mujoco.MjModel, data: mujoco.MjData, push: float) -> float:
    """MuJoCo's static normal force with the sphere ``push`` [m] deeper (``mj_inverse`` at
    rest)."""
    work = mujoco.MjData(model)
    work.qpos[:] = data.qpos
    work.qpos[2] -= push
    mujoco.mj_inverse(model, work)
    f6 = np.zeros(6)
    mujoco.mj_contactForce(model, work, 0, f6)
    return float(f6[0])


def _grasp_force(g, push: float) -> float:
    """The grasp's normal force at contact 0 and its pieces with the object ``push`` [m]
    deeper: ``max(0, p + K d)`` for the contact, ``K_i max(0, d - g_i)`` for each piece."""
    own = np.flatnonzero(g.piece_of == 0)
    total = 0.0
    for k in own:
        p = g.forces[k, 0] if g.gaps[k] == 0 else -g.stiffness[k] * g.gaps[k]
        total += max(0.0, p + g.stiffness[k] * push)
    return total


def test_the_grasps_law_follows_mujoco_as_the_sphere_presses_in() -> None:
    model, data = _settled()
    fitted = ihm.grasp_from_mujoco(model, data, compliance="mujoco", contact_law="fitted")
    slope = ihm.grasp_from_mujoco(model, data, compliance="mujoco")
    assert slope.m == 1 and fitted.m > 1  # the law's pieces
    assert np.all(fitted.piece_of == 0)
    pieces = np.arange(1, fitted.m)
    np.testing.assert_allclose(fitted.points[pieces], fitted.points[[0] * len(pieces)])
    np.testing.assert_allclose(fitted.normals[pieces], fitted.normals[[0] * len(pieces)])
    assert np.all(fitted.forces[pieces] == 0) and np.all(fitted.gaps[pieces] > 0)
    assert np.all(fitted.stiffness > 0)
    depth = float(data.contact[0].includemargin - data.contact[0].dist)
    fit = fit_law(DEFAULT, depth, LAW_SPAN)
    worst_fit = worst_slope = 0.0
    for push in np.linspace(2.5e-4, LAW_SPAN, 12):
        mj = _mujoco_force(model, data, push)
        worst_fit = max(worst_fit, abs(_grasp_force(fitted, push) / mj - 1))
        worst_slope = max(worst_slope, abs(_grasp_force(slope, push) / mj - 1))
    assert worst_fit <= fit.error + 0.01  # measured: within the fit's own error
    assert worst_slope > 0.3  # the slope at the state alone: far off


def test_fitted_law_options_are_checked() -> None:
    model, data = _settled()
    with pytest.raises(GraspError, match="contact_law"):
        ihm.grasp_from_mujoco(model, data, compliance="mujoco", contact_law="cubic")
    with pytest.raises(GraspError, match="compliance='mujoco'"):
        ihm.grasp_from_mujoco(model, data, contact_law="fitted")
    with pytest.raises(MapError, match="contact_law"):
        MapSpec("barrett_box", contact_law="fitted").check("modesearch")
    assert ihm.grasp_from_mujoco(model, data).piece_of.tolist() == [0]
