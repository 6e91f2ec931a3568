"""Faces of plane arrangements in the 3-D space of planar object motions.

Two arrangements matter for planar grasps (thesis sec. state_number):

* the *central* arrangement of the tangential-motion planes ``T_i r = 0``; its
  faces (regions, facets, lines, the origin) are the slip states;
* the *affine* arrangement of the normal-motion planes ``N_i r = p_i``; its
  regions are the detachment states.

Faces are returned as sign vectors ``sign(A r - b)`` in ``{-1, 0, 1}``.

Central arrangements are enumerated on the unit sphere: every pair of great
circles meets in two antipodal vertices; the arcs between consecutive
vertices on a circle are the 2-faces, and the two sides of each arc are the
3-faces. This is exact, needs no LP, and costs ``O(m^2 log m)`` plus the sign
evaluation.

Affine arrangements are enumerated by the *lowest vertex* rule: with a
generic height direction ``h``, every face of an essential arrangement that is
bounded below has a unique lowest vertex, and at a simple vertex (exactly
three independent planes) the faces whose lowest point it is are the cones
spanned by the edge directions ``e_j`` that point up (``h . e_j > 0``). Faces
unbounded below are caught by one extra "floor" plane ``h . r = -L`` placed
below every vertex. Non-simple vertices fall back to the full local (central)
enumeration. The output is a *superset* of the faces in degenerate
configurations (duplicates, never omissions), which is all a solver that
checks each candidate needs.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

__all__ = ["dedupe_planes", "central_faces", "affine_faces", "signs"]

# Generic height direction for the lowest-vertex rule (fixed for reproducibility).
_H = np.array([0.2718281828, 0.5772156649, 0.7702101]) / np.linalg.norm(
    [0.2718281828, 0.5772156649, 0.7702101]
)
_TOL = 1e-9


def signs(x: NDArray[np.float64], tol: float = _TOL) -> NDArray[np.int8]:
    """Elementwise sign with a dead zone ``|x| <= tol`` -> 0."""
    s = np.sign(x).astype(np.int8)
    s[np.abs(x) <= tol] = 0
    return s


def dedupe_planes(
    A: NDArray[np.float64], b: NDArray[np.float64], tol: float = 1e-9
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.intp], NDArray[np.int8]]:
    """Merge identical planes ``A_k r = b_k`` (up to scale and orientation).

    Returns unique unit-normal planes ``(Au, bu)`` and, for every input plane
    ``k``, ``index[k]`` and ``orient[k]`` with
    ``sign(A_k r - b_k) = orient[k] * sign(Au[index[k]] r - bu[index[k]])``.
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    scale = np.linalg.norm(A, axis=1)
    a = A / scale[:, None]
    beta = b / scale
    # canonical orientation: first clearly non-zero component positive
    first = np.argmax(np.abs(a) > 1e-6, axis=1)
    orient = np.sign(a[np.arange(len(a)), first]).astype(np.int8)
    a = a * orient[:, None]
    beta = beta * orient
    key = np.concatenate([a, beta[:, None]], axis=1)
    same = np.max(np.abs(key[:, None, :] - key[None, :, :]), axis=2) <= tol * (
        1.0 + np.abs(beta)[:, None]
    )
    first = np.argmax(same, axis=1)  # lowest-index plane equal to each plane
    reps, index = np.unique(first, return_inverse=True)
    return a[reps], beta[reps], index, orient


def unique_rows(x: NDArray[np.int8]) -> NDArray[np.int8]:
    """Distinct rows of a small-integer matrix (faster than ``np.unique(axis=0)``)."""
    if len(x) == 0:
        return x
    x = np.ascontiguousarray(x)
    v = x.view(np.dtype((np.void, x.dtype.itemsize * x.shape[1]))).ravel()
    _, first = np.unique(v, return_index=True)
    return x[np.sort(first)]


