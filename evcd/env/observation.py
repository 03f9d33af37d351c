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
Where the roads never change (``static_routes``: no road events in the world's days), a route is
found once per (edge, destination) and kept: SUMO's ``findRoute`` plans with the edges' fixed
weights (length over speed limit; the background vehicles' routing devices do not change them), so
it gives the same route every time, and the observations are the same with and without keeping.

Observation options (``EnvConfig.observe``, off by default: what a navigation service knows) add
blocks after these, in this order:

- ``P[i]`` (``points_in_service``): station ``i``'s charging points in service now (its points
  less those of its charger outages in force, :mod:`evcd.sim.outages`).
- ``T[i]`` (``route_time``): the route's current estimated travel time (s): each of its edges' length
  over the mean speed of the vehicles on it in the last step (``edge.getLastStepMeanSpeed``: its
  current limit when empty, so that an incident, rain or road works show), that speed floored at
  :data:`FLOOR_SHARE` of the limit (one car waiting at a light is not a road at a standstill; SUMO's
  own ``edge.getTraveltime`` divides by the bare mean and gave 42,000 s for a 140 m edge holding a
  car just inserted), the target's own edge at its limit (its own speed is not the road's), the
  first and last edges counted for the part of them driven. 0 where the target waits;
  :data:`UNREACHABLE_S` without a route.
- ``F[i]`` (``forecast``): the forecast number of vehicles at station ``i`` (charging and waiting)
  when the target would get there, now plus ``T[i]`` (at most :data:`FORECAST_HORIZON_S` ahead),
  from the environment's forecaster (:mod:`evcd.forecast`, :mod:`evcd.env.forecast_source`).
- ``G[i]`` (``guided_ahead``, the fleet's only, :mod:`evcd.env.fleet`): the *other* guided EVs driving
  to station ``i`` whose estimated time to it (their ``T`` of the station they are sent to) is shorter
  than this EV's ``T[i]``: the part of the fleet's ``H[i]`` due there before it. The observer computes
  ``T`` for it (kept in :attr:`Observation.extra`); the fleet, which knows where it sent every EV,
  adds the block.

A *layout* names the blocks of a vector in order, one letter each: ``"DNZ"`` (this environment),
``"DNZH"`` (the fleet's, :mod:`evcd.env.fleet`), then the options' letters (e.g. ``"DNZP"``,
``"DNZHPT"``); :func:`check_layout` says which are valid.

With normalisation, ``D`` is in km, ``N`` in tens of vehicles, ``Z`` (and ``H``, ``P``, ``G``) in multiples of
the station's charging points (``Z``, ``F``: 1 = all points busy, above 1 = a queue; ``P``: 1 = all in
service) and ``T`` in minutes.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evcd.scenario.routing import RoadGraph
from evcd.scenario.stations_file import Station
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SUMO_ERRORS

log = logging.getLogger(__name__)

#: ``D`` of a station the router finds no route to (m); also the upper bound of ``D``.
UNREACHABLE_M = 1.0e6
#: ``T`` of a station the router finds no route to (s); also the upper bound of ``T``.
UNREACHABLE_S = 1.0e6
#: Upper bound of ``N`` in the observation space.
MAX_VEHICLES = 1.0e6
D_SCALE_M = 1000.0
N_SCALE = 10.0
T_SCALE_S = 60.0
#: ``T``'s floor of an edge's speed, as a share of its current limit.
FLOOR_SHARE = 0.1
#: The base layouts: the single environment's and the fleet's.
BASE_LAYOUTS = ("DNZ", "DNZH")
#: Observation options (``EnvConfig.observe``) and their blocks, in the order the blocks follow the base.
OPTIONS: dict[str, str] = {"points_in_service": "P", "route_time": "T", "forecast": "F", "guided_ahead": "G"}
#: The options only the fleet has (its blocks need the other guided EVs; the fleet adds them).
FLEET_OPTIONS = ("guided_ahead",)
#: Latest arrival a forecast is asked for, after now (s): beyond an episode's longest trip.
FORECAST_HORIZON_S = 7200.0


def check_layout(layout: str | int) -> str:
    """``layout`` as block letters: a base layout (``"DNZ"``, ``"DNZH"``; or 3 and 4, their block
    counts) followed by any of the options' blocks, each once, in :data:`OPTIONS`' order.

    Raises:
        ValueError: anything else (the message names the allowed forms).
    """
    if isinstance(layout, bool):
        layout = str(layout)
    if isinstance(layout, (int, np.integer)) and int(layout) in (3, 4):
        return BASE_LAYOUTS[int(layout) - 3]
    text = str(layout)
    base = "DNZH" if text.startswith("DNZH") else "DNZ"
    rest = text[len(base) :]
    order = "".join(OPTIONS.values())
    if not text.startswith("DNZ") or rest != "".join(c for c in order if c in rest):
        raise ValueError(
            f"layout {layout!r}: must be 3 / 'DNZ' or 4 / 'DNZH', followed by any of {', '.join(order)} in "
            f"that order (e.g. 'DNZP', 'DNZHPT')"
        )
    fleet_only = [OPTIONS[o] for o in FLEET_OPTIONS if OPTIONS[o] in rest]
    if base == "DNZ" and fleet_only:
        raise ValueError(
            f"layout {layout!r}: block {fleet_only[0]} ({', '.join(FLEET_OPTIONS)}) counts the fleet's other "
            "guided EVs: it follows the fleet's 'DNZH' only (evcd.env.fleet); the single target has none"
        )
    return text


def routes_start(routes: Sequence[tuple[str, ...]]) -> str | None:
    """The edge the routes start on (the target's), ``None`` if none has edges."""
    return next((r[0] for r in routes if r), None)


def layout_of(base: str, observe: Sequence[str] = ()) -> str:
    """The layout of ``base`` (``"DNZ"`` or ``"DNZH"``) with the observation options ``observe``."""
    return check_layout(base + "".join(OPTIONS[o] for o in OPTIONS if o in observe))


@dataclass(frozen=True)
class Observation:
    """One observation, raw (``D`` in m, counts) and as the float32 vector the agent sees."""

    distance: np.ndarray  # D, float64 (m)
    vehicles: np.ndarray  # N, int
    occupancy: np.ndarray  # Z, int
    routes: tuple[tuple[str, ...], ...]  # the route to each station, starting with the current edge
    vector: np.ndarray  # float32 in the observer's layout, normalised if asked
    #: the options' blocks, raw, by letter (and ``T`` wherever the observer computed it)
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)


