"""The thesis' own slip-state enumeration (sec. enumeration: one LP per step, the dual
polyhedron, a minimum cycle basis), kept as the reference that ``python -m stability.bench
planar`` times beside ours and that the tests hold :func:`~stability.planar.slip_states`
to.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .._lp import INF, solve_lp
from ..grasp import Grasp
from .enumeration import motion_planes

__all__ = ["slip_states_thesis"]


def slip_states_thesis(grasp: Grasp) -> NDArray[np.int8]:
    """The thesis' own slip-state enumeration (sec. enumeration), as a reference.

    Step 1 (Alg. buildset): add the planes ``T_i r = 0`` one at a time and keep
    every region that meets each open half-space, one LP each (HiGHS; regions
    are open cones, so ``s_j T_j r >= 1`` stands for ``> 0``). Step 2: regions
    whose sign vectors differ in one entry share a facet (the dual
    polyhedron's edges). Step 3: the faces of the dual polyhedron, from a
    minimum cycle basis (networkx) plus the symmetric sum of its cycles, are
    the lines. Step 4: the all-rolling state. Returns the distinct states like
    :func:`slip_states`; used by the benchmark (the thesis' algorithm timed on
    the same machine) and by the tests (agreement of independent methods).
    """
    import networkx as nx

    T, _ = motion_planes(grasp)
    m = grasp.m
    regions: list[tuple[int, ...]] = [()]
    for i in range(m):
        grown = []
        for s in regions:
            for side in (1, -1):
                rows = np.array([sj * T[j] for j, sj in enumerate(s)] + [side * T[i]])
                ok, _, _, _ = solve_lp(
                    np.zeros(3), rows, np.ones(len(rows)), np.full(len(rows), INF),
                    np.full(3, -INF), np.full(3, INF),
                )  # fmt: skip
                if ok:
                    grown.append((*s, side))
        regions = grown
    R = np.array(regions, dtype=np.int8)
    graph = nx.Graph()
    graph.add_nodes_from(range(len(R)))
    states = [np.zeros((1, m), dtype=np.int8), R]
    diff = (R[:, None, :] != R[None, :, :]).sum(axis=2)
    for a, b in zip(*np.nonzero(np.triu(diff == 1)), strict=True):
        graph.add_edge(int(a), int(b))
        f = R[a].copy()
        f[R[a] != R[b]] = 0
        states.append(f[None])
    if graph.number_of_edges():
        cycles = [set(c) for c in nx.minimum_cycle_basis(graph)]
        edge_sets = [{e for e in graph.subgraph(c).edges()} for c in cycles]
        last: set = set()
        for es in edge_sets:
            last ^= {tuple(sorted(e)) for e in es}
        faces = [sorted({n for e in es for n in e}) for es in edge_sets]
        if last:
            faces.append(sorted({n for e in last for n in e}))
        for nodes in faces:
            sub = R[nodes]
            f = sub[0].copy()
            f[np.any(sub != sub[0], axis=0)] = 0
            states.append(f[None])
    return np.unique(np.concatenate(states), axis=0)
