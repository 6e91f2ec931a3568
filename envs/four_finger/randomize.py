"""Randomised physics for the four-finger rotation env: what may be wrong about the model.

A :class:`Randomization` states ranges; the env draws one :class:`PhysicsSample` per
episode (at ``reset``) and :class:`ModelScaler` writes it into the ``MjModel``:

| what | MuJoCo field(s) | default range |
|------|-----------------|---------------|
| sliding friction of the object's contacts | ``pair_friction[:, 0:2]`` | x 0.5 - 1.5 |
| torsional friction of the object's contacts | ``pair_friction[:, 2]`` | x 0.5 - 1.5 |
| object mass and inertia (same density scale) | ``body_mass``, ``body_inertia`` | x 0.5 - 2 |
| servo gain ``kp``, per actuator | ``actuator_gainprm[:, 0]``, ``-biasprm[:, 1]`` | x 0.8 - 1.2 |
| one policy step of action latency | the env applies the previous action | 0 or 1 step, p = 0.5 |
| sensor noise, Gaussian | joints, contact positions, normal forces | 0.005 rad, 1 mm, 0.05 N |

Scales are drawn uniformly between the bounds (mass log-uniformly, so that x0.5 and x2 are
equally likely). With ``corner_prob`` > 0, an episode is instead, with that probability, one
of the :func:`corners` drawn uniformly (boundary sampling: the bounds, where a policy fails
first, are drawn more often than a uniform draw would). With ``hard_prob`` > 0 an episode is,
with that probability, drawn from the hard region: friction at its lower bound, mass
log-uniform in the upper half of its range (nominal to heaviest), torsional friction
uniform and each servo gain uniform between the range's lower bound and ``hard_gain``
(default: the whole range; 1: the weak half): where the sphere policies drop (half the
friction at the nominal mass and above, worst with weak servos; docs/four_finger.md).

The servo's torque limit (``forcerange`` 0.5 N m) is the motor's and is not scaled.
Setpoints (``data.ctrl``) are the controller's own numbers and are not noisy; contact slots
of a link that touches nothing stay zero. ``mj_setConst`` is run after every change so that
the model's derived constants (``body_subtreemass``, ``dof_invweight0``) follow.

:func:`corners` lists the ``2^4`` combinations of the bounds of friction, torsional friction,
mass and gain, each with latency and noise at their maxima: the robustness table's cases.
:meth:`Randomization.scaled` shrinks the four ranges towards nominal (a narrower stated
range, or a first stage of a curriculum: ``python -m train.ppo --range-scale``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.four_finger.physics import FourFingerError

__all__ = ["ModelScaler", "PhysicsSample", "Randomization", "centre", "corners"]


@dataclass(frozen=True)
class Randomization:
    """Ranges of the randomised physics (``(low, high)`` scale factors; module table)."""

    friction: tuple[float, float] = (0.5, 1.5)
    torsional: tuple[float, float] = (0.5, 1.5)
    mass: tuple[float, float] = (0.5, 2.0)
    gain: tuple[float, float] = (0.8, 1.2)
    latency_prob: float = 0.5  # probability that an episode has one step of action latency
    noise_joint: float = 0.005  # [rad] std of joint position noise
    noise_pos: float = 0.001  # [m] std of contact position noise
    noise_force: float = 0.05  # [N] std of normal force noise
    corner_prob: float = 0.0  # probability that an episode is one of the corners()
    hard_prob: float = 0.0  # probability that an episode is drawn from the hard region
    hard_gain: float = math.inf  # upper bound of the gains in the hard region (inf: gain[1])

    def __post_init__(self) -> None:
        for name in ("friction", "torsional", "mass", "gain"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
                raise FourFingerError(
                    f"randomization {name} range must be 0 < low <= high, got {(lo, hi)}"
                )
        for name in ("latency_prob", "corner_prob", "hard_prob"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise FourFingerError(f"{name} must be in [0, 1], got {v}")
        if not self.hard_gain >= self.gain[0]:
            raise FourFingerError(f"hard_gain must be >= {self.gain[0]}, got {self.hard_gain}")
        if self.corner_prob + self.hard_prob > 1.0:
            raise FourFingerError(
                f"corner_prob + hard_prob must be <= 1, got {self.corner_prob + self.hard_prob}"
            )
        for name in ("noise_joint", "noise_pos", "noise_force"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise FourFingerError(f"{name} must be a finite number >= 0, got {v}")

    def scaled(self, s: float) -> Randomization:
        """The ranges shrunk towards nominal by ``s`` in (0, 1]: each bound ``b`` of friction,
        torsional friction and gain becomes ``1 + s (b - 1)``, each mass bound ``b**s`` (the
        log-range scaled, so x0.5-2 at ``s = 0.5`` is x0.71-1.41). Latency, noise and the
        sampling probabilities are kept: they are not ranges of a scale. ``s = 1`` is ``self``."""
        if not (np.isfinite(s) and 0.0 < s <= 1.0):
            raise FourFingerError(f"range scale must be in (0, 1], got {s}")
        if s == 1.0:
            return self

        def lin(r: tuple[float, float]) -> tuple[float, float]:
            return (1.0 + s * (r[0] - 1.0), 1.0 + s * (r[1] - 1.0))

        hard = self.hard_gain if math.isinf(self.hard_gain) else 1.0 + s * (self.hard_gain - 1.0)
        return replace(
            self,
            friction=lin(self.friction),
            torsional=lin(self.torsional),
            mass=(self.mass[0] ** s, self.mass[1] ** s),
            gain=lin(self.gain),
            hard_gain=hard,
        )

    def sample(self, rng: np.random.Generator, nu: int) -> PhysicsSample:
        """One episode's physics: with probability ``corner_prob`` one of :func:`corners`
        (each equally likely), with probability ``hard_prob`` a draw from the hard region,
        else the uniform draw of the module doc."""
        lo, hi = np.log(self.mass)
        friction, gain = self.friction, self.gain
        if self.corner_prob > 0 or self.hard_prob > 0:
            u = rng.uniform()
            if u < self.corner_prob:
                cs = corners(self)
                return cs[int(rng.integers(len(cs)))]
            if u < self.corner_prob + self.hard_prob:
                friction, lo = (self.friction[0], self.friction[0]), max(lo, min(0.0, hi))
                gain = (self.gain[0], min(self.hard_gain, self.gain[1]))
        return PhysicsSample(
            friction=float(rng.uniform(*friction)),
            torsional=float(rng.uniform(*self.torsional)),
            mass=float(np.exp(rng.uniform(lo, hi))),
            gain=tuple(float(g) for g in rng.uniform(*gain, nu)),
            latency=int(rng.uniform() < self.latency_prob),
            noise=(self.noise_joint, self.noise_pos, self.noise_force),
        )


@dataclass(frozen=True)
class PhysicsSample:
    """The physics of one episode: scale factors, latency [policy steps] and noise stds
    (joint [rad], contact position [m], normal force [N]). ``gain`` is one factor for all
    actuators or one per actuator."""

    friction: float = 1.0
    torsional: float = 1.0
    mass: float = 1.0
    gain: float | tuple[float, ...] = 1.0
    latency: int = 0
    noise: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def label(self) -> str:
        """``friction x0.5, torsional x1.5, mass x2, gain x0.8, latency 1, noise``."""
        g = self.gain if isinstance(self.gain, float | int) else float(np.mean(self.gain))
        return (
            f"friction x{self.friction:g}, torsional x{self.torsional:g}, mass x{self.mass:g}, "
            f"gain x{g:g}, latency {self.latency}" + (", noise" if any(self.noise) else "")
        )


def _case(
    r: Randomization, friction: float, torsional: float, mass: float, gain: float
) -> PhysicsSample:
    """One evaluation case of ``r``: the scales given, one step of latency (if ``r`` allows
    any) and ``r``'s noise."""
    noise = (r.noise_joint, r.noise_pos, r.noise_force)
    return PhysicsSample(friction, torsional, mass, gain, int(r.latency_prob > 0), noise)