def unit_divisors(points: Sequence[int] | np.ndarray, layout: str | int = "DNZ") -> np.ndarray:
    """What normalisation divides a vector of ``layout`` by (float64, one value per entry):
    :data:`D_SCALE_M` (m -> km), :data:`N_SCALE` (tens of vehicles), each station's charging points
    (``Z``, ``H``, ``P``: multiples of them) and :data:`T_SCALE_S` (s -> min). The one definition of the
    scaled units: the environments' normalisation and the agents' reading of observations both use it.
    Read-only: computed once per points and layout (every observation a rule reads divides by it)."""
    pts = np.asarray(points, dtype=np.float64)
    return _unit_divisors(tuple(pts.ravel().tolist()), layout)


@functools.lru_cache(maxsize=64)
def _unit_divisors(points: tuple[float, ...], layout: str | int) -> np.ndarray:
    letters = check_layout(layout)
    pts = np.asarray(points, dtype=np.float64)
    m = pts.size
    per = {"D": np.full(m, D_SCALE_M), "N": np.full(m, N_SCALE), "T": np.full(m, T_SCALE_S)}
    out = np.concatenate([per.get(c, pts) for c in letters])
    out.flags.writeable = False
    return out


def block_vector(
    blocks: Mapping[str, np.ndarray], layout: str, stations: Sequence[Station], normalize: bool
) -> np.ndarray:
    """The float32 vector of ``blocks`` (letter -> values per station) in ``layout``'s order,
    normalised (:func:`unit_divisors`) or raw."""
    raw = np.concatenate([np.asarray(blocks[c], dtype=np.float64) for c in layout])
    if normalize:
        raw = raw / unit_divisors([st.points for st in stations], layout)
    return raw.astype(np.float32)


def to_physical(
    obs: np.ndarray, points: Sequence[int] | np.ndarray, normalized: bool, layout: str | int = "DNZ"
) -> np.ndarray:
    """Observation vectors of ``layout`` (one or a batch) in metres, vehicles and seconds (float64),
    whether the environment normalised them (``normalized``) or not."""
    x = np.asarray(obs).astype(np.float64)
    return x * unit_divisors(points, layout) if normalized else x


