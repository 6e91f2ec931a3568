"""Saved states of the four-finger rotation env, and one policy step from them under given
physics (timestep, substeps, solver, tolerance): what ``python -m envs.bench``'s fidelity rows
and the env's tests compare."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from envs.four_finger.env import FourFingerRotate, yaw_rate
from envs.four_finger.physics import SOLVERS

__all__ = ["STATE_SPEC", "policy_step_outcomes", "save_state"]

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_CTRL


def save_state(env: FourFingerRotate) -> np.ndarray:
    """The env's full physics state and setpoints (:data:`STATE_SPEC`), for
    :func:`policy_step_outcomes`."""
    s = np.empty(mujoco.mj_stateSize(env.model, STATE_SPEC))
    mujoco.mj_getState(env.model, env.data, s, STATE_SPEC)
    return s


def policy_step_outcomes(
    env: FourFingerRotate,
    states: Sequence[np.ndarray],
    timestep: float,
    substeps: int,
    solver: str,
    tol: float,
) -> np.ndarray:
    """One policy step (``substeps`` x ``timestep``, ``solver`` to tolerance ``tol``) from each
    of ``states`` (:func:`save_state`), in ``env``'s model (its options are left so): per
    state the object's yaw rate [rad/s], its position x, y, z [mm] and the observed link
    normal forces (8) [N] at the end."""
    m, d, ph = env.model, env.data, env.physics
    m.opt.timestep, m.opt.tolerance = timestep, tol
    m.opt.solver = SOLVERS[solver]
    m.opt.iterations = 1000 if tol < 1e-10 else 100
    out = []
    for s in states:
        mujoco.mj_setState(m, d, s, STATE_SPEC)
        mujoco.mj_forward(m, d)
        q0 = ph.object_quat().copy()
        mujoco.mj_step(m, d, nstep=substeps)
        _, fn, _ = ph.link_contacts()
        rate = yaw_rate(q0, ph.object_quat(), timestep * substeps)
        out.append([rate, *(ph.object_pos() * 1e3), *fn])
    return np.array(out)
