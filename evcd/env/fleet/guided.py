"""One guided EV of a fleet episode: its life (waiting to depart, deciding, done) and how the centre
sends it to a station.

A guided EV is an ordinary vehicle of the background day (:mod:`evcd.env.fleet.trips`): it charges
at the station's FIFO points like any other EV (:class:`~evcd.sim.charging.ChargingController`),
behind background EVs and other guided ones, and after charging drives on to its own destination.
Sending it elsewhere changes its next parking stop and its route (:meth:`GuidedEV.send`); a choice
equal to the current one changes nothing in SUMO, so an EV always sent to its own station drives
exactly as in the plain background day.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import libsumo

from evcd.env.episode_rules import Motion, final_info, visits_of
from evcd.env.fleet.trips import ChargingTrip
from evcd.env.observation import Observation, RouteObserver
from evcd.env.target import park_at
from evcd.scenario.stations_file import Station
from evcd.sim.charge_record import ChargeRecord
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SUMO_ERRORS
from evcd.sim.stops import next_stop_on_route

log = logging.getLogger(__name__)


class Stage(enum.Enum):
    """Where a guided EV is in its episode."""

    PENDING = "pending"  # not inserted by SUMO yet
    INSERTED = "inserted"  # on the road, waiting for its first decision tick
    ACTIVE = "active"  # an agent: observes and decides at every tick
    DONE = "done"  # charging, truncated, or never inserted


@dataclass
class GuidedEV:
    """The bookkeeping of one guided EV.

    Attributes:
        trip: the day's trip (id, scheduled departure, the station it plans).
        station: its current station (index); the trip's own until the centre sends it elsewhere.
        stage: see :class:`Stage`.
        inserted: when SUMO inserted it (s of day).
        destination: the last edge of its trip (kept when it is sent elsewhere).
        origin: the edge it departed from.
        switches: how often its station changed.
        decisions: ticks at which it decided.
        slot_start: start of its current slot (s of day).
        road: its edge at the last tick ...
        pos: ... and lane position.
        motion: when it last moved (the episode rules' stuck test).
        obs: its latest observation (``None`` before its first tick).
        reason: why it is done (:data:`~evcd.env.episode_rules.REASONS`).
        charge_start: when it got a charging point (s of day).
        end: when it was done (s of day).
    """

    trip: ChargingTrip
    station: int
    stage: Stage = Stage.PENDING
    inserted: float | None = None
    destination: str = ""
    origin: str = ""
    switches: int = 0
    decisions: int = 0
    slot_start: float = 0.0
    road: str = ""
    pos: float = 0.0
    motion: Motion | None = None
    obs: Observation | None = None
    reason: str | None = None
    charge_start: float | None = None
    end: float | None = None

    @property
    def vehicle(self) -> str:
        """Its SUMO id (also its agent name)."""
        return self.trip.vehicle

    @property
    def travel_time(self) -> float | None:
        """Scheduled departure to charge start (s), ``None`` unless it started charging."""
        return None if self.charge_start is None else self.charge_start - self.trip.depart

    def on_insert(self, api: Any, now: float) -> None:
        """Note SUMO's insertion: its time, origin and destination."""
        self.stage, self.inserted = Stage.INSERTED, now
        route = api.vehicle.getRoute(self.vehicle)
        self.origin, self.destination = route[0], route[-1]

    def finish(self, reason: str, now: float) -> None:
        """It is done (charging or truncated) at ``now``."""
        self.stage, self.reason, self.end = Stage.DONE, reason, now

    def info(
        self, now: float | None, day: int | None, records: Sequence[ChargeRecord], stations: Sequence[Station]
    ) -> dict[str, Any]:
        """Its ``info``: ``time``, ``station`` (current), ``own_station`` (its trip's), ``departure`` and
        ``day``; once done, the episode rules' final keys (:func:`~evcd.env.episode_rules.final_info`,
        its visits read from the controller's ``records``)."""
        info: dict[str, Any] = {"time": now, "station": self.station, "own_station": self.trip.station,
                                "departure": self.trip.depart, "day": day}  # fmt: skip
        if self.stage is Stage.DONE and self.reason is not None and self.end is not None:
            info |= final_info(
                reason=self.reason, now=self.end, departure=self.trip.depart, origin=self.origin,
                travel=self.travel_time, visits=visits_of(records, self.vehicle, self.end), day=day,
                switches=self.switches, station=self.station, stations=stations,
            )  # fmt: skip
        return info

    def send(
        self,
        api: Any,
        controller: ChargingController,
        index: int,
        station: Station,
        observer: RouteObserver,
        time: float,
    ) -> None:
        """Send it to station ``index`` from where it was at the last tick (``road``, ``pos``, and the
        route its observation measured), keeping its destination after the station.

        A waiting EV leaves the queue it is in. A driving EV gets its next parking stop replaced
        (SUMO re-routes it through the new car park to its destination); if SUMO refuses, the route
        of the observation plus the way on to the destination, with a loop if it is too close to
        brake.

        Raises a SUMO error if SUMO refuses every way of stopping there.
        """
        if self.station != index:
            self.switches += 1
        self.station = index
        vid, veh = self.vehicle, api.vehicle
        route = self.obs.routes[index] if self.obs is not None else ()
        on_junction = not route or route[0].startswith(":")
        # on a junction: the edge it is leaving and the rest of its route, read before SUMO changes it
        before = veh.getRoute(vid)[veh.getRouteIndex(vid) :] if on_junction else ()
        if controller.status(vid) is not None:  # waiting in another car park: leave its queue
            controller.release(api, vid, time)
        else:
            try:
                veh.rerouteParkingArea(vid, station.parking_area)
                if _stops_on_its_route(veh, vid, station.parking_area):
                    return
                log.debug(
                    "t=%s %s: rerouteParkingArea to %s left the stop off the route", time, vid, station.id
                )
            except SUMO_ERRORS as exc:
                log.debug("t=%s %s: rerouteParkingArea to %s refused (%s)", time, vid, station.id, exc)
        onward = _find(api, station.edge, self.destination)
        if on_junction:  # through the edge it is entering
            route = _through_junction(api, before, station.edge)
        veh.setRoute(vid, [*route, *onward[1:]] if onward else list(route))
        park_at(api, vid, station, observer, self.road, self.pos, time, onward)


def _stops_on_its_route(veh: Any, vid: str, parking_area: str) -> bool:
    """Whether ``vid``'s next stop is at ``parking_area`` AND its route still passes that stop's edge.

    ``rerouteParkingArea`` on a junction (an internal edge) replaces the stop but may keep the old
    route, which then never reaches the new car park: SUMO drops the stop and the EV drives on to
    its destination without charging (it vanished, uncharged, in 1-3 % of the rules' guided EVs at
    600 EVs before this check)."""
    stop, on_route = next_stop_on_route(veh, vid)
    return stop is not None and stop.stoppingPlaceID == parking_area and on_route


def _through_junction(api: Any, route: Sequence[str], dst: str) -> tuple[str, ...]:
    """For a vehicle on a junction, whose ``route`` (from its current route index on) starts with the
    edge it is leaving and goes on with the one it is entering: those two, then the way to ``dst``.
    (SUMO's own re-routing from inside a junction, ``changeTarget`` or ``rerouteTraveltime``, crashed
    libsumo 1.28 there when the vehicle had a stop off its route.)

    Raises:
        TraCIException: no way from the entered edge to ``dst``.
    """
    if len(route) < 2:  # on its last junction: nothing left to enter
        raise libsumo.TraCIException(f"no edge after the junction towards {dst}")
    way = _find(api, route[1], dst)
    if not way:
        raise libsumo.TraCIException(f"no route from {route[1]} to {dst}")
    return (route[0], *way)


def _find(api: Any, src: str, dst: str) -> tuple[str, ...]:
    """The router's edges from ``src`` to ``dst`` (empty if none)."""
    if not dst or src == dst:
        return (src,) if dst else ()
    try:
        return tuple(api.simulation.findRoute(src, dst, vType="ev").edges)
    except SUMO_ERRORS:
        return ()
