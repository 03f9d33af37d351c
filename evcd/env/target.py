"""The target EV: where and when it departs, how it is put into SUMO and sent to a station.

The target is an ``ev`` vehicle added through the API (``evcd_target``), held by the charging
controller (:meth:`ChargingController.hold`, plus ``evcd.hold=1``) so it never leaves a charging point
by itself. Sending it to station ``i`` sets its route (the one the observation measured) and a
parking stop at the station's car park (``parking=true``, a duration far beyond the day). It is
re-routed only when the choice changes; choosing another station while it waits in a car park takes
it out of that queue.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sumolib

from evcd.env.observation import RouteObserver
from evcd.scenario.demand import DAY, DemandConfig, InverseCdf
from evcd.scenario.routing import RoadGraph
from evcd.scenario.stations_file import Station
from evcd.scenario.vtypes import EV_TYPE
from evcd.sim.charging import HOLD_PARAM, ChargingController
from evcd.sim.driver import SUMO_ERRORS

log = logging.getLogger(__name__)

TARGET_ID = "evcd_target"
STOP_DURATION_S = 10.0 * DAY
_MIN_ORIGIN_M = 20.0


@dataclass(frozen=True)
class TargetPlan:
    """Where and when the target departs, and its battery.

    Attributes:
        departure: scheduled departure (s of day); ``T_travel`` is measured from it.
        origin: SUMO edge it departs from.
        depart_pos: position on ``origin`` (m).
        capacity_wh: battery capacity (Wh).
        soc: initial state of charge (low: it must charge).
    """

    departure: float
    origin: str
    depart_pos: float
    capacity_wh: float
    soc: float


class OriginSampler:
    """Origins for the target: normal drivable edges (> 20 m) from which every station is reachable,
    drawn in proportion to their length (a uniformly random point of the road network)."""

    def __init__(self, net: sumolib.net.Net, graph: RoadGraph, stations: Sequence[Station]) -> None:
        ok = np.ones(len(graph.edge_ids), dtype=bool)
        for st in stations:
            ok &= np.isfinite(graph.distances_to(st.edge))
        self.edges = [
            e
            for i, e in enumerate(graph.edge_ids)
            if ok[i] and graph.lengths[i] > _MIN_ORIGIN_M and net.getEdge(e).getFunction() == ""
        ]
        if not self.edges:
            raise ValueError("the network has no edge from which every station can be reached")
        self.lengths = np.array([graph.lengths[graph.index[e]] for e in self.edges])
        self._sampler = InverseCdf(self.lengths)

    def draw(self, rng: np.random.Generator) -> tuple[str, float]:
        """An origin edge and a position on it (not within 5 % of its ends)."""
        i = self._sampler.draw(rng)
        length = float(self.lengths[i])
        return self.edges[i], round(float(rng.uniform(0.05, 0.95)) * length, 2)


def draw_plan(
    rng: np.random.Generator,
    origins: OriginSampler,
    window: tuple[float, float],
    step_length: float,
    battery: DemandConfig,
) -> TargetPlan:
    """Draw a target from ``rng`` (in a fixed order: departure, origin, position, battery)."""
    lo, hi = window
    steps = max(1, int((hi - lo) // step_length))
    departure = lo + step_length * int(rng.integers(steps))
    origin, pos = origins.draw(rng)
    capacity = float(rng.uniform(*battery.battery_wh))
    soc = float(rng.uniform(*battery.soc_charging))
    return TargetPlan(float(departure), origin, pos, round(capacity, 1), round(soc, 4))


class Target:
    """The target EV of one episode in a running simulation.

    Args:
        plan: its departure.
        route_id: a SUMO route id not used yet in this simulation (routes outlive loadState).
        vehicle_id: its SUMO id (the single environment's :data:`TARGET_ID`; the batched engine
            gives each co-simulated target its own).
        vtype: its SUMO vehicle type.
        battery: whether it carries a battery the charging controller queues (the single
            environment's target does; the batched engine's do not: it queues them itself).
    """

    def __init__(
        self,
        plan: TargetPlan,
        route_id: str,
        vehicle_id: str = TARGET_ID,
        vtype: str = EV_TYPE,
        battery: bool = True,
    ) -> None:
        self.plan = plan
        self.route_id = route_id
        self.vehicle_id = vehicle_id
        self.vtype = vtype
        self.battery = battery
        self.station: int | None = None  # current choice
        self.switches = 0  # how often the choice changed after the first

    def add(self, api: Any, controller: ChargingController) -> None:
        """Add the target to the simulation, departing at ``plan.departure`` (must not be past)."""
        p, vid = self.plan, self.vehicle_id
        self._add_vehicle(api, [p.origin], depart=f"{p.departure:g}", lane="best", pos=p.depart_pos)
        if not self.battery:
            return
        api.vehicle.setParameter(vid, "device.battery.capacity", f"{p.capacity_wh:.1f}")
        api.vehicle.setParameter(vid, "device.battery.chargeLevel", f"{p.capacity_wh * p.soc:.1f}")
        api.vehicle.setParameter(vid, HOLD_PARAM, "1")
        controller.hold(vid)

    def _add_vehicle(self, api: Any, route: list[str], depart: str, lane: str, pos: float) -> None:
        api.route.add(self.route_id, route)
        api.vehicle.add(
            self.vehicle_id,
            self.route_id,
            typeID=self.vtype,
            depart=depart,
            departLane=lane,
            departPos=f"{pos:.2f}",
            departSpeed="0",
        )

    def switch_to(self, index: int) -> None:
        """Make station ``index`` the choice (a change after the first choice counts as a switch)."""
        if self.station is not None:
            self.switches += 1
        self.station = index

    @staticmethod
    def location(api: Any, vehicle_id: str = TARGET_ID) -> tuple[str, float, float]:
        """Its road (edge id, junction-internal ones start with ``:``), lane position and odometer (m).

        Raises a SUMO error if it is not in the simulation.
        """
        veh = api.vehicle
        return veh.getRoadID(vehicle_id), veh.getLanePosition(vehicle_id), veh.getDistance(vehicle_id)

    def drive_to(
        self,
        api: Any,
        controller: ChargingController,
        index: int,
        station: Station,
        route: tuple[str, ...],
        observer: RouteObserver,
        road: str,
        pos: float,
        time: float,
    ) -> None:
        """Send the target to ``station`` (index ``index``) along ``route`` (from the observation).

        Raises a SUMO error if SUMO refuses every way of stopping there.
        """
        self.switch_to(index)
        vid = self.vehicle_id
        if controller.status(vid) is not None:  # waiting in another car park: leave its queue
            controller.release(api, vid, time)
            controller.hold(vid)
        veh = api.vehicle
        if route and not route[0].startswith(":"):
            veh.setRoute(vid, route)  # drops the stop at the former station
        else:  # on a junction: let SUMO route from the next edge
            veh.changeTarget(vid, station.edge)
        self.stop_at(api, station, observer, road, pos, time)

    def reenter(
        self,
        api: Any,
        index: int,
        station: Station,
        route: tuple[str, ...],
        observer: RouteObserver,
        at: tuple[str, float, int],
        time: float,
        ids: tuple[str, str],
    ) -> None:
        """Leave the car park the target waits at, out of the simulation (the batched engine's
        targets wait beside the queue), for station ``index``: it enters the road again as a new
        vehicle at the car park, on ``route`` (from the observation; SUMO routes it if empty).

        Args:
            at: the car park's ``(edge, lane position, lane index)``.
            ids: the new vehicle's ``(vehicle id, route id)`` (SUMO keeps routes of removed vehicles).

        Raises a SUMO error if SUMO refuses every way of stopping at ``station``.
        """
        road, pos, lane = at
        self.switch_to(index)
        self.vehicle_id, self.route_id = ids
        self._add_vehicle(api, list(route) or [road], depart="now", lane=str(lane), pos=pos)
        if not route:
            api.vehicle.changeTarget(self.vehicle_id, station.edge)
        self.stop_at(api, station, observer, road, pos, time)

    def stop_at(
        self, api: Any, station: Station, observer: RouteObserver, road: str, pos: float, time: float
    ) -> None:
        """Give the target its parking stop at ``station`` (:func:`park_at`)."""
        park_at(api, self.vehicle_id, station, observer, road, pos, time)


def park_at(
    api: Any,
    vehicle: str,
    station: Station,
    observer: RouteObserver,
    road: str,
    pos: float,
    time: float,
    onward: Sequence[str] = (),
) -> None:
    """Give ``vehicle`` (on ``road`` at lane position ``pos``) a parking stop at ``station``, looping
    back if it is past the car park or too close to brake for it.

    Args:
        onward: edges to drive after the station (from the station's edge) when a loop replaces the
            route (the fleet's guided EVs keep their destination); the target has none.

    Raises a SUMO error if SUMO refuses every way of stopping there.
    """
    veh = api.vehicle
    try:
        veh.setParkingAreaStop(vehicle, station.parking_area, duration=STOP_DURATION_S)
    except SUMO_ERRORS as exc:  # past the car park, or too close to brake for it: loop back
        _, loop = observer.loop_route(api, road, pos, station)
        log.debug("t=%s %s cannot stop at %s now (%s); looping via %s", time, vehicle, station.id, exc, loop)
        if not loop:
            raise
        veh.setRoute(vehicle, [*loop, *onward[1:]])
        veh.setParkingAreaStop(vehicle, station.parking_area, duration=STOP_DURATION_S)