def corners(r: Randomization | None = None) -> list[PhysicsSample]:
    """The ``2^4`` corners of ``r``'s friction, torsional, mass and gain ranges, each with one
    step of latency (if ``r`` allows any) and ``r``'s noise."""
    r = r or Randomization()
    return [
        _case(r, f, t, m, g)
        for f, t, m, g in itertools.product(r.friction, r.torsional, r.mass, r.gain)
    ]


def centre(r: Randomization | None = None) -> PhysicsSample:
    """The centre of ``r``'s ranges: friction, torsional friction and gain at the middle of
    their ranges, mass at the geometric middle (the middle of its log-uniform draw), with
    latency and noise as at the :func:`corners`."""
    r = r or Randomization()
    mid = [sum(b) / 2 for b in (r.friction, r.torsional, r.gain)]
    return _case(r, mid[0], mid[1], math.sqrt(r.mass[0] * r.mass[1]), mid[2])


class ModelScaler:
    """Writes a :class:`PhysicsSample`'s scales into a model, from the nominal values saved
    when it is built (so scales never compound)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, obj_body: int) -> None:
        self.model, self.data, self.obj_body = model, data, obj_body
        pair_bodies = np.stack(
            [model.geom_bodyid[model.pair_geom1], model.geom_bodyid[model.pair_geom2]], axis=1
        )
        self.obj_pairs = np.flatnonzero((pair_bodies == obj_body).any(axis=1))
        self.friction0 = model.pair_friction.copy()
        self.mass0 = float(model.body_mass[obj_body])
        self.inertia0 = model.body_inertia[obj_body].copy()
        self.kp0 = model.actuator_gainprm[:, 0].copy()
        if not np.allclose(model.actuator_biasprm[:, 1], -self.kp0):
            raise FourFingerError("gain randomisation expects position servos (biasprm[1] = -kp)")
        self.current = PhysicsSample()

    def apply(self, s: PhysicsSample) -> None:
        """Scale friction, torsional friction, mass, inertia and gains (nominal x factor)."""
        m, p = self.model, self.obj_pairs
        m.pair_friction[:] = self.friction0
        m.pair_friction[p, 0:2] *= s.friction
        m.pair_friction[p, 2] *= s.torsional
        m.body_mass[self.obj_body] = self.mass0 * s.mass
        m.body_inertia[self.obj_body] = self.inertia0 * s.mass
        kp = self.kp0 * np.asarray(s.gain, dtype=float)
        m.actuator_gainprm[:, 0] = kp
        m.actuator_biasprm[:, 1] = -kp
        mujoco.mj_setConst(m, self.data)
        self.current = s

    def noise(self, rng: np.random.Generator, n_joints: int, n_links: int) -> NDArray[np.float64]:
        """One observation's additive noise (joints, zero setpoint noise, then per link x, y, z,
        c_n); the caller zeroes the slots of links without contact."""
        sq, sp, sf = self.current.noise
        out = np.zeros(2 * n_joints + 4 * n_links)
        out[:n_joints] = rng.normal(0.0, sq, n_joints) if sq else 0.0
        c = out[2 * n_joints :].reshape(n_links, 4)
        c[:, :3] = rng.normal(0.0, sp, (n_links, 3)) if sp else 0.0
        c[:, 3] = rng.normal(0.0, sf, n_links) if sf else 0.0
        return out
