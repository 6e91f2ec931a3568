"""The candidate contact states of a planar grasp (thesis sec. state_number), from the
faces of two plane arrangements in the space of object motions ``r = (x, y, theta)``:

* slip states: all faces of the central arrangement of the tangential planes
  ``T_i r = 0`` (``d_t = T r``), sign ``+1``/``-1`` slip along ``+-t``, ``0`` roll;
* detachment states: the regions of the affine arrangement of the normal planes
  ``N_i r = p_i`` (``d_n = N r``, preload ``p`` [N]), ``1`` persist, ``0`` detach;
* joint states: the (slip, detachment) pairs that co-occur for some motion, enumerated
  together (:func:`state_chunks`), the set the solver visits.

The geometry is exact (:mod:`stability.planar._arrangement`), no LP per step.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import GraspError, MethodError
from ..grasp import Grasp, cross2
from ._arrangement import affine_faces, central_faces, dedupe_planes

__all__ = [
    "STATE_NAMES",
    "contact_states",
    "count_slip_faces",
    "detachment_states",
    "motion_planes",
    "preload_vector",
    "require_planar",
    "slip_states",
    "state_chunks",
]

STATE_NAMES = {(1, 0): "roll", (1, 1): "slip+", (1, -1): "slip-"}


def motion_planes(grasp: Grasp) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rows ``T_i``, ``N_i`` (each (m, 3)) with ``d_t = T r`` and ``d_n = N r``."""
    require_planar(grasp)
    p, n, t = grasp.points, grasp.normals, grasp.tangents[:, 0, :]
    T = np.concatenate([t, cross2(p, t)[:, None]], axis=1)
    N = np.concatenate([n, cross2(p, n)[:, None]], axis=1)
    return T, N


def require_planar(grasp: Grasp) -> None:
    """GraspError unless ``grasp`` is a :class:`~stability.Grasp`, MethodError unless planar."""
    if not isinstance(grasp, Grasp):
        raise GraspError(f"expected a stability.Grasp, got {type(grasp).__name__}")
    if not grasp.planar:
        raise MethodError("the planar method needs a planar grasp (points of shape (m, 2))")


def _slip_arrangement(grasp: Grasp):
    """Distinct tangential planes ``Au`` (with ``idx``, ``orient`` back to contacts) and
    the sign vectors of all faces of their central arrangement."""
    T, _ = motion_planes(grasp)
    Au, _, idx, orient = dedupe_planes(T, np.zeros(len(T)))
    return Au, idx, orient, central_faces(Au)


def slip_states(grasp: Grasp) -> NDArray[np.int8]:
    """Every slip state consistent with a rigid motion of the object: (K, m) in {-1, 0, 1}.

    ``+1``/``-1``: the contact slips in the +t / -t direction (``d_t > 0`` /
    ``< 0``), ``0``: it rolls. Rows are the distinct sign vectors of the faces
    (regions, facets, lines, origin) of the central arrangement of the planes
    ``T_i r = 0``, computed exactly on the sphere in ``O(m^2 log m)`` plus
    ``O(m^3)`` sign evaluations; the first row is the all-rolling state. For
    ``m >= 3`` generic contacts ``K = 4m^2 - 4m + 2`` (thesis table) ``+ 1``
    (the all-rolling state, which we count). For ``m = 2`` the two opposite
    lines where both contacts roll share the all-rolling sign vector, so
    ``K = 9``; :func:`count_slip_faces` counts faces and gives the thesis' 10.
    """
    Au, idx, orient, faces = _slip_arrangement(grasp)
    S = faces[:, idx] * orient
    S = np.unique(S, axis=0)
    zero = np.flatnonzero(~S.any(axis=1))
    order = np.concatenate([zero, np.flatnonzero(S.any(axis=1))])
    return S[order]


