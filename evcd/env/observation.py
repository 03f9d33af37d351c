"""The navigation centre's view: distance, road load and station load per station.

For each station ``i`` (in the scenario's order), from the target's current position:

- ``D[i]``: driving distance (m) along the route SUMO's router finds (``simulation.findRoute`` from
  the target's current edge, junction-internal edges included) to the end of the station's car park
  (the position SUMO's parking stop aims at). On the station's own edge before the car park it is
  the distance along the edge; past it, the loop through the best successor edge. 0 for the
  station whose car park the target is in.
- ``N[i]``: vehicles currently on that route's edges (``edge.getLastStepVehicleNumber``), not
  counting the target. Vehicles parked off-road in car parks are not on an edge.
- ``Z[i]``: vehicles at station ``i``, charging + waiting (:meth:`ChargingController.occupancy`;
  the target counts once it has joined the queue).

Cost per observation: one ``findRoute`` per station (a few more in the rare loop case) and one
``getLastStepVehicleNumber`` per distinct edge of the union of the routes; no per-vehicle calls.

With normalisation, ``D`` is in km, ``N`` in tens of vehicles and ``Z`` in multiples of the
station's charging points (1 = all points busy, above 1 = a queue).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evcd.scenario.routing import RoadGraph
from evcd.scenario.stations_file import Station
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SUMO_ERRORS

log = logging.getLogger(__name__)

#: ``D`` of a station the router finds no route to (m); also the upper bound of ``D``.
UNREACHABLE_M = 1.0e6
#: Upper bound of ``N`` in the observation space.
MAX_VEHICLES = 1.0e6
D_SCALE_M = 1000.0
N_SCALE = 10.0


@dataclass(frozen=True)
class Observation:
    """One observation, raw (``D`` in m, counts) and as the float32 vector the agent sees."""

    distance: np.ndarray  # D, float64 (m)
    vehicles: np.ndarray  # N, int
    occupancy: np.ndarray  # Z, int
    routes: tuple[tuple[str, ...], ...]  # the route to each station, starting with the current edge
    vector: np.ndarray  # float32 [D, N, Z], normalised if asked


def unit_divisors(points: Sequence[int] | np.ndarray, blocks: int = 3) -> np.ndarray:
    """What normalisation divides ``[D, N, Z]`` by (float64, length ``3m``): :data:`D_SCALE_M` (m -> km),
    :data:`N_SCALE` (tens of vehicles) and each station's charging points (``Z`` in multiples of them).
    With ``blocks=4``, the fleet's ``[D, N, Z, H]`` (:mod:`evcd.env.fleet`): ``H`` in multiples of the
    points too. The one definition of the scaled units: the environments' normalisation and the
    agents' reading of observations both use it."""
    if blocks not in (3, 4):
        raise ValueError(f"blocks={blocks!r}: must be 3 ([D, N, Z]) or 4 ([D, N, Z, H])")
    pts = np.asarray(points, dtype=np.float64)
    m = pts.size
    return np.concatenate([np.full(m, D_SCALE_M), np.full(m, N_SCALE), *([pts] * (blocks - 2))])


def to_vector(
    dist: np.ndarray,
    vehicles: np.ndarray,
    occupancy: np.ndarray,
    stations: Sequence[Station],
    normalize: bool,
) -> np.ndarray:
    """The float32 vector ``[D, N, Z]``, normalised (:func:`unit_divisors`) or raw."""
    raw = np.concatenate([dist, vehicles, occupancy]).astype(np.float64)
    if normalize:
        raw = raw / unit_divisors([st.points for st in stations])
    return raw.astype(np.float32)


def to_physical(
    obs: np.ndarray, points: Sequence[int] | np.ndarray, normalized: bool, blocks: int = 3
) -> np.ndarray:
    """Observation vectors (one ``(blocks * m,)`` or a batch) in metres and vehicles (float64),
    whether the environment normalised them (``normalized``) or not; ``blocks=4`` for the fleet's."""
    x = np.asarray(obs).astype(np.float64)
    return x * unit_divisors(points, blocks) if normalized else x


