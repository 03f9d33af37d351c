"""Place charging stations on any SUMO network with a minimum road distance between them.

The placement is a greedy p-median: stations are added one at a time, each at the candidate edge
that most reduces the mean road distance from every drivable edge to its nearest station, among the
candidates at least ``min_spacing`` metres (by road, both directions) from every station placed so
far. Optional *anchors* (e.g. a real public charger given by longitude/latitude) are placed first.
This spreads stations over the town the way an operator would, rather than pushing them to its
edges as a pure max-min spacing would.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import sumolib

from evcd.scenario.routing import RoadGraph, distance_matrix
from evcd.scenario.stations_file import DEFAULT_LOT_CAPACITY, DEFAULT_POINTS, DEFAULT_POWER_W, Station

log = logging.getLogger(__name__)

#: Car-park frontage along the lane (m); candidate edges must be longer than this plus margins.
LOT_LENGTH = 20.0
#: Do not put a car park on roads faster than this (m/s): no chargers on expressways or ramps.
MAX_SPEED = 60 / 3.6 + 0.1


@dataclass(frozen=True)
class Anchor:
    """A station that must sit near a real location."""

    name: str
    lon: float
    lat: float


def candidate_edges(net: sumolib.net.Net, graph: RoadGraph, min_length: float = 2 * LOT_LENGTH) -> list[str]:
    """Edges that can host a car park: drivable, not internal, slow enough and long enough."""
    out = []
    for eid in graph.edge_ids:
        e = net.getEdge(eid)
        if e.getLength() >= min_length and e.getSpeed() <= MAX_SPEED and e.getFunction() == "":
            out.append(eid)
    return out


def _station_on(
    net: sumolib.net.Net, edge_id: str, sid: str, name: str, points: int, power_w: float
) -> Station:
    edge = net.getEdge(edge_id)
    mid = edge.getLength() / 2
    return Station(
        id=sid,
        name=name,
        lane=edge.getLanes()[0].getID(),
        start_pos=round(mid - LOT_LENGTH / 2, 2),
        end_pos=round(mid + LOT_LENGTH / 2, 2),
        power_w=power_w,
        points=points,
        lot_capacity=DEFAULT_LOT_CAPACITY,
    )


def nearest_edge(net: sumolib.net.Net, candidates: Sequence[str], lon: float, lat: float) -> str:
    """The candidate edge closest (straight line) to a longitude/latitude."""
    try:
        x, y = net.convertLonLat2XY(lon, lat)
    except Exception as exc:  # sumolib raises plain exceptions when the net has no projection
        raise ValueError(f"cannot place an anchor at {lon},{lat}: no geo-reference ({exc!r})") from exc
    best, best_d = None, np.inf
    for eid in candidates:
        shape = np.asarray(net.getEdge(eid).getShape())
        d = float(np.min(np.hypot(shape[:, 0] - x, shape[:, 1] - y)))
        if d < best_d:
            best, best_d = eid, d
    if best is None:
        raise ValueError("no candidate edge to place a station on")
    log.info("anchor (%.5f, %.5f) -> edge %s (%.0f m away)", lon, lat, best, best_d)
    return best


def place_stations(
    net: sumolib.net.Net,
    k: int,
    min_spacing: float,
    rng: np.random.Generator,
    anchors: Sequence[Anchor] = (),
    points: int = DEFAULT_POINTS,
    power_w: float = DEFAULT_POWER_W,
    max_candidates: int = 300,
) -> list[Station]:
    """Place ``k`` stations with pairwise road distance >= ``min_spacing`` (m) in both directions.

    Args:
        net: the network (sumolib).
        k: number of stations (>= 1).
        min_spacing: minimum road distance between any two stations (m, >= 0).
        rng: random generator (samples the candidate set on large networks).
        anchors: real locations placed first, in order (at most ``k``).
        points: charging points per station.
        power_w: power per point (W).
        max_candidates: candidate edges considered (sampled when there are more).

    Raises:
        ValueError: bad arguments, or the spacing cannot be met on this network.
    """
    if k < 1:
        raise ValueError(f"k={k}: need at least one station")
    if min_spacing < 0:
        raise ValueError(f"min_spacing={min_spacing}: must be >= 0 m")
    if len(anchors) > k:
        raise ValueError(f"{len(anchors)} anchors for k={k} stations")
    graph = RoadGraph.from_net(net)
    cands = candidate_edges(net, graph)
    if not cands:
        raise ValueError("no edge of the network can host a station (all too short or too fast)")
    anchor_edges = [nearest_edge(net, cands, a.lon, a.lat) for a in anchors]
    pool = sorted(set(cands) - set(anchor_edges))
    if len(pool) > max_candidates:
        pool = sorted(rng.choice(pool, size=max_candidates, replace=False).tolist())
    pool = anchor_edges + pool
    # to[c, e]: distance from edge e to candidate c; frm[c, e]: from candidate c to edge e.
    to = np.stack([graph.distances_to(c) for c in pool])
    frm = np.stack([graph.distances_from(c) for c in pool])
    col = np.array([graph.index[c] for c in pool])
    # symmetric spacing between the car-park midpoints: the shorter of the two driving directions
    mid = graph.lengths[col] / 2
    ab = frm[:, col] - mid[:, None] + mid[None, :]
    pair = np.minimum(ab, ab.T)
    nearest = np.full(len(graph.edge_ids), np.inf)
    chosen: list[int] = []
    for i in range(k):
        allowed = np.ones(len(pool), dtype=bool)
        for c in chosen:
            allowed &= pair[c] >= min_spacing
        allowed[chosen] = False
        if i < len(anchor_edges):
            best = i
            if not allowed[best]:
                raise ValueError(f"anchor {anchors[i].name!r} is closer than min_spacing={min_spacing} m")
        else:
            if not allowed.any():
                raise ValueError(
                    f"cannot place k={k} stations with min_spacing={min_spacing} m: only {len(chosen)} fit "
                    f"(largest spacing between the placed ones: {_min_pair(pair, chosen):.0f} m)"
                )
            # mean distance from every edge to its nearest station if candidate c were added
            cost = np.where(allowed, np.minimum(nearest[None, :], to).mean(axis=1), np.inf)
            best = int(np.argmin(cost))
        chosen.append(best)
        nearest = np.minimum(nearest, to[best])
    stations = []
    for i, c in enumerate(chosen):
        street = net.getEdge(pool[c]).getName()
        name = anchors[i].name if i < len(anchors) else (street or f"Station {i}")
        stations.append(_station_on(net, pool[c], f"cs{i}", name, points, power_w))
    log.info("placed %d stations, min pairwise road distance %.0f m", k, _min_pair(pair, chosen))
    return stations


def station_distances(graph: RoadGraph, stations: Sequence[Station]) -> np.ndarray:
    """Road distance (m) between the car-park midpoints of every pair of stations (row -> column)."""
    return distance_matrix(graph, [s.edge for s in stations], [s.mid_pos for s in stations])


def _min_pair(pair: np.ndarray, chosen: list[int]) -> float:
    vals = [pair[a, b] for a in chosen for b in chosen if a != b]
    return float(min(vals)) if vals else float("inf")