def count_slip_faces(grasp: Grasp) -> dict[str, int]:
    """Faces of the tangential-plane arrangement by dimension (thesis sec. state_number).

    ``regions`` (3-faces, all contacts slip), ``facets`` (2-faces), ``lines``
    (1-faces, counted as rays from the origin) and ``origin`` (1 when the
    planes meet only at the origin). ``total`` = regions + facets + lines is
    the thesis' ``#(S)``: ``4m^2 - 4m + 2`` for generic contacts.
    """
    Au, _, _, faces = _slip_arrangement(grasp)
    rank_all = np.linalg.matrix_rank(Au)
    counts = {"regions": 0, "facets": 0, "lines": 0, "origin": 0}
    for f in faces:
        z = np.flatnonzero(f == 0)
        dim = 3 - (np.linalg.matrix_rank(Au[z]) if len(z) else 0)
        if len(z) == len(Au):  # the all-rolling face: origin, or the common line
            if rank_all == 3:
                counts["origin"] += 1
            elif rank_all == 2:
                counts["lines"] += 2
            continue
        counts[{3: "regions", 2: "facets", 1: "lines"}[dim]] += 1
    counts["total"] = counts["regions"] + counts["facets"] + counts["lines"]
    return counts


def preload_vector(grasp: Grasp, preload: Any) -> NDArray[np.float64]:
    """The preload [N] per contact (a scalar for all; None: 0); GraspError if invalid."""
    return grasp.per_contact(preload, "preload")


def detachment_states(
    grasp: Grasp, preload: float | NDArray[np.float64] | None = None
) -> NDArray[np.int8]:
    """Detachment states: (K, m) with 1 = contact persists, 0 = detaches (thesis ``U_k``).

    The regions of the affine arrangement ``N_i r = p_i`` (closed on the
    persist side). With preload the planes miss the origin, and there are up
    to ``sum_{k<=3} C(m, k)`` regions; without, ``m(m-1) + 2``.
    """
    _, N = motion_planes(grasp)
    p = preload_vector(grasp, preload)
    Au, bu, idx, orient = dedupe_planes(N, p)
    faces = np.concatenate(list(affine_faces(Au, bu, np.zeros(len(Au), dtype=bool))))
    faces = faces[np.all(faces != 0, axis=1)]  # regions only (non-simple vertices give all faces)
    U = (faces[:, idx] * orient <= 0).astype(np.int8)
    return np.unique(U, axis=0)


def _planes(grasp: Grasp, p: NDArray[np.float64]):
    T, N = motion_planes(grasp)
    m = grasp.m
    A = np.concatenate([T, N])
    b = np.concatenate([np.zeros(m), p])
    Au, bu, idx, orient = dedupe_planes(A, b)
    may_zero = np.zeros(len(Au), dtype=bool)
    may_zero[idx[:m]] = True
    return T, N, Au, bu, idx, orient, may_zero


def state_chunks(
    grasp: Grasp, p: NDArray[np.float64], chunk: int = 8192
) -> Iterator[tuple[NDArray[np.int8], NDArray[np.bool_]]]:
    """Candidate (slip state S, persist mask P) chunks co-occurring for some motion.

    Small pieces from the enumeration are merged to about ``chunk`` rows so
    that the batched solves amortise their overhead.
    """
    m = grasp.m
    _, _, Au, bu, idx, orient, may_zero = _planes(grasp, p)
    buf: list[NDArray[np.int8]] = []
    rows = 0
    first = True
    for f in affine_faces(Au, bu, may_zero, chunk=chunk):
        buf.append(f)
        rows += len(f)
        if rows >= chunk or first:  # the first piece (the origin's faces) goes out alone
            first = False
            sv = np.concatenate(buf)[:, idx] * orient
            yield sv[:, :m], sv[:, m:] <= 0
            buf, rows = [], 0
    if buf:
        sv = np.concatenate(buf)[:, idx] * orient
        yield sv[:, :m], sv[:, m:] <= 0


def contact_states(
    grasp: Grasp, preload: float | NDArray[np.float64] | None = None
) -> tuple[NDArray[np.int8], NDArray[np.int8]]:
    """All co-occurring (slip, detachment) state pairs, deduplicated.

    Returns ``(S, U)``, each (K, m): ``S`` in {-1, 0, 1} (slip-, roll, slip+),
    ``U`` in {0, 1} (detach, persist). This is the set the solver visits
    (thesis ``T = U x S``, restricted to pairs some motion realises).
    """
    require_planar(grasp)
    p = preload_vector(grasp, preload)
    parts = [np.concatenate([S, P.astype(np.int8)], axis=1) for S, P in state_chunks(grasp, p)]
    both = np.unique(np.concatenate(parts), axis=0)
    return both[:, : grasp.m], both[:, grasp.m :]