def observation_bounds(stations: Sequence[Station], normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest possible vectors (``Z`` is bounded by the car parks' capacity)."""
    m = len(stations)
    lots = np.array([st.lot_capacity for st in stations], dtype=np.float64)
    high = to_vector(np.full(m, UNREACHABLE_M), np.full(m, MAX_VEHICLES), lots, stations, normalize)
    return np.zeros(3 * m, dtype=np.float32), high


class RouteObserver:
    """Computes :class:`Observation`\\ s for one scenario.

    Args:
        stations: the scenario's stations, in action order.
        graph: the network's drivable edges (lengths and successors).
        vtype: vehicle type the router plans for (the target's).
        normalize: scale the vector (see the module docstring).
    """

    def __init__(
        self, stations: Sequence[Station], graph: RoadGraph, vtype: str = "ev", normalize: bool = False
    ) -> None:
        self.stations = tuple(stations)
        self.graph = graph
        self.vtype = vtype
        self.normalize = normalize
        self._edge_len = {st.edge: float(graph.lengths[graph.index[st.edge]]) for st in self.stations}

    @property
    def size(self) -> int:
        """Length of the observation vector (3 x stations)."""
        return 3 * len(self.stations)

    def observe(
        self,
        api: Any,
        controller: ChargingController,
        road: str,
        pos: float,
        at_station: int | None = None,
        *,
        others: Mapping[str, int] | None = None,
        queued_at: int | None = None,
    ) -> Observation:
        """Observe from a target on ``road`` at lane position ``pos``.

        Args:
            api: the running simulation's API.
            controller: the stations' queues.
            road: the target's edge.
            pos: its lane position.
            at_station: index of the station whose car park the target is in (waiting), if any.
            others: vehicles per edge not to count in ``N`` (the batched engine's other targets).
            queued_at: a station whose ``Z`` counts the target although the controller does not
                queue it (the batched engine's targets wait beside the queues, see
                :mod:`evcd.env.runners.ghost`).
        """
        m = len(self.stations)
        dist = np.empty(m)
        routes: list[tuple[str, ...]] = []
        for i, st in enumerate(self.stations):
            if i == at_station:
                d, edges = 0.0, ()
            else:
                d, edges = self._route(api, road, pos, st)
            dist[i] = d
            routes.append(edges)
        counts = self._edge_counts(api, {e for r in routes for e in r})
        if others:
            for e in counts.keys() & others.keys():
                counts[e] -= others[e]
        vehicles = np.array([sum(counts[e] for e in r) for r in routes], dtype=np.int64)
        if at_station is None:  # the target itself drives on its road, which starts every route
            vehicles -= np.array([1 if r and road in r and counts[road] > 0 else 0 for r in routes])
        occupancy = np.array(controller.occupancies(), dtype=np.int64)
        if queued_at is not None:
            occupancy[queued_at] += 1
        return Observation(dist, vehicles, occupancy, tuple(routes), self.vector(dist, vehicles, occupancy))

    def vector(self, dist: np.ndarray, vehicles: np.ndarray, occupancy: np.ndarray) -> np.ndarray:
        """The float32 vector ``[D, N, Z]`` (normalised if the observer normalises)."""
        return to_vector(dist, vehicles, occupancy, self.stations, self.normalize)

    # ------------------------------------------------------------------ routing
    def _route(self, api: Any, road: str, pos: float, st: Station) -> tuple[float, tuple[str, ...]]:
        """Distance and edges from ``(road, pos)`` to the end of ``st``'s car park."""
        tail = self._edge_len[st.edge] - st.end_pos  # the part of the last edge not driven
        if road == st.edge:
            if pos <= st.end_pos:
                return st.end_pos - pos, (road,)
            return self._loop(api, road, pos, st)
        length, edges = self._find(api, road, st.edge)
        if not edges:
            return UNREACHABLE_M, ()
        return length - pos - tail, edges

    def loop_route(self, api: Any, road: str, pos: float, st: Station) -> tuple[float, tuple[str, ...]]:
        """Route back to ``st`` for a vehicle on ``st``'s edge past its car park (or too close to
        stop): leave the edge, then the shortest way back, through the best successor edge."""
        return self._loop(api, road, pos, st)

    def _loop(self, api: Any, road: str, pos: float, st: Station) -> tuple[float, tuple[str, ...]]:
        tail = self._edge_len[st.edge] - st.end_pos
        best: tuple[float, tuple[str, ...]] = (UNREACHABLE_M, ())
        idx = self.graph.index.get(road)
        succ = [] if idx is None else [self.graph.edge_ids[j] for j in self.graph.succ[idx]]
        for nxt in succ:
            hop, hop_edges = self._find(api, road, nxt)  # road + junction + next edge
            back, back_edges = self._find(api, nxt, st.edge)
            if not hop_edges or not back_edges:
                continue
            nxt_len = float(self.graph.lengths[self.graph.index[nxt]])
            d = hop - pos + back - nxt_len - tail
            if d < best[0]:
                best = (d, (road, *back_edges))
        return best

    def _find(self, api: Any, src: str, dst: str) -> tuple[float, tuple[str, ...]]:
        try:
            stage = api.simulation.findRoute(src, dst, vType=self.vtype)
        except SUMO_ERRORS as exc:
            log.debug("no route %s -> %s: %s", src, dst, exc)
            return UNREACHABLE_M, ()
        return float(stage.length), tuple(stage.edges)

    @staticmethod
    def _edge_counts(api: Any, edges: set[str]) -> dict[str, int]:
        count = api.edge.getLastStepVehicleNumber
        return {e: count(e) for e in edges}
