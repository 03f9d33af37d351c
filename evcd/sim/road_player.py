"""Plays a day's :class:`~evcd.sim.road_events.RoadEvents` into a running SUMO.

    player = RoadPlayer(events, driver.api)     # right after the driver starts: reads the originals
    player.sync(driver.api, driver.time)        # after a state load: everything as it is at that time
    driver.add_listener(player)                 # then it follows the clock

What is played (all through TraCI, so that the day's build and every episode of it play the same):
lane speed limits (``lane.setMaxSpeed``: rain, road works, the crawl past an incident), closed
lanes (``lane.setDisallowed``), vehicle types' headways (``vehicletype.setTau``: rain), and the
incidents' expected crossing times for the router (``edge.adaptTraveltime`` over the incident's
interval). At an incident's start and every ``reroute_every`` seconds while it lasts, every
background vehicle whose remaining route crosses an incident edge is rerouted on those times
(``vehicle.rerouteTraveltime``): it takes another way when that is quicker than the crawl, and keeps
its stops (a charging EV still goes to its station). Vehicles in a junction wait for the next round
(rerouting from a junction is what SUMO handles worst), a vehicle whose next stop is off its route
is left alone (libsumo 1.28 crashes rerouting it), and evcd's own targets (ids starting with
``evcd_``) are routed by the environment, whose router sees the same crossing times.

:meth:`RoadPlayer.sync` sets every element the day touches to its value at the given time, whatever
the loaded state holds, so a snapshot saved during rain or an incident loads into the same
situation as in the build. A player belongs to one SUMO run (one day): it reads the original values
when made, before anything is changed.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from evcd.sim.driver import SUMO_ERRORS
from evcd.sim.road_events import Incident, RoadEvents
from evcd.sim.stops import next_stop_on_route

log = logging.getLogger(__name__)

#: Vehicles with ids starting with this are the environment's own (targets): not rerouted here.
OWN_PREFIX = "evcd_"


class RoadPlayer:
    """A driver listener that keeps SUMO's roads as a day's events say (module docstring).

    Args:
        events: the day's road events.
        api: the freshly started simulation's API (the original limits are read from it).
        reroute_every: seconds between reroute rounds while an incident lasts.
    """

    def __init__(self, events: RoadEvents, api: Any, reroute_every: float = 60.0) -> None:
        self.events = events
        self.reroute_every = float(reroute_every)
        edges = {e.edge for e in (*events.incidents, *events.roadworks)}
        lanes = list(api.lane.getIDList()) if events.rain else [
            f"{edge}_{i}" for edge in sorted(edges) for i in range(api.edge.getLaneNumber(edge))
        ]  # fmt: skip
        self._speed0 = {lane: api.lane.getMaxSpeed(lane) for lane in lanes}
        closable = [f"{e.edge}_{i}" for e in (*events.incidents, *events.roadworks) for i in e.lanes]
        self._allowed0 = {lane: tuple(api.lane.getAllowed(lane)) for lane in sorted(set(closable))}
        #: each vehicle type's own headway (its tau without rain), the types of the fresh simulation
        #: read now, the later ones when first seen (:meth:`_headways`)
        self._tau0: dict[str, float] = {}
        self._factor = 1.0  # the headway factor last applied
        if events.rain:
            self._tau0 = {t: api.vehicletype.getTau(t) for t in api.vehicletype.getIDList()}
        self._changes = events.change_times()
        self._next = 0  # index of the next change time
        self._active: tuple[tuple[int, ...], tuple[int, ...]] | None = None
        self.reroutes = 0  # vehicles rerouted (for tests and logs)
        self.skipped = 0  # vehicles left alone: their next stop is off their route (evcd.sim.stops)

    # ------------------------------------------------------------------ what holds when
    def active(self, now: float) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Indices of the incidents and rain spells in force at ``now``."""
        inc = tuple(i for i, e in enumerate(self.events.incidents) if e.start <= now < e.end)
        rain = tuple(i for i, r in enumerate(self.events.rain) if r.start <= now < r.end)
        return inc, rain

    def _targets(
        self, active: tuple[tuple[int, ...], tuple[int, ...]]
    ) -> tuple[dict[str, float], set[str], float]:
        """Lane speed limits, closed lanes and the headway factor that ``active`` means."""
        inc = [self.events.incidents[i] for i in active[0]]
        rain = [self.events.rain[i] for i in active[1]]
        factor = rain[0].speed_factor if rain else 1.0
        speeds = {lane: v * factor for lane, v in self._speed0.items()}
        closed: set[str] = set()
        for e in (*self.events.roadworks, *inc):
            cap = e.speed if not isinstance(e, Incident) else e.pass_speed
            for lane in self._speed0:
                if lane.rpartition("_")[0] == e.edge:
                    speeds[lane] = min(speeds[lane], cap)
            closed.update(f"{e.edge}_{i}" for i in e.lanes)
        return speeds, closed, rain[0].headway_factor if rain else 1.0

    # ------------------------------------------------------------------ applying
    def sync(self, api: Any, now: float) -> None:
        """Set every element the day touches to its value at ``now`` (after a start or a state load)."""
        for e in self.events.incidents:
            length = api.lane.getLength(f"{e.edge}_0")
            api.edge.adaptTraveltime(e.edge, length / e.pass_speed, e.start, e.end)
        self._next = next((k for k, t in enumerate(self._changes) if t > now), len(self._changes))
        self._apply(api, self.active(now), force=True)

    def __call__(self, api: Any, now: float) -> None:
        """After every step: apply what starts or ends now; reroute while an incident lasts."""
        if self._next < len(self._changes) and now >= self._changes[self._next]:
            while self._next < len(self._changes) and now >= self._changes[self._next]:
                self._next += 1
            before = self._active
            self._apply(api, self.active(now), force=False)
            if before is not None and set(self._active[0]) - set(before[0]):
                self._reroute(api)
                return
        if self._active and self._active[0] and math.isclose(now % self.reroute_every, 0.0, abs_tol=1e-6):
            self._reroute(api)

    def _apply(self, api: Any, active: tuple[tuple[int, ...], tuple[int, ...]], force: bool) -> None:
        speeds, closed, headway = self._targets(active)
        old = None if force or self._active is None else self._targets(self._active)
        for lane, v in speeds.items():
            if old is None or old[0][lane] != v:
                api.lane.setMaxSpeed(lane, v)
        for lane, allowed in self._allowed0.items():
            if old is None or (lane in closed) != (lane in old[1]):
                if lane in closed:
                    api.lane.setDisallowed(lane, ["all"])
                else:
                    api.lane.setAllowed(lane, list(allowed))
        if self.events.rain and (old is None or old[2] != headway):
            self._headways(api, headway, loaded=force)
        self._active = active

    def _headways(self, api: Any, factor: float, loaded: bool) -> None:
        """Every vehicle type there now at its own headway times ``factor``. A type first seen now got
        its headway under the factor in force when it was made: the last one applied, or, after a
        state load (``loaded``), the one of the state's time (a saved state keeps the types' headways
        then), i.e. ``factor`` itself; its own is that divided out. A type recorded earlier but
        gone (a loaded state without it) is skipped."""
        made_under = factor if loaded else self._factor
        for vtype in api.vehicletype.getIDList():
            if vtype not in self._tau0:
                self._tau0[vtype] = api.vehicletype.getTau(vtype) / made_under
            api.vehicletype.setTau(vtype, self._tau0[vtype] * factor)
        self._factor = factor

    def _reroute(self, api: Any) -> None:
        """Reroute every background vehicle whose remaining route crosses an incident in force."""
        assert self._active is not None
        blocked = {self.events.incidents[i].edge for i in self._active[0]}
        veh = api.vehicle
        for vid in veh.getIDList():
            if vid.startswith(OWN_PREFIX) or veh.getRoadID(vid).startswith(":"):
                continue
            route = veh.getRoute(vid)
            ahead = route[veh.getRouteIndex(vid) :]
            if blocked.isdisjoint(ahead[1:]):
                continue
            stop, on_route = next_stop_on_route(veh, vid)
            if stop is not None and not on_route:
                self.skipped += 1
                log.debug("not rerouting %s: its next stop is off its route", vid)
                continue
            try:
                veh.rerouteTraveltime(vid, False)
                self.reroutes += 1
            except SUMO_ERRORS as exc:
                log.debug("rerouting %s around an incident failed: %s", vid, exc)


def attach(driver: Any, events: RoadEvents) -> RoadPlayer | None:
    """A :class:`RoadPlayer` for a freshly started ``driver`` (a :class:`~evcd.sim.driver.SumoDriver`),
    synced to its time and listening; ``None`` for a calm day (nothing is touched)."""
    if events.empty:
        return None
    player = RoadPlayer(events, driver.api)
    player.sync(driver.api, driver.time)
    driver.add_listener(player)
    return player
