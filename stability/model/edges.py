"""Friction edges of the hierarchical refinement (thesis ch. 6, eqs. l1, length): one
contact's ordered, cyclic list of edge directions in its tangent plane and the level each
was made for, halved where an answer needs it (:mod:`stability.refinement`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["TWO_PI", "EdgeSet", "edge_length"]

TWO_PI = 2.0 * math.pi


def edge_length(p: int, gamma: float, q: int) -> float:
    """``l_p = prod_{r=p}^{q+1} sec(gamma / 2^r)`` (thesis eqs. l1, length)."""
    return math.prod(1.0 / math.cos(gamma / 2.0**r) for r in range(p, q + 2))


@dataclass
class EdgeSet:
    """One contact's friction edges: angles ``theta`` [rad, in ``[0, 2 pi)``] in cyclic
    order and the level ``p`` each was made for (its length is ``l_p``)."""

    theta: list[float]
    level: list[int]
    gamma: float
    q: int
    lengths: dict[int, float] = field(default_factory=dict)

    @classmethod
    def uniform(cls, k: int, level: int, gamma: float, q: int) -> EdgeSet:
        th = [TWO_PI * j / k for j in range(k)]
        return cls(th, [level] * k, gamma, q)

    def __len__(self) -> int:
        return len(self.theta)

    def length(self, s: int) -> float:
        p = self.level[s]
        if p not in self.lengths:
            self.lengths[p] = edge_length(p, self.gamma, self.q)
        return self.lengths[p]

    def width(self, j: int) -> float:
        """Angle of sector ``j`` (edges ``j`` and ``j + 1``, cyclic) [rad]; 0 if degenerate."""
        k = len(self.theta)
        if k == 1:
            return TWO_PI
        w = (self.theta[(j + 1) % k] - self.theta[j]) % TWO_PI
        return 0.0 if w < 1e-12 else w

    def finest_width(self) -> float:
        return self.gamma / 2.0**self.q

    def sectors_at(self, phi: float, tol: float = 1e-9) -> list[int]:
        """The non-degenerate sectors whose closed arc contains direction ``phi``."""
        out = []
        for j in range(len(self.theta)):
            w = self.width(j)
            if w == 0.0:
                continue
            off = (phi - self.theta[j]) % TWO_PI
            if off <= w + tol or off >= TWO_PI - tol:
                out.append(j)
        return out

    def refine_at(self, phi: float, depth: int) -> int:
        """Halve the sectors about direction ``phi`` [rad] ``depth`` times over (down to the
        finest width); the number of sectors halved."""
        n = 0
        for _ in range(depth):
            fine = self.finest_width() * (1 + 1e-9)
            todo = [j for j in self.sectors_at(phi) if self.width(j) > fine]
            if not todo:
                break
            for th in sorted({self.theta[j] for j in todo}):
                j = next(j for j in range(len(self)) if self.theta[j] == th and self.width(j) > 0)
                n += int(self.refine(j))
        return n

    def refine(self, j: int) -> bool:
        """Halve sector ``j``: edges of level ``p + 1`` along its edges and bisector; then
        drop redundant edges. False if the sector is already at the finest width."""
        w = self.width(j)
        if w <= self.finest_width() * (1 + 1e-9):
            return False
        k = len(self.theta)
        a, b = self.theta[j], self.theta[(j + 1) % k]
        p = self.level[j] + 1
        new = [(a, p), ((a + w / 2.0) % TWO_PI, p), (b, p)]
        edges = list(zip(self.theta, self.level, strict=True))
        edges[j + 1 : j + 1] = new
        self.theta, self.level = (list(x) for x in zip(*_dedupe(edges), strict=True))
        return True


def _dedupe(edges: list[tuple[float, int]]) -> list[tuple[float, int]]:
    """Collapse each cyclic run of edges along one direction to its first and last (one if
    they have the same level): the two sectors it separates need only their own edges."""
    n = len(edges)

    def same(i: int, j: int) -> bool:
        d = abs(edges[i % n][0] - edges[j % n][0]) % TWO_PI
        return min(d, TWO_PI - d) < 1e-12

    # rotate so that the list starts at the beginning of a run
    start = next((i for i in range(n) if not same(i - 1, i)), 0)
    edges = edges[start:] + edges[:start]
    out: list[tuple[float, int]] = []
    i = 0
    while i < n:
        j = i
        while j + 1 < n and same(j, j + 1):
            j += 1
        first, last = edges[i], edges[j]
        out.append(first)
        if j > i and last[1] != first[1]:
            out.append(last)
        i = j + 1
    return out
