"""The grasp model: contact points, frames, friction, grasp map and hand matrices.

Conventions (docs/design.md, Conventions; thesis ch. 4-5):

* A contact has an orthonormal frame ``[n, t]`` (planar) or ``[n, t1, t2]``
  (spatial). ``n`` points INTO the object: the direction in which the hand
  pushes it. In the plane ``t`` is ``n`` rotated by +90 degrees. Spatial
  tangents are built deterministically when not given (see
  :func:`default_tangents`), so that ``t2 = n x t1`` (right-handed frame).
* Contact forces are forces applied by the hand on the object, expressed in
  the contact frame, stacked per contact: ``c = [c_1n, c_1t, c_2n, c_2t, ...]``.
* The grasp map ``G`` (3 x 2m planar, 6 x 3m spatial) maps ``c`` to the wrench
  on the object about the object-frame origin; equilibrium is ``G c + w = 0``.
  ``G^T r`` is the contact-point displacement (in contact frames) caused by a
  small object motion ``r`` (planar ``r = (x, y, theta)``, spatial
  ``r = (v, omega)``); ``d_n > 0`` is separation.
* Optional hand: ``J`` (2m x l or 3m x l) maps joint motion ``q`` to contact
  motion in contact frames, so ``d = G^T r - J q``; ``R`` (l x a) maps actuator
  forces to joint torques ``tau = R f``. Without ``J`` the hand is a rigid
  fixture. Actuators are nonbackdrivable (thesis ch. 5: ``R^T q >= 0``, ``f >= f_c``,
  ``f = f_c`` where the transmission moves) unless marked ``backdrivable``: a
  backdrivable actuator is a constant force source, ``f = f_c`` whatever its
  transmission does (``R^T q`` free). That is how a motor without a self-locking
  gear, a saturated position servo, a passive spring's torque or a link's weight
  enters the model (``ihm.grasp_from_mujoco``).
* Optional compliance (our extension of the thesis' model, off by default): per contact a
  normal stiffness ``k_i > 0``, so that the spring law is ``c_n = max(0, p - k_i d_n)``
  (the thesis' unit springs are ``k_i = 1``); per actuator a stiffness ``K_a >= 0`` and a
  stop gap ``g_a >= 0``: its force is ``f = f_c - K v + lambda`` with ``v = R^T q`` its
  transmission motion, ``lambda >= 0`` the reaction of a one-way stop at ``v = -g``
  (``v >= -g``, ``lambda (v + g) = 0``). ``K = 0, g = 0`` is the thesis' nonbackdrivable
  actuator; a backdrivable one has no stop (``lambda = 0``, ``f = f_c - K v``): a constant
  force source when ``K = 0``, a spring (a position servo, a passive joint spring) when
  ``K > 0``.

Units: positions in metres (or any consistent length unit), forces in newtons,
torques in newton-metres; ``mu`` is dimensionless.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GraspError

__all__ = ["Grasp", "actuator_compliance", "default_tangents", "cross2"]


def cross2(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Planar cross product ``a_x b_y - a_y b_x`` along the last axis."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def default_tangents(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    """Deterministic tangent frames for unit normals (m, 3) -> (m, 2, 3).

    ``t1 = normalize(e x n)`` with ``e`` the coordinate axis least aligned with
    ``n`` (ties broken towards the lower axis index), ``t2 = n x t1``. The
    result depends only on ``n`` and is continuous away from the tie surfaces.
    """
    n = np.asarray(normals, dtype=float)
    axis = np.argmin(np.abs(n), axis=1)
    e = np.eye(3)[axis]
    t1 = np.cross(e, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return np.stack([t1, t2], axis=1)


def _as_finite(name: str, value: ArrayLike) -> NDArray[np.float64]:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GraspError(f"{name} must be numeric, got {value!r}") from exc
    if not np.all(np.isfinite(arr)):
        raise GraspError(f"{name} contains NaN or inf")
    return arr


class Grasp:
    """A grasp: ``m`` point contacts with Coulomb friction on one object.

    Parameters
    ----------
    points : (m, 2) or (m, 3) array
        Contact points in the object frame [m]. The column count decides
        whether the grasp is planar (2) or spatial (3).
    normals : (m, 2) or (m, 3) array
        Contact normals pointing INTO the object. Non-unit normals are
        normalised; a zero normal is an error.
    mu : float or (m,) array
        Coulomb friction coefficients, ``>= 0``.
    tangents : (m, 3) or (m, 2, 3) array, optional (spatial only)
        ``t1`` per contact, or ``(t1, t2)`` per contact. With only ``t1``,
        ``t2 = n x t1``. Frames must be orthonormal (tolerance 1e-6).
        Planar tangents are always ``n`` rotated by +90 degrees.
    J : (k m, l) array, optional
        Hand Jacobian in contact frames (``k`` = 2 planar, 3 spatial).
    R : (l, a) array, optional
        Transmission: joint torques ``tau = R f`` for actuator forces ``f``.
        Requires ``J``.
    backdrivable : (a,) bool array, optional
        Per actuator (column of ``R``; of the identity when ``R`` is not given):
        True makes it a constant force source (``f = f_c``, transmission free);
        default all False (the thesis' nonbackdrivable actuators). Requires ``J``.
    stiffness : float or (m,) array, optional
        Normal stiffness ``k_i > 0`` of each contact's spring [N/m]: ``c_n = max(0, p - k_i
        d_n)``. Default 1 (the thesis' unit virtual springs, displacements in newtons).
    actuator_stiffness : (a,) array, optional
        ``K_a >= 0`` per actuator [N/m or N m/rad, per unit of its transmission motion
        ``v = R^T q``]: ``f = f_c - K v (+ lambda)``. Default 0. Requires ``J``.
    stop_gap : (a,) array, optional
        ``g_a >= 0`` per nonbackdrivable actuator [m or rad of ``v``]: how far its
        transmission runs back before its one-way stop holds (``v >= -g``). Default 0 (the
        thesis' lock at the current state); must be 0 for a backdrivable one (no stop).
        Requires ``J``.

    Raises
    ------
    GraspError
        On mismatched shapes, NaN/inf, negative friction, zero normals,
        non-orthonormal or left-handed frames.
    """

    def __init__(
        self,
        points: ArrayLike,
        normals: ArrayLike,
        mu: float | ArrayLike,
        tangents: ArrayLike | None = None,
        J: ArrayLike | None = None,
        R: ArrayLike | None = None,
        backdrivable: ArrayLike | None = None,
        stiffness: float | ArrayLike | None = None,
        actuator_stiffness: ArrayLike | None = None,
        stop_gap: ArrayLike | None = None,
    ) -> None:
        p = _as_finite("points", points)
        n = _as_finite("normals", normals)
        if p.ndim != 2 or p.shape[1] not in (2, 3):
            raise GraspError(f"points must have shape (m, 2) or (m, 3), got {p.shape}")
        m, dim = p.shape
        if m == 0:
            raise GraspError("a grasp needs at least one contact, got 0 points")
        if n.shape != p.shape:
            raise GraspError(f"normals shape {n.shape} does not match points shape {p.shape}")
        norms = np.linalg.norm(n, axis=1)
        if np.any(norms < 1e-12):
            raise GraspError(f"zero normal at contact(s) {np.flatnonzero(norms < 1e-12).tolist()}")
        n = n / norms[:, None]

        mu_arr = _as_finite("mu", mu)
        if mu_arr.ndim == 0:
            mu_arr = np.full(m, float(mu_arr))
        if mu_arr.shape != (m,):
            raise GraspError(f"mu must be a scalar or have shape ({m},), got {mu_arr.shape}")
        if np.any(mu_arr < 0):
            raise GraspError(f"friction coefficient mu must be >= 0, got {mu_arr.tolist()}")

        if dim == 2:
            if tangents is not None:
                raise GraspError("planar grasps take no tangents: t is n rotated by +90 degrees")
            t = np.stack([-n[:, 1], n[:, 0]], axis=1)[:, None, :]
        else:
            t = default_tangents(n) if tangents is None else self._check_tangents(tangents, n)

        self._points = p
        self._normals = n
        self._tangents = t  # (m, dim-1, dim)
        self._mu = mu_arr
        self._dim = dim
        self._J = None
        self._R = None
        k = dim
        if J is not None:
            Jm = _as_finite("J", J)
            if Jm.ndim != 2 or Jm.shape[0] != k * m:
                raise GraspError(f"J must have shape ({k * m}, l) for {m} contacts, got {Jm.shape}")
            self._J = Jm
        if R is not None:
            if self._J is None:
                raise GraspError("R (transmission) given without J (hand Jacobian)")
            Rm = _as_finite("R", R)
            if Rm.ndim != 2 or Rm.shape[0] != self._J.shape[1]:
                raise GraspError(
                    f"R must have shape ({self._J.shape[1]}, a) to match J's "
                    f"{self._J.shape[1]} joints, got {Rm.shape}"
                )
            self._R = Rm
        self._backdrivable = None
        if self._J is not None:
            a = self._J.shape[1] if self._R is None else self._R.shape[1]
            self._backdrivable = np.zeros(a, dtype=bool)
            if backdrivable is not None:
                b = np.asarray(backdrivable)
                if b.shape != (a,) or b.dtype.kind not in "bi" or not np.isin(b, (0, 1)).all():
                    raise GraspError(
                        f"backdrivable must be {a} booleans (one per actuator), got "
                        f"{backdrivable!r}"
                    )
                self._backdrivable = b.astype(bool)
        elif backdrivable is not None:
            raise GraspError("backdrivable given without J (hand Jacobian)")
        self._stiffness = self._check_stiffness(stiffness)
        self._actuator_stiffness, self._stop_gap = self._check_actuators(
            actuator_stiffness, stop_gap
        )
        for arr in (self._points, self._normals, self._tangents, self._mu, self._J, self._R,
                    self._backdrivable, self._stiffness, self._actuator_stiffness,
                    self._stop_gap):  # fmt: skip
            if arr is None:
                continue
            arr.setflags(write=False)
        self._G = self._build_G()
        self._G.setflags(write=False)

    def _check_stiffness(self, stiffness: float | ArrayLike | None) -> NDArray[np.float64]:
        k = self.per_contact(stiffness, "stiffness", nonneg=False, default=1.0)
        if np.any(k <= 0):
            raise GraspError(f"contact stiffness must be > 0 [N/m], got {k.tolist()}")
        return k

    def _check_actuators(
        self, stiffness: ArrayLike | None, gap: ArrayLike | None
    ) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
        if self._J is None:
            for name, val in (("actuator_stiffness", stiffness), ("stop_gap", gap)):
                if val is not None:
                    raise GraspError(f"{name} given without J (hand Jacobian)")
            return None, None
        a = self._backdrivable.size
        out = []
        for name, val in (("actuator_stiffness", stiffness), ("stop_gap", gap)):
            arr = np.zeros(a) if val is None else _as_finite(name, val)
            if arr.shape != (a,):
                raise GraspError(f"{name} must have shape ({a},), one per actuator, got "
                                 f"{arr.shape}")  # fmt: skip
            if np.any(arr < 0):
                raise GraspError(f"{name} must be >= 0, got {arr.tolist()}")
            out.append(arr)
        bad = np.flatnonzero(self._backdrivable & (out[1] > 0))
        if bad.size:
            raise GraspError(f"stop_gap at backdrivable actuator(s) {bad.tolist()}: a "
                             "backdrivable actuator has no stop (set its gap to 0)")  # fmt: skip
        return out[0], out[1]

    @staticmethod
    def _check_tangents(tangents: ArrayLike, n: NDArray[np.float64]) -> NDArray[np.float64]:
        m = n.shape[0]
        t = _as_finite("tangents", tangents)
        if t.shape == (m, 3):
            t = np.stack([t, np.cross(n, t)], axis=1)
        if t.shape != (m, 2, 3):
            raise GraspError(f"tangents must have shape ({m}, 3) or ({m}, 2, 3), got {t.shape}")
        frames = np.concatenate([n[:, None, :], t], axis=1)  # (m, 3, 3) rows n, t1, t2
        gram = frames @ frames.transpose(0, 2, 1)
        err = np.abs(gram - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero(err > 1e-6)
        if bad.size:
            raise GraspError(
                f"contact frames [n, t1, t2] not orthonormal at contact(s) {bad.tolist()} "
                f"(max |F F^T - I| = {err.max():.3g})"
            )
        det = np.linalg.det(frames)
        bad = np.flatnonzero(det < 0)
        if bad.size:
            raise GraspError(
                f"contact frames left-handed (t2 != n x t1) at contact(s) {bad.tolist()}"
            )
        return t

    # -- geometry ---------------------------------------------------------------------
    @property
    def m(self) -> int:
        """Number of contacts."""
        return self._points.shape[0]

    @property
    def dim(self) -> int:
        """2 for planar grasps, 3 for spatial ones."""
        return self._dim

    @property
    def planar(self) -> bool:
        return self._dim == 2

    @property
    def points(self) -> NDArray[np.float64]:
        """(m, dim) contact points in the object frame [m]."""
        return self._points

    @property
    def normals(self) -> NDArray[np.float64]:
        """(m, dim) unit normals pointing into the object."""
        return self._normals

    @property
    def tangents(self) -> NDArray[np.float64]:
        """(m, dim-1, dim) unit tangents: planar ``t`` = n rotated +90 deg, spatial ``t1, t2``."""
        return self._tangents

    @property
    def frames(self) -> NDArray[np.float64]:
        """(m, dim, dim) contact frames, rows ``[n, t]`` or ``[n, t1, t2]``."""
        return np.concatenate([self._normals[:, None, :], self._tangents], axis=1)

    @property
    def mu(self) -> NDArray[np.float64]:
        """(m,) friction coefficients."""
        return self._mu

    @property
    def J(self) -> NDArray[np.float64] | None:
        """Hand Jacobian in contact frames, or None for a rigid fixture."""
        return self._J

    @property
    def R(self) -> NDArray[np.float64] | None:
        """Transmission (joint torques per actuator force), or None."""
        return self._R

    @property
    def backdrivable(self) -> NDArray[np.bool_] | None:
        """(a,) per actuator: True for a constant force source (``f = f_c``, transmission
        free), False for the thesis' nonbackdrivable actuator; None without a hand."""
        return self._backdrivable

    @property
    def stiffness(self) -> NDArray[np.float64]:
        """(m,) normal stiffness of each contact's spring [N/m] (1: the thesis' unit springs)."""
        return self._stiffness

    @property
    def actuator_stiffness(self) -> NDArray[np.float64] | None:
        """(a,) stiffness ``K`` per actuator (``f = f_c - K v + lambda``); None without a hand."""
        return self._actuator_stiffness

    @property
    def stop_gap(self) -> NDArray[np.float64] | None:
        """(a,) how far each nonbackdrivable transmission runs back before its stop holds
        (``v >= -g``); None without a hand."""
        return self._stop_gap

    @property
    def compliant(self) -> bool:
        """True when any stiffness or stop gap differs from the thesis' model (unit contact
        springs, rigid transmissions locking where they are)."""
        if np.any(self._stiffness != 1.0):
            return True
        if self._J is None:
            return False
        return bool(np.any(self._actuator_stiffness != 0) or np.any(self._stop_gap != 0))

    @property
    def wrench_dim(self) -> int:
        """3 for planar (fx, fy, tz), 6 for spatial (f, tau)."""
        return 3 if self._dim == 2 else 6

    @property
    def G(self) -> NDArray[np.float64]:
        """Grasp map: (3, 2m) planar, (6, 3m) spatial.

        Column for unit force ``f`` (a frame axis) at point ``p``: ``[f; p x f]``
        (planar moment ``p_x f_y - p_y f_x``).
        """
        return self._G

    def _build_G(self) -> NDArray[np.float64]:
        F = self.frames  # (m, k, dim)
        m, k, dim = F.shape
        if dim == 2:
            mom = cross2(self._points[:, None, :], F)[..., None]  # (m, k, 1)
        else:
            mom = np.cross(self._points[:, None, :], F)  # (m, k, 3)
        cols = np.concatenate([F, mom], axis=2)  # (m, k, wrench_dim)
        return cols.reshape(m * k, -1).T.copy()

    def __repr__(self) -> str:
        kind = "planar" if self.planar else "spatial"
        hand = "rigid" if self._J is None else f"J {self._J.shape}"
        return f"Grasp({kind}, m={self.m}, hand={hand})"

    # -- helpers used by solvers ---------------------------------------------------------
    def per_contact(
        self, value: float | ArrayLike | None, name: str, nonneg: bool = True, default: float = 0.0
    ) -> NDArray[np.float64]:
        """Broadcast a scalar or (m,) per-contact quantity, validated."""
        if value is None:
            return np.full(self.m, default)
        arr = _as_finite(name, value)
        if arr.ndim == 0:
            arr = np.full(self.m, float(arr))
        if arr.shape != (self.m,):
            raise GraspError(f"{name} must be a scalar or have shape ({self.m},), got {arr.shape}")
        if nonneg and np.any(arr < 0):
            raise GraspError(f"{name} must be >= 0, got {arr.tolist()}")
        return arr

    def spring_force(
        self, normal_motion: ArrayLike, preload: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """(m,) normal forces of the contacts' springs, ``max(0, p - k d_n)`` [N], for the
        normal motions ``d_n`` (``> 0`` separates) and preloads ``p`` (default 0)."""
        p = 0.0 if preload is None else np.asarray(preload, dtype=float)
        return np.maximum(0.0, p - self._stiffness * np.asarray(normal_motion, dtype=float))

    def contact_motion(
        self, motion: ArrayLike, hand_motion: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Per contact, the object's motion relative to the hand in the contact frame,
        ``d = G^T r - J q`` (``J q`` only with a hand and ``hand_motion``): (m, dim),
        normal first; ``d_n > 0`` separates."""
        d = self._G.T @ np.asarray(motion, dtype=float)
        if hand_motion is not None and self._J is not None:
            d = d - self._J @ np.asarray(hand_motion, dtype=float)
        return d.reshape(self.m, self.dim)

    def wrench(self, value: ArrayLike, name: str = "wrench") -> NDArray[np.float64]:
        """Validate a wrench of this grasp's dimension."""
        arr = _as_finite(name, value)
        if arr.shape != (self.wrench_dim,):
            raise GraspError(
                f"{name} must have shape ({self.wrench_dim},) for a "
                f"{'planar' if self.planar else 'spatial'} grasp, got {arr.shape}"
            )
        return arr


def actuator_compliance(grasp: Grasp, na: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(K, g)``: the grasp's actuator stiffness and stop gaps over its ``na`` actuators
    (zeros where not set: the thesis' rigid transmissions)."""
    K = getattr(grasp, "actuator_stiffness", None)
    g = getattr(grasp, "stop_gap", None)
    K = np.zeros(na) if K is None else np.asarray(K, dtype=float)
    g = np.zeros(na) if g is None else np.asarray(g, dtype=float)
    if K.shape != (na,) or g.shape != (na,):
        raise GraspError(f"actuator_stiffness/stop_gap have {K.size}/{g.size} entries for "
                         f"{na} actuators")  # fmt: skip
    return K, g
