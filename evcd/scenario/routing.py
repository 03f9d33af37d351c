"""Shortest road distances on a SUMO network, without starting a simulation.

Distances follow lane connections (``edge.getOutgoing()``), so they match what a vehicle can drive.
The distance from edge ``a`` to edge ``b`` is measured from the start of ``a`` to the start of ``b``:
the lengths of ``a`` and of every edge driven before ``b``.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import sumolib

PASSENGER = "passenger"


@dataclass
class RoadGraph:
    """A compact directed graph of a network's drivable (passenger) edges.

    Attributes:
        edge_ids: SUMO ids, index ``i`` is node ``i`` of the graph.
        lengths: edge lengths (m).
        succ: successor indices of each edge.
        pred: predecessor indices of each edge.
    """

    edge_ids: list[str]
    lengths: np.ndarray
    succ: list[list[int]]
    pred: list[list[int]]
    index: dict[str, int] = field(init=False)

    def __post_init__(self) -> None:
        self.index = {e: i for i, e in enumerate(self.edge_ids)}

    @classmethod
    def from_net(cls, net: sumolib.net.Net, vclass: str = PASSENGER) -> RoadGraph:
        """Build the graph of the edges of ``net`` that ``vclass`` may use."""
        edges = [e for e in net.getEdges(withInternal=False) if e.allows(vclass)]
        ids = sorted(e.getID() for e in edges)
        index = {e: i for i, e in enumerate(ids)}
        by_id = {e.getID(): e for e in edges}
        succ: list[list[int]] = [[] for _ in ids]
        pred: list[list[int]] = [[] for _ in ids]
        for i, eid in enumerate(ids):
            outs = sorted({index[o.getID()] for o in by_id[eid].getOutgoing() if o.getID() in index})
            succ[i] = outs
            for j in outs:
                pred[j].append(i)
        lengths = np.array([by_id[e].getLength() for e in ids], dtype=np.float64)
        return cls(ids, lengths, succ, pred)

    def __contains__(self, edge_id: str) -> bool:
        return edge_id in self.index

    def _dijkstra(self, start: int, reverse: bool) -> np.ndarray:
        dist = np.full(len(self.edge_ids), np.inf)
        dist[start] = 0.0
        heap = [(0.0, start)]
        nbrs = self.pred if reverse else self.succ
        lengths = self.lengths
        while heap:
            d, u = heapq.heappop(heap)
            if d > dist[u]:
                continue
            for v in nbrs[u]:
                # forward: leaving u costs len(u); reverse: reaching u from v costs len(v)
                nd = d + (lengths[v] if reverse else lengths[u])
                if nd < dist[v]:
                    dist[v] = nd
                    heapq.heappush(heap, (nd, v))
        return dist

    def distances_from(self, edge_id: str) -> np.ndarray:
        """Road distance (m) from the start of ``edge_id`` to the start of every edge."""
        return self._dijkstra(self._idx(edge_id), reverse=False)

    def distances_to(self, edge_id: str) -> np.ndarray:
        """Road distance (m) from the start of every edge to the start of ``edge_id``."""
        return self._dijkstra(self._idx(edge_id), reverse=True)

    def _idx(self, edge_id: str) -> int:
        try:
            return self.index[edge_id]
        except KeyError:
            raise ValueError(f"edge {edge_id!r} is not a drivable edge of this network") from None


def distance_matrix(
    graph: RoadGraph, edges: Iterable[str], offsets: Iterable[float] | None = None
) -> np.ndarray:
    """Pairwise road distances between points on ``edges``.

    ``offsets`` (m along each edge, default 0) turn edge-start distances into point distances:
    from point ``a`` to point ``b`` is ``d(edge_a, edge_b) - off_a + off_b`` (for ``a == b`` it is 0).
    """
    edges = list(edges)
    off = np.zeros(len(edges)) if offsets is None else np.asarray(list(offsets), dtype=float)
    idx = [graph.index[e] for e in edges]
    out = np.zeros((len(edges), len(edges)))
    for i, e in enumerate(edges):
        d = graph.distances_from(e)
        for j in range(len(edges)):
            if i != j:
                out[i, j] = d[idx[j]] - off[i] + off[j]
    return out