def observation_bounds(
    stations: Sequence[Station], normalize: bool, layout: str = "DNZ"
) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest possible vectors of ``layout`` (``Z`` is bounded by the car parks' capacity,
    ``P`` by the points)."""
    m = len(stations)
    high = {
        "D": np.full(m, UNREACHABLE_M), "N": np.full(m, MAX_VEHICLES), "H": np.full(m, MAX_VEHICLES),
        "Z": np.array([st.lot_capacity for st in stations], dtype=np.float64),
        "P": np.array([st.points for st in stations], dtype=np.float64), "T": np.full(m, UNREACHABLE_S),
        "F": np.full(m, MAX_VEHICLES), "G": np.full(m, MAX_VEHICLES),
    }  # fmt: skip
    layout = check_layout(layout)
    return np.zeros(len(layout) * m, dtype=np.float32), block_vector(high, layout, stations, normalize)


class RouteObserver:
    """Computes :class:`Observation`\\ s for one scenario.

    Args:
        stations: the scenario's stations, in action order.
        graph: the network's drivable edges (lengths and successors).
        vtype: vehicle type the router plans for (the target's).
        normalize: scale the vector (see the module docstring).
        observe: the observation options (:data:`OPTIONS`: ``points_in_service``, ``route_time``,
            ``forecast``; with the fleet's ``guided_ahead`` it makes no block but computes ``T``).
        forecast: with ``forecast``, ``forecast(now, arrival, controller)`` -> the forecast vehicles
            at each station at its ``arrival`` time (a :class:`~evcd.env.forecast_source.ForecastSource`).
        static_routes: the router's edge weights and the lanes' permissions never change (no road
            events): keep each route found (module docstring). Code that changes them through the API
            (``lane.setMaxSpeed``, ``edge.adaptTraveltime``, ...) must call :meth:`clear_routes`.
    """

    def __init__(
        self,
        stations: Sequence[Station],
        graph: RoadGraph,
        vtype: str = "ev",
        normalize: bool = False,
        observe: Sequence[str] = (),
        forecast: Callable[[float, np.ndarray, ChargingController], np.ndarray] | None = None,
        static_routes: bool = False,
    ) -> None:
        self.stations = tuple(stations)
        self.graph = graph
        self.vtype = vtype
        self.normalize = normalize
        unknown = sorted(set(observe) - set(OPTIONS))
        if unknown:
            raise ValueError(
                f"observe={list(observe)}: unknown option {unknown[0]!r}; the options: {', '.join(OPTIONS)}"
            )
        #: the blocks this observer makes (the fleet's options' blocks are the fleet's to add)
        self.layout = layout_of("DNZ", [o for o in observe if o not in FLEET_OPTIONS])
        #: ``T`` is computed (for ``T``, ``F`` or the fleet's ``G``) and kept in the observations' extra
        self.times = "T" in self.layout or "F" in self.layout or "guided_ahead" in observe
        if "F" in self.layout and forecast is None:
            raise ValueError("observe=[forecast] needs a forecaster (ChargingNavEnv's forecaster=...)")
        self.forecast = forecast
        self._edge_len = {st.edge: float(graph.lengths[graph.index[st.edge]]) for st in self.stations}
        self.static_routes = static_routes
        self._found: dict[tuple[str, str], tuple[float, tuple[str, ...]]] = {}

    @property
    def size(self) -> int:
        """Length of the observation vector (blocks of the layout x stations)."""
        return len(self.layout) * len(self.stations)

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
        extra: dict[str, np.ndarray] = {}
        if "P" in self.layout:
            now = api.simulation.getTime()
            extra["P"] = np.array([controller.points_in_service(st.id, now) for st in self.stations])
        if self.times:
            times = self._route_times(api, routes, dist, pos)
            extra["T"] = times
            if "F" in self.layout:
                assert self.forecast is not None
                now = api.simulation.getTime()
                extra["F"] = self.forecast(now, now + np.minimum(times, FORECAST_HORIZON_S), controller)
        blocks = {"D": dist, "N": vehicles, "Z": occupancy, **extra}
        vector = block_vector(blocks, self.layout, self.stations, self.normalize)
        return Observation(dist, vehicles, occupancy, tuple(routes), vector, extra)

    def _route_times(
        self, api: Any, routes: Sequence[tuple[str, ...]], dist: np.ndarray, pos: float
    ) -> np.ndarray:
        """``T``: SUMO's current travel time of each route's edges, the first and last edges for the
        part of them driven (module docstring)."""
        tt = {}
        for e in {e for r in routes for e in r}:
            limit = float(api.lane.getMaxSpeed(f"{e}_0"))
            mean = limit if e == routes_start(routes) else float(api.edge.getLastStepMeanSpeed(e))
            tt[e] = self._length(e) / max(mean, FLOOR_SHARE * limit)
        out = np.zeros(len(routes))
        for i, (route, st) in enumerate(zip(routes, self.stations, strict=True)):
            if not route:
                out[i] = UNREACHABLE_S if dist[i] >= UNREACHABLE_M else 0.0
                continue
            share = np.ones(len(route))
            first, last = self._length(route[0]), self._length(route[-1])
            share[0] = max(0.0, first - pos) / first
            if len(route) == 1:
                share[0] = max(0.0, st.end_pos - pos) / first
            else:
                share[-1] = st.end_pos / last
            out[i] = sum(tt[e] * f for e, f in zip(route, share, strict=True))
        return out

    def _length(self, edge: str) -> float:
        """An edge's length (1 for one the graph does not hold)."""
        idx = self.graph.index.get(edge)
        return float(self.graph.lengths[idx]) if idx is not None else 1.0

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

    def clear_routes(self) -> None:
        """Forget the routes kept (``static_routes``): after a change of edge weights or permissions."""
        self._found.clear()

    def _find(self, api: Any, src: str, dst: str) -> tuple[float, tuple[str, ...]]:
        if self.static_routes:
            found = self._found.get((src, dst))
            if found is None:
                found = self._found[src, dst] = self._router(api, src, dst)
            return found
        return self._router(api, src, dst)

    def _router(self, api: Any, src: str, dst: str) -> tuple[float, tuple[str, ...]]:
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
