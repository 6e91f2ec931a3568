"""Convex pieces of a 2D safe region: discs and axis-aligned boxes.

The safe region of the islands-and-bridges world is a union of convex pieces.
Each piece knows its signed distance (positive inside, thesis' ``M``) and its
Euclidean projection. Units: whatever length unit the map uses (the default
map is in metres of an abstract plane).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Box", "Disc", "Piece", "point_depth", "point_signed_distance", "signed_distance"]


@dataclass(frozen=True)
class Disc:
    """Closed disc ``|p - center| <= radius``."""

    center: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        if not (np.all(np.isfinite(self.center)) and np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"Disc needs a finite center and radius > 0, got {self}")

    def signed_distance(self, p: ArrayLike) -> NDArray[np.float64]:
        """``radius - |p - center|`` for points ``p`` (..., 2): > 0 inside, < 0 outside."""
        d = np.asarray(p, dtype=float) - np.asarray(self.center)
        return self.radius - np.linalg.norm(d, axis=-1)

    def project(self, p: ArrayLike) -> NDArray[np.float64]:
        """Closest point of the disc to ``p`` (2,)."""
        p = np.asarray(p, dtype=float)
        c = np.asarray(self.center, dtype=float)
        d = p - c
        n = float(np.linalg.norm(d))
        return p.copy() if n <= self.radius else c + d * (self.radius / n)

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounding box ``(lo, hi)``."""
        c = np.asarray(self.center, dtype=float)
        return c - self.radius, c + self.radius


@dataclass(frozen=True)
class Box:
    """Closed axis-aligned box ``lo <= p <= hi`` (componentwise)."""

    lo: tuple[float, float]
    hi: tuple[float, float]

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lo, dtype=float), np.asarray(self.hi, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(np.isfinite([lo, hi])):
            raise ValueError(f"Box needs finite 2D corners, got {self}")
        if np.any(hi <= lo):
            raise ValueError(f"Box needs lo < hi componentwise, got {self}")

    def signed_distance(self, p: ArrayLike) -> NDArray[np.float64]:
        """Signed distance to the boundary (..., ): > 0 inside (distance to the nearest
        side), < 0 outside (Euclidean distance to the box)."""
        p = np.asarray(p, dtype=float)
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        inside = np.minimum(p - lo, hi - p).min(axis=-1)
        outside = np.linalg.norm(np.maximum(0.0, np.maximum(lo - p, p - hi)), axis=-1)
        return np.where(inside >= 0, inside, -outside)

    def project(self, p: ArrayLike) -> NDArray[np.float64]:
        """Closest point of the box to ``p`` (2,)."""
        return np.clip(np.asarray(p, dtype=float), self.lo, self.hi)

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounding box ``(lo, hi)``."""
        return np.asarray(self.lo, dtype=float), np.asarray(self.hi, dtype=float)


Piece = Disc | Box


def signed_distance(pieces: Sequence[Piece], p: ArrayLike) -> NDArray[np.float64]:
    """Signed distance of ``p`` (..., 2) to the edge of the union of ``pieces``.

    Outside the union this is exact (minus the distance to the nearest piece).
    Inside it is the largest per-piece depth, a lower bound of the distance to
    the union's edge that is exact away from the overlaps of pieces; its sign
    is exact everywhere, which is what the shields and the termination rule use
    (thesis: ``M(s) >= 0`` is safe).

    A single point ``(2,)`` takes a float path (one env step calls this once or twice) that
    computes bit for bit what the array path does: ``sqrt(dx*dx + dy*dy)`` is how
    ``np.linalg.norm`` reduces two components.
    """
    q = np.asarray(p, dtype=float)
    if q.shape == (2,):
        return np.float64(point_signed_distance(pieces, float(q[0]), float(q[1])))
    return np.max([piece.signed_distance(q) for piece in pieces], axis=0)


def point_signed_distance(pieces: Sequence[Piece], x: float, y: float) -> float:
    """:func:`signed_distance` of the one point ``(x, y)``, in floats (the largest
    :func:`point_depth`): the same value to the last bit, no arrays (env steps call it)."""
    best = -math.inf
    for piece in pieces:  # a plain loop: measurably faster than max() over a generator here
        d = point_depth(piece, x, y)
        if d > best:
            best = d
    return best


def point_depth(piece: Piece, x: float, y: float) -> float:
    """``piece.signed_distance((x, y))`` in floats, the same operations in the same order, so
    the same value to the last bit (the shields' safety checks rely on that)."""
    if isinstance(piece, Disc):
        dx, dy = x - float(piece.center[0]), y - float(piece.center[1])
        return float(piece.radius) - math.sqrt(dx * dx + dy * dy)
    lx, ly, hx, hy = float(piece.lo[0]), float(piece.lo[1]), float(piece.hi[0]), float(piece.hi[1])
    inside = min(min(x - lx, hx - x), min(y - ly, hy - y))
    if inside >= 0:
        return inside
    ex = max(0.0, max(lx - x, x - hx))
    ey = max(0.0, max(ly - y, y - hy))
    return -math.sqrt(ex * ex + ey * ey)