def _circle_bases(A: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    e = np.eye(3)[np.argmin(np.abs(A), axis=1)]
    e1 = np.cross(A, e)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(A, e1)


def central_faces(A: NDArray[np.float64], tol: float = _TOL) -> NDArray[np.int8]:
    """All faces of the central arrangement ``{A_k r = 0}`` in R^3, as sign vectors.

    ``A`` holds distinct unit normals (no two parallel, see
    :func:`dedupe_planes`). The first row is the origin face (all zeros).
    In general position with ``n >= 2`` planes there are ``n(n-1)+2`` regions,
    ``2n(n-1)`` facets and ``n(n-1)`` lines, ``4n^2 - 4n + 2`` faces besides
    the origin (thesis Table tab:performance); lines whose sign vectors
    coincide (``n = 2``: both rays of the one line are all-rolling) appear once.
    """
    A = np.asarray(A, dtype=float)
    n = len(A)
    origin = np.zeros((1, n), dtype=np.int8)
    if n == 0:
        return origin
    e1, e2 = _circle_bases(A)
    if n == 1:
        return np.array([[0], [1], [-1]], dtype=np.int8)
    i, j = np.triu_indices(n, 1)
    X = np.cross(A[i], A[j])
    nrm = np.linalg.norm(X, axis=1)
    X = X[nrm > tol] / nrm[nrm > tol, None]  # parallel rows (not expected here) meet nowhere
    verts = np.concatenate([X, -X])
    q = np.round(verts / 1e-7).astype(np.int64)  # merge vertices shared by 3+ circles
    qv = np.ascontiguousarray(q).view(np.dtype((np.void, 24))).ravel()
    _, first = np.unique(qv, return_index=True)
    verts = verts[np.sort(first)]
    # arcs: consecutive vertices around every circle
    on_v, on_k = np.nonzero(np.abs(verts @ A.T) <= 1e-7)
    ang = np.arctan2(
        np.einsum("kd,kd->k", verts[on_v], e2[on_k]), np.einsum("kd,kd->k", verts[on_v], e1[on_k])
    )
    order = np.lexsort((ang, on_k))
    k_s, a_s = on_k[order], ang[order]
    start = np.flatnonzero(np.r_[True, k_s[1:] != k_s[:-1]])
    nxt = np.r_[a_s[1:], 0.0]
    last = np.r_[start[1:], len(k_s)] - 1
    nxt[last] = a_s[start] + 2 * np.pi
    mid = 0.5 * (a_s + nxt)
    pts = np.cos(mid)[:, None] * e1[k_s] + np.sin(mid)[:, None] * e2[k_s]
    facets = signs(pts @ A.T)
    r = np.arange(len(k_s))
    facets[r, k_s] = 0
    up = facets.copy()
    up[r, k_s] = 1
    down = facets.copy()
    down[r, k_s] = -1
    return unique_rows(np.concatenate([origin, signs(verts @ A.T), facets, up, down]))


@lru_cache(maxsize=64)
def _triples(P: int) -> NDArray[np.intp]:
    if P < 3:
        return np.zeros((0, 3), dtype=np.intp)
    r = np.arange(P)
    i, j, k = np.meshgrid(r, r, r, indexing="ij")
    mask = (i < j) & (j < k)
    return np.stack([i[mask], j[mask], k[mask]], axis=1)


def _vertex_faces(
    A: NDArray[np.float64],
    b: NDArray[np.float64],
    may_zero: NDArray[np.bool_],
    only_neg: NDArray[np.bool_],
    tri: NDArray[np.intp],
    V: NDArray[np.float64],
    chunk: int,
) -> Iterator[NDArray[np.int8]]:
    """Faces whose lowest vertex is one of ``V`` (the vertices of the triples ``tri``).

    At a simple vertex, incident plane ``j`` takes the sign 0 (if
    ``may_zero[j]``) or its "up" sign ``sign(h . e_j)`` (dropped when
    ``only_neg[j]`` and up is +1: faces inside the bounding simplex only).
    """
    for s in range(0, len(V), chunk):
        v = V[s : s + chunk]
        t = tri[s : s + chunk]
        res = v @ A.T - b  # (k, P)
        scale = _TOL * (1.0 + np.abs(v).max(axis=1, keepdims=True))
        inc = np.abs(res) <= scale
        base = signs(res, 0.0)
        base[inc] = 0
        E = _inv3(A[t])  # columns e_j: A3 e_j = unit_j
        he = np.einsum("d,kdj->kj", _H, E)
        en = np.linalg.norm(E, axis=1)
        simple = (inc.sum(axis=1) == 3) & np.all(np.abs(he) > 1e-9 * en, axis=1)
        vs = np.flatnonzero(simple)
        if len(vs):
            up = np.sign(he[vs]).astype(np.int8)
            tv = t[vs]
            bb = base[vs]
            rows = np.arange(len(vs))
            for j in range(3):
                bb[rows, tv[:, j]] = up[:, j]
            # may the up side of plane j be taken?  (not for simplex planes pointing out)
            up_ok = ~(only_neg[tv] & (up > 0))
            zero_ok = may_zero[tv]
            for bits in range(8):
                zero = [(bits >> j) & 1 for j in range(3)]
                ok = np.ones(len(vs), dtype=bool)
                for j in range(3):
                    ok &= zero_ok[:, j] if zero[j] else up_ok[:, j]
                if not ok.any():
                    continue
                f = bb[ok].copy()
                r = np.arange(len(f))
                for j in range(3):
                    if zero[j]:
                        f[r, tv[ok, j]] = 0
                yield f
        bad = np.flatnonzero(~simple)  # non-simple: full local enumeration (superset)
        seen: set[bytes] = set()
        for kk in bad:
            key = np.round(v[kk] / 1e-7).astype(np.int64).tobytes()
            if key in seen:
                continue
            seen.add(key)
            Z = np.flatnonzero(inc[kk])
            local = central_faces(A[Z])
            f = np.repeat(base[kk][None, :], len(local), axis=0)
            f[:, Z] = local
            yield f


def _inv3(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched inverse of 3 x 3 matrices by cofactors (rows are planes, nonsingular)."""
    a, b, c = M[:, 0], M[:, 1], M[:, 2]
    bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
    det = np.einsum("ki,ki->k", a, bc)
    return np.stack([bc, ca, ab], axis=2) / det[:, None, None]


# outward normals of a regular tetrahedron: the bounding simplex
_SIMPLEX = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
_SIMPLEX /= np.linalg.norm(_SIMPLEX, axis=1, keepdims=True)


def affine_faces(
    A: NDArray[np.float64],
    b: NDArray[np.float64],
    may_zero: NDArray[np.bool_],
    chunk: int = 8192,
) -> Iterator[NDArray[np.int8]]:
    """Candidate faces of the affine arrangement ``{A_k r = b_k}`` in R^3, in chunks.

    ``A`` must hold distinct unit-normal planes (see :func:`dedupe_planes`).
    ``may_zero[k]`` says whether faces lying *in* plane ``k`` are wanted
    (True for tangential planes: rolling; False for normal planes, whose
    boundary belongs to both sides under closed inequalities). Yields sign
    vectors over the planes of ``A``; every face that is wanted appears at
    least once (more than once only at non-simple vertices).
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    may_zero = np.asarray(may_zero, dtype=bool)
    P = len(A)
    # make the arrangement essential: planes through the lineality space
    rank = np.linalg.matrix_rank(A, tol=1e-9) if P else 0
    if rank < 3:
        _, _, Vt = np.linalg.svd(A if P else np.zeros((1, 3)))
        dummies = Vt[rank:]
        A = np.concatenate([A, dummies])
        b = np.concatenate([b, np.zeros(len(dummies))])
        may_zero = np.concatenate([may_zero, np.zeros(len(dummies), dtype=bool)])
    Pe = len(A)
    through0 = np.abs(b) <= _TOL
    Z0 = np.flatnonzero(through0)
    # the origin first, as one (usually non-simple) vertex when it is a vertex at all:
    # small motions from the unloaded state are the usual answer
    origin_is_vertex = len(Z0) >= 3 and np.linalg.matrix_rank(A[Z0], tol=1e-9) == 3
    if origin_is_vertex:
        base = signs(-b)
        local = central_faces(A[Z0])
        f = np.repeat(base[None, :], len(local), axis=0)
        f[:, Z0] = local
        yield f[:, :P]
    # vertices: every independent triple (triples of planes through the origin give the
    # origin, handled above); |det| of unit normals down to 1e-13 still gives a vertex
    tri = _triples(Pe)
    tri = tri[~np.all(through0[tri], axis=1)] if len(tri) else tri
    A3 = A[tri]
    ok = np.abs(np.linalg.det(A3)) > 1e-13 if len(tri) else np.zeros(0, dtype=bool)
    tri = tri[ok]
    V = np.linalg.solve(A3[ok], b[tri][..., None])[..., 0] if len(tri) else np.zeros((0, 3))
    # bounding simplex around every vertex: faces unbounded below get a lowest vertex on it
    R = 1.0 + 2.0 * (float(np.abs(V @ _SIMPLEX.T).max()) if len(V) else 0.0)
    Ab = np.concatenate([A, _SIMPLEX])
    bb = np.concatenate([b, np.full(4, R)])
    mz = np.concatenate([may_zero, np.zeros(4, dtype=bool)])
    on = np.concatenate([np.zeros(Pe, dtype=bool), np.ones(4, dtype=bool)])
    btri = _triples(Pe + 4)
    btri = btri[btri[:, 2] >= Pe]  # at least one simplex plane (sorted triples)
    A3 = Ab[btri]
    ok = np.abs(np.linalg.det(A3)) > 1e-13
    btri = btri[ok]
    BV = np.linalg.solve(A3[ok], bb[btri][..., None])[..., 0]
    inside = np.all(BV @ _SIMPLEX.T - R <= _TOL * (1.0 + R), axis=1)
    allV = np.concatenate([V, BV[inside]])
    allT = np.concatenate([tri, btri[inside]])
    yield from (f[:, :P] for f in _vertex_faces(Ab, bb, mz, on, allT, allV, chunk))
