"""Shield functions for the islands-and-bridges world (thesis Sec. "Islands and Bridges").

A shield maps the agent's action to a safe one, thesis eq. (shield)::

    a~_t = Psi(a_t, s_t)

where *safe* is a one-step lookahead: the predicted next state ``s_{t+1} = predict(s_t, a)``
must satisfy ``M(s_{t+1}) >= 0``, ``M`` being the signed distance to the edge of the safe
region (positive inside, :func:`envs.geometry.signed_distance`).

Two shields are implemented:

``Psi_simple`` (:func:`simple_shield`)::

    Psi_simple(a, s) = a        if M(predict(s, a)) >= 0
                       [0, 0]   otherwise

``Psi_smart`` (:func:`smart_shield`)::

    Psi_smart(a, s) = argmin_{a~ : M(s + k a~) >= 0, low <= a~ <= high} ||a~ - clip(a)||

for the affine dynamics of the islands world, ``predict(s, a) = s + k clip(a, low, high)``
(``k`` is the env's ``action_scale``, the step length per unit action;
``clip(a) = clip(a, low, high)`` componentwise). The shield answers for the step the env would
take: it first clips the agent's action to the action box, as the env does, and works with
``clip(a)`` from then on. A safe ``clip(a)`` is returned as it is (clipping alone is not an
intervention); otherwise, with the target point ``q = s + k clip(a)`` and the reachable box
``R = [s + k low, s + k high]``, the problem is the Euclidean projection of ``q`` onto
``(union_i P_i) ∩ R`` (``||a~ - clip(a)|| = ||p - q|| / k`` for ``p = s + k a~``), and because
the safe region is a union of convex pieces ``P_i`` (discs and axis-aligned boxes) it splits
into one convex projection per piece::

    p* = argmin_i ||proj_{P_i ∩ R}(q) - q||,      a~ = (p* - s) / k

Each per-piece projection is exact and in closed form (:func:`project_box_box`,
:func:`project_disc_box`), so the smart shield returns the true minimiser, not a sampled
approximation. Pieces are shrunk by a tiny margin (``MARGIN_REL``) so that round-off never puts
the executed next state outside the region (``M >= 0`` holds for the executed action).

Everything here is a plain function of numbers and :mod:`envs.geometry` pieces; the gymnasium
wrappers live in :mod:`shields.wrappers`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from envs.geometry import Box, Disc, Piece, point_depth

__all__ = [
    "MARGIN_REL",
    "project_box_box",
    "project_disc_box",
    "project_piece_box",
    "project_union_box",
    "simple_shield",
    "smart_shield",
]

#: Inward margin of the smart shield, relative to the problem's length scale
#: ``1 + max|s| + k``: pieces are shrunk by this before projecting.
MARGIN_REL = 1e-9

Point = tuple[float, float]


# --------------------------------------------------------------------------- simple shield


def simple_shield(
    state: ArrayLike,
    action: ArrayLike,
    predict: Callable[[NDArray[np.float64], NDArray[np.float64]], ArrayLike],
    safe_distance: Callable[[NDArray[np.float64]], float],
) -> tuple[NDArray[np.float64], bool]:
    """Thesis ``Psi_simple``: keep the action if its predicted next state is safe, else stop.

    ``Psi_simple(a, s) = a if M(predict(s, a)) >= 0 else [0, 0]``.

    Args:
        state: current state ``s`` (2,).
        action: agent action ``a``.
        predict: one-step model ``predict(s, a) -> s_{t+1}``.
        safe_distance: ``M(s)``, ``>= 0`` is safe.

    Returns:
        ``(executed_action, intervened)``: the action itself (float64, same values) when safe,
        the zero action (a zero step) otherwise.

    The action is used as given; :class:`shields.SimpleShield` passes the agent's action
    clipped to the action box, so that the executed action is the step the env takes.
    """
    s = np.asarray(state, dtype=np.float64)
    a = np.array(action, dtype=np.float64)
    if float(safe_distance(np.asarray(predict(s, a), dtype=np.float64))) >= 0.0:
        return a, False
    return np.zeros_like(a), True


# --------------------------------------------------------------------------- projections


def project_box_box(
    lo: ArrayLike, hi: ArrayLike, rlo: ArrayLike, rhi: ArrayLike, q: ArrayLike
) -> NDArray[np.float64] | None:
    """Exact projection of ``q`` onto the box ``[lo, hi] ∩ [rlo, rhi]`` (itself a box, so
    the projection is a clip). Returns ``None`` if the intersection is empty."""
    lo2 = np.maximum(np.asarray(lo, dtype=float), rlo)
    hi2 = np.minimum(np.asarray(hi, dtype=float), rhi)
    if np.any(lo2 > hi2):
        return None
    return np.clip(np.asarray(q, dtype=float), lo2, hi2)


def project_disc_box(
    center: ArrayLike, radius: float, lo: ArrayLike, hi: ArrayLike, q: ArrayLike
) -> NDArray[np.float64] | None:
    """Exact Euclidean projection of ``q`` onto ``D ∩ B`` (disc ``|p - c| <= r``, box
    ``lo <= p <= hi``). Returns ``None`` if the intersection is empty.

    ``D ∩ B`` is convex, so the minimiser ``p*`` is characterised by its active constraints
    (KKT): no constraint active -> ``p* = q``; only the circle -> ``p* = proj_D(q)`` (then it
    lies in ``B``); only box sides -> ``p* = proj_B(q)`` (then it lies in ``D``); the circle and
    at least one side -> ``p*`` is an intersection of the circle with a side line. The function
    tries these closed-form candidates in that order and keeps the nearest feasible one.
    """
    c = np.asarray(center, dtype=float)
    lo_, hi_ = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    qq = np.asarray(q, dtype=float)
    if np.any(lo_ > hi_):
        return None
    p = _proj_disc_box(
        float(c[0]), float(c[1]), float(radius), float(lo_[0]), float(lo_[1]),
        float(hi_[0]), float(hi_[1]), float(qq[0]), float(qq[1]),
    )  # fmt: skip
    return None if p is None else np.array(p)


def _proj_disc_box(
    cx: float, cy: float, r: float, lx: float, ly: float, hx: float, hy: float, qx: float, qy: float
) -> Point | None:
    """Float-only core of :func:`project_disc_box` (fast: no small numpy arrays)."""
    if r < 0.0 or lx > hx or ly > hy:
        return None
    # empty iff the box point nearest to the centre is outside the disc
    nx, ny = min(max(cx, lx), hx), min(max(cy, ly), hy)
    if (nx - cx) ** 2 + (ny - cy) ** 2 > r * r:
        return None
    # 1. q itself; 2. projection onto the disc (feasible -> optimal, D ⊇ D ∩ B)
    dx, dy = qx - cx, qy - cy
    d = math.hypot(dx, dy)
    if d <= r:
        px, py = qx, qy
    else:
        px, py = cx + dx * (r / d), cy + dy * (r / d)
    if lx <= px <= hx and ly <= py <= hy:
        return px, py
    # 3. projection onto the box (feasible -> optimal)
    bx, by = min(max(qx, lx), hx), min(max(qy, ly), hy)
    if (bx - cx) ** 2 + (by - cy) ** 2 <= r * r:
        return bx, by
    # 4. circle ∩ side lines (circle active together with >= 1 side)
    tol = 1e-12 * (1.0 + r + abs(cx) + abs(cy))
    best: Point | None = None
    best_d2 = math.inf
    for x_side in (lx, hx):
        h2 = r * r - (x_side - cx) ** 2
        if h2 < -tol * r:
            continue
        h = math.sqrt(max(h2, 0.0))
        for y in (cy - h, cy + h):
            if ly - tol <= y <= hy + tol:
                y = min(max(y, ly), hy)
                d2 = (x_side - qx) ** 2 + (y - qy) ** 2
                if d2 < best_d2:
                    best, best_d2 = (x_side, y), d2
    for y_side in (ly, hy):
        h2 = r * r - (y_side - cy) ** 2
        if h2 < -tol * r:
            continue
        h = math.sqrt(max(h2, 0.0))
        for x in (cx - h, cx + h):
            if lx - tol <= x <= hx + tol:
                x = min(max(x, lx), hx)
                d2 = (x - qx) ** 2 + (y_side - qy) ** 2
                if d2 < best_d2:
                    best, best_d2 = (x, y_side), d2
    return best


def _proj_piece_box(
    piece: Piece,
    margin: float,
    rlx: float,
    rly: float,
    rhx: float,
    rhy: float,
    qx: float,
    qy: float,
) -> Point | None:
    """Projection of ``q`` onto ``shrink(piece, margin) ∩ [rl, rh]`` (floats), or ``None``."""
    if isinstance(piece, Disc):
        r = piece.radius - margin
        if r < 0.0:
            return None
        cx, cy = piece.center
        return _proj_disc_box(float(cx), float(cy), r, rlx, rly, rhx, rhy, qx, qy)
    if isinstance(piece, Box):
        lx, ly = max(piece.lo[0] + margin, rlx), max(piece.lo[1] + margin, rly)
        hx, hy = min(piece.hi[0] - margin, rhx), min(piece.hi[1] - margin, rhy)
        if lx > hx or ly > hy:
            return None
        return min(max(qx, lx), hx), min(max(qy, ly), hy)
    raise TypeError(f"unsupported piece {type(piece).__name__}; expected Disc or Box")


def project_piece_box(
    piece: Piece, lo: ArrayLike, hi: ArrayLike, q: ArrayLike, margin: float = 0.0
) -> NDArray[np.float64] | None:
    """Exact projection of ``q`` onto ``piece ∩ [lo, hi]`` with the piece shrunk inward by
    ``margin`` (disc radius ``r - margin``, box sides moved in by ``margin``); ``None`` if empty.
    """
    lo_, hi_, qq = (np.asarray(v, dtype=float) for v in (lo, hi, q))
    p = _proj_piece_box(
        piece, margin, float(lo_[0]), float(lo_[1]), float(hi_[0]), float(hi_[1]),
        float(qq[0]), float(qq[1]),
    )  # fmt: skip
    return None if p is None else np.array(p)


def _dist2_lower_bound(piece: Piece, qx: float, qy: float) -> float:
    """Squared distance from ``q`` to the (unshrunk) piece: a lower bound for the piece ∩ box."""
    if isinstance(piece, Disc):
        d = math.hypot(qx - piece.center[0], qy - piece.center[1]) - piece.radius
        return d * d if d > 0.0 else 0.0
    ex = max(piece.lo[0] - qx, 0.0, qx - piece.hi[0])
    ey = max(piece.lo[1] - qy, 0.0, qy - piece.hi[1])
    return ex * ex + ey * ey


def _project_union(
    pieces: Sequence[Piece], margin: float, rl: Point, rh: Point, qx: float, qy: float
) -> tuple[Point, Piece] | None:
    order = sorted(range(len(pieces)), key=lambda i: _dist2_lower_bound(pieces[i], qx, qy))
    best: tuple[Point, Piece] | None = None
    best_d2 = math.inf
    for i in order:
        if _dist2_lower_bound(pieces[i], qx, qy) >= best_d2:
            break  # sorted lower bounds: no later piece can do better
        p = _proj_piece_box(pieces[i], margin, rl[0], rl[1], rh[0], rh[1], qx, qy)
        if p is not None:
            d2 = (p[0] - qx) ** 2 + (p[1] - qy) ** 2
            if d2 < best_d2:
                best, best_d2 = (p, pieces[i]), d2
    return best


def project_union_box(
    pieces: Sequence[Piece], lo: ArrayLike, hi: ArrayLike, q: ArrayLike, margin: float = 0.0
) -> NDArray[np.float64] | None:
    """Exact projection of ``q`` onto ``(union of pieces) ∩ [lo, hi]``: the nearest of the
    per-piece projections (:func:`project_piece_box`). ``None`` if the set is empty."""
    lo_, hi_, qq = (np.asarray(v, dtype=float) for v in (lo, hi, q))
    res = _project_union(
        pieces, margin, (float(lo_[0]), float(lo_[1])), (float(hi_[0]), float(hi_[1])),
        float(qq[0]), float(qq[1]),
    )  # fmt: skip
    return None if res is None else np.array(res[0])


# --------------------------------------------------------------------------- smart shield


def _is_safe(pieces: Sequence[Piece], x: float, y: float) -> bool:
    """``M((x, y)) >= 0``: bit for bit the env's termination rule (``signed_distance`` of one
    point is the largest :func:`envs.geometry.point_depth`), stopping at the first piece that
    holds the point."""
    return any(point_depth(piece, x, y) >= 0.0 for piece in pieces)


def _bounds2(v: ArrayLike) -> Point:
    b = np.asarray(v, dtype=float)
    if b.shape != (2,):  # a scalar bound for both components
        b = np.broadcast_to(b, (2,))
    return float(b[0]), float(b[1])


def smart_shield(
    state: ArrayLike,
    action: ArrayLike,
    pieces: Sequence[Piece],
    scale: float,
    low: ArrayLike = -1.0,
    high: ArrayLike = 1.0,
) -> tuple[NDArray[np.float64], bool]:
    """Thesis ``Psi_smart``: the safe action nearest to the (clipped) agent action (exact).

    ``Psi_smart(a, s) = argmin ||a~ - clip(a)||  s.t.  M(s + k a~) >= 0,  low <= a~ <= high``,

    for the affine model ``predict(s, a) = s + k clip(a, low, high)`` and the safe region
    ``union(pieces)`` (``M`` = :func:`envs.geometry.signed_distance`). The shield answers for
    the step the env would take, so ``a`` is first clipped componentwise to ``[low, high]`` and
    everything below uses ``c = clip(a, low, high)``. If ``c`` is safe (``M(s + k c) >= 0``) it
    is returned as it is (float64) with ``intervened=False``: clipping alone is not an
    intervention. Otherwise the target ``q = s + k c`` is projected exactly onto
    ``union_i (shrink(P_i) ∩ [s + k low, s + k high])`` (one closed-form convex projection per
    piece, pieces shrunk by ``MARGIN_REL * (1 + max|s| + k)``) and ``a~ = (p* - s) / k``.

    Args:
        state: current state ``s`` (2,).
        action: agent action ``a`` (2,), possibly outside ``[low, high]``.
        pieces: convex pieces (``Disc``/``Box``) whose union is the safe region.
        scale: ``k > 0``, step length per unit action.
        low, high: action bounds (scalars or (2,)).

    Returns:
        ``(executed_action, intervened)``: ``clip(a)`` or its nearest safe action, both inside
        ``[low, high]``; ``intervened`` is ``True`` only when safety changed the in-box action
        ``clip(a)``. If no safe action exists (no piece meets the reachable box, e.g. ``s`` is
        far outside the region), the zero action with ``intervened=True``.
    """
    s = np.asarray(state, dtype=np.float64)
    a = np.array(action, dtype=np.float64)
    if s.shape != (2,) or a.shape != (2,):
        raise ValueError(f"smart_shield is 2D: state {s.shape}, action {a.shape}")
    k = float(scale)
    if not k > 0.0:
        raise ValueError(f"scale must be > 0, got {scale}")
    lo, hi = _bounds2(low), _bounds2(high)
    sx, sy = float(s[0]), float(s[1])
    length = 1.0 + max(abs(sx), abs(sy)) + k
    # 0. clip to the action box, as the env does: from here on only clip(a) counts
    cx = min(max(float(a[0]), lo[0]), hi[0])
    cy = min(max(float(a[1]), lo[1]), hi[1])
    # 1. already safe? (same arithmetic as the env: s + k * clip(a)); not an intervention
    if _is_safe(pieces, sx + k * cx, sy + k * cy):
        return np.array([cx, cy]), False
    # 2. project the target of the clipped action onto the safe pieces ∩ the reachable box
    rl = (sx + k * lo[0], sy + k * lo[1])
    rh = (sx + k * hi[0], sy + k * hi[1])
    qx, qy = sx + k * cx, sy + k * cy
    for margin_rel in (MARGIN_REL, 1e3 * MARGIN_REL):
        res = _project_union(pieces, margin_rel * length, rl, rh, qx, qy)
        if res is None:
            break
        (px, py), piece = res
        ex = min(max((px - sx) / k, lo[0]), hi[0])
        ey = min(max((py - sy) / k, lo[1]), hi[1])
        # exact check in the chosen piece (union depth >= piece depth)
        if point_depth(piece, sx + k * ex, sy + k * ey) >= 0.0:
            return np.array([ex, ey]), True
    return np.zeros(2), True
