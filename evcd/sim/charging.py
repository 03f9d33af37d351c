"""First-come-first-served charging points at the stations.

SUMO has no notion of a limited number of charging points: every EV parked in a station's car park
(the ``parkingArea`` linked to the ``chargingStation``) is charged. :class:`ChargingController` adds
the points. Every EV that parks in a station's car park joins the station's FIFO; the first
``points`` EVs charge, the others are held at ``device.battery.maximumChargeRate`` = 0 in the car
park (off the road: they block nobody and never teleport). A charging EV that reaches its target
state of charge (SoC) is resumed (``vehicle.resume``) and drives on; the head of the queue gets its
charge rate back and takes the point.

Per vehicle (SUMO vehicle ``<param>``):

- ``evcd.targetSoc``: SoC (0..1] at which the EV is released; default: the controller's.
- ``evcd.hold`` = ``1``: never release it (the RL target: the caller ends the episode when it starts
  charging and may :meth:`~ChargingController.release` it). :meth:`~ChargingController.hold` does
  the same without a parameter.

Charging points may be out of service for a while (``outages``, :mod:`evcd.sim.outages`): the FIFO
then serves fewer points, and a vehicle whose point fails goes back to the head of the queue.

The controller is driven explicitly, once after every simulation step::

    controller = ChargingController(read_stations(path))
    driver.add_listener(controller.update)      # or: controller.update(driver.api, driver.time)

Per step it makes 2 + (number of stations) API calls, plus a few per event; the charge of a charging
EV is read a handful of times per session (scheduled from its observed charge rate), then every step
in the last seconds before its target.
Its state is plain data (:meth:`~ChargingController.state_dict`) so a simulation snapshot can carry
it.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable, Sequence
from typing import Any

from evcd.scenario.stations_file import Station
from evcd.sim.charge_record import ChargeRecord, Outcome
from evcd.sim.driver import SUMO_ERRORS
from evcd.sim.outages import Outage, check_outages, points_in_service
from evcd.sim.visits import StationState, Visit

log = logging.getLogger(__name__)

TARGET_SOC_PARAM = "evcd.targetSoc"
HOLD_PARAM = "evcd.hold"
DEFAULT_TARGET_SOC = 0.8
STATE_VERSION = 1

_LEVEL = "device.battery.chargeLevel"  # Wh (SUMO < 1.20: actualBatteryCapacity)
_CAPACITY = "device.battery.capacity"  # Wh (SUMO < 1.20: maximumBatteryCapacity)
_RATE = "device.battery.maximumChargeRate"  # W; settable, unlike maximumPower
_TRUE = {"1", "true", "yes"}
_SOC_TOL = 1e-9
# Reading a vehicle's charge costs ~5 us, so a charging vehicle is not read every step: the next read
# is scheduled from the charge rate seen between the last two reads, at a fraction of the predicted
# time to target, and every step once less than _POLL_EVERY_STEP_S remains. A release therefore
# happens in the first step at or above the target unless the rate rises by more than 1/_AHEAD.
_PROBE_S = 10.0  # first read after a vehicle starts charging (no rate known yet)
_AHEAD = 0.8  # read again after this fraction of the predicted remaining time
_POLL_EVERY_STEP_S = 5.0


class ChargingController:
    """FIFO queues and charging points of every station.

    Args:
        stations: the scenario's stations (their ``points`` and car parks are used).
        default_target_soc: release SoC for vehicles without ``evcd.targetSoc``.
        hold: ids of vehicles never to release (like ``evcd.hold=1``).
        outages: charging points out of service over given periods (:mod:`evcd.sim.outages`).

    Raises:
        ValueError: no stations, a bad target SoC, repeated ids or car parks, or a bad outage.
    """

    def __init__(
        self,
        stations: Sequence[Station],
        default_target_soc: float = DEFAULT_TARGET_SOC,
        hold: Iterable[str] = (),
        outages: Iterable[Outage] = (),
    ) -> None:
        if not stations:
            raise ValueError("ChargingController needs at least one station")
        if not 0.0 < default_target_soc <= 1.0:
            raise ValueError(f"default_target_soc={default_target_soc} must be in (0, 1]")
        ids = [st.id for st in stations]
        lots = [st.parking_area for st in stations]
        if len(set(ids)) != len(ids) or len(set(lots)) != len(lots):
            raise ValueError(f"station ids and car parks must be unique: {ids}, {lots}")
        self.stations: tuple[Station, ...] = tuple(stations)
        self.default_target_soc = default_target_soc
        self._by_lot = {st.parking_area: st.id for st in stations}
        self._hold: set[str] = set(hold)
        self.use_outages(outages)
        self._reset()

    def use_outages(self, outages: Iterable[Outage]) -> None:
        """Make ``outages`` the points out of service from now on (a day's own: a controller that
        plays several days is given each day's before it plays it).

        Raises:
            ValueError: a bad outage (:func:`~evcd.sim.outages.check_outages`).
        """
        self.outages = check_outages(outages, self.stations)
        self._out = {st.id: tuple(o for o in self.outages if o.station == st.id) for st in self.stations}

    def _reset(self) -> None:
        self._st = {st.id: StationState(st) for st in self.stations}
        self._visits: dict[str, Visit] = {}
        self._where: dict[str, str] = {}  # vehicle -> station, for every vehicle in a known lot
        self._records: list[ChargeRecord] = []
        self._joined: list[str] = []
        self._started: list[int] = []
        self._ended: list[int] = []

    # ------------------------------------------------------------------ the step
    def update(self, api: Any, time: float) -> None:
        """Advance the queues after a simulation step; ``api`` is libsumo or a TraCI connection."""
        self._joined.clear()
        self._started.clear()
        self._ended.clear()
        sim = api.simulation
        # A stop that ends by itself is reported while the vehicle is still in the car park (it
        # drives out in the next step); one we resume leaves the car park's list at once.
        for vid in sim.getParkingEndingVehiclesIDList():
            if vid in self._visits:  # its stop ended without us: duration over, or rerouted
                self._end(api, vid, time, Outcome.LEFT, still_parked=True)
            elif vid in self._where:
                self._st[self._where[vid]].leaving.add(vid)
        for vid in sim.getParkingStartingVehiclesIDList():
            if vid not in self._where:
                stops = api.vehicle.getStops(vid, 1)
                sid = self._by_lot.get(stops[0].stoppingPlaceID) if stops else None
                if sid is not None:
                    self._join(api, vid, sid, time)
        for st in self._st.values():
            self._reconcile(api, st, time)
            if st.charging:
                self._release_charged(api, st, time)
            points = self.points_in_service(st.station.id, time)
            if len(st.charging) > points:
                self._interrupt(api, st, points, time)
            if st.queue:
                self._fill_points(api, st, points, time)
        for vid in self._joined:  # joined this step and no point free: hold it
            visit = self._visits.get(vid)
            if visit is None or visit.zeroed or self._records[visit.record].start_time is not None:
                continue
            if self._set_rate(api, vid, "0", time):
                visit.zeroed = True

    def _join(self, api: Any, vid: str, sid: str, time: float) -> None:
        st = self._st[sid]
        st.lot.add(vid)
        self._where[vid] = sid
        get = api.vehicle.getParameter
        try:
            capacity = float(get(vid, _CAPACITY))
            level = float(get(vid, _LEVEL))
            rate = get(vid, _RATE)
            target_txt = get(vid, TARGET_SOC_PARAM)
            hold_txt = get(vid, HOLD_PARAM)
        except (*SUMO_ERRORS, ValueError) as exc:
            log.debug("vehicle %s parked at station %s has no battery; not queued (%s)", vid, sid, exc)
            return
        if capacity <= 0:
            log.debug("vehicle %s at station %s has battery capacity 0; not queued", vid, sid)
            return
        target = self.default_target_soc
        if target_txt:
            try:
                target = float(target_txt)
            except ValueError:
                target = -1.0
            if not 0.0 < target <= 1.0:
                target = self.default_target_soc
                log.warning("vehicle %s: bad %s=%r; using %s", vid, TARGET_SOC_PARAM, target_txt, target)
        hold = vid in self._hold or hold_txt.strip().lower() in _TRUE
        soc = level / capacity
        self._records.append(ChargeRecord(vid, sid, time, soc, target, hold))
        self._visits[vid] = Visit(len(self._records) - 1, capacity, rate)
        st.queue.append(vid)
        self._joined.append(vid)
        log.debug("t=%s %s joins %s (soc %.3f, queue %d)", time, vid, sid, soc, len(st.queue))

    def _reconcile(self, api: Any, st: StationState, time: float) -> None:
        """Catch vehicles that left the car park unannounced, and adopt unknown parked ones."""
        lot_id = st.station.parking_area
        if api.parkingarea.getVehicleCount(lot_id) == len(st.lot):
            return
        present = api.parkingarea.getVehicleIDs(lot_id)
        here = set(present)
        for vid in sorted(st.lot - here):
            if vid in self._visits:
                log.warning("t=%s %s vanished from station %s", time, vid, st.station.id)
                self._end(api, vid, time, Outcome.VANISHED)
            else:  # a vehicle without battery, or one whose parking ended, has driven out
                st.lot.discard(vid)
                st.leaving.discard(vid)
                self._where.pop(vid, None)
        for vid in present:
            if vid not in self._where:
                log.info("t=%s adopting %s, already parked at station %s", time, vid, st.station.id)
                self._join(api, vid, st.station.id, time)

    def _release_charged(self, api: Any, st: StationState, time: float) -> None:
        for vid in list(st.charging):
            visit = self._visits[vid]
            rec = self._records[visit.record]
            if rec.hold or time < visit.next_read:
                continue
            soc = self._soc(api, vid, visit)
            if soc is None:
                self._end(api, vid, time, Outcome.VANISHED)
            elif soc + _SOC_TOL >= rec.target_soc:
                try:
                    api.vehicle.resume(vid)
                except SUMO_ERRORS as exc:
                    log.warning("t=%s could not resume %s at %s: %s", time, vid, st.station.id, exc)
                    self._end(api, vid, time, Outcome.VANISHED)
                    continue
                self._end(api, vid, time, Outcome.CHARGED, soc)
            else:
                self._schedule_read(visit, time, soc, rec.target_soc)

    @staticmethod
    def _schedule_read(visit: Visit, time: float, soc: float, target: float) -> None:
        rate = (soc - visit.read_soc) / (time - visit.read_time) if time > visit.read_time else 0.0
        if rate <= 0:  # not charging (yet): look again later
            visit.next_read = time + _PROBE_S
        else:
            remaining = (target - soc) / rate
            visit.next_read = time if remaining <= _POLL_EVERY_STEP_S else time + _AHEAD * remaining
        visit.read_time, visit.read_soc = time, soc

    def _interrupt(self, api: Any, st: StationState, points: int, time: float) -> None:
        """Points failed: the vehicles that started last stop and go back to the queue's head."""
        while len(st.charging) > points:
            vid = st.charging.pop()
            visit = self._visits[vid]
            if not self._set_rate(api, vid, "0", time):
                st.charging.append(vid)
                self._end(api, vid, time, Outcome.VANISHED)
                continue
            visit.zeroed = True
            st.queue.insert(0, vid)
            log.debug("t=%s %s's point at %s is out of service: back to the queue's head", time, vid,
                      st.station.id)  # fmt: skip

    def _fill_points(self, api: Any, st: StationState, points: int, time: float) -> None:
        while st.queue and len(st.charging) < points:
            vid = st.queue.pop(0)
            visit = self._visits[vid]
            rec = self._records[visit.record]
            if visit.zeroed:
                if not self._set_rate(api, vid, visit.rate, time):
                    self._end(api, vid, time, Outcome.VANISHED)
                    continue
                visit.zeroed = False
            soc = rec.soc_arrival if rec.arrival_time == time else self._soc(api, vid, visit)
            if soc is None:
                self._end(api, vid, time, Outcome.VANISHED)
                continue
            visit.read_time, visit.read_soc, visit.next_read = time, soc, time + _PROBE_S
            if soc + _SOC_TOL >= rec.target_soc:
                visit.next_read = time  # already there: released at the next update
            st.charging.append(vid)
            if rec.start_time is not None:  # resumes after its point failed: not a new start
                continue
            rec.start_time, rec.soc_start = time, soc
            self._started.append(visit.record)
            log.debug("t=%s %s starts charging at %s (soc %.3f)", time, vid, st.station.id, soc)

    def _end(
        self,
        api: Any,
        vid: str,
        time: float,
        outcome: Outcome,
        soc: float | None = None,
        still_parked: bool = False,
    ) -> None:
        visit = self._visits.pop(vid)
        rec = self._records[visit.record]
        st = self._st[rec.station]
        if vid in st.charging:
            st.charging.remove(vid)
        elif vid in st.queue:
            st.queue.remove(vid)
        if still_parked:
            st.leaving.add(vid)
        else:
            st.lot.discard(vid)
            self._where.pop(vid, None)
        if outcome is not Outcome.VANISHED:
            if soc is None:
                soc = self._soc(api, vid, visit)
            if visit.zeroed:  # it drives on: give its charge rate back for later stations
                self._set_rate(api, vid, visit.rate, time)
        rec.release_time, rec.soc_release, rec.outcome = time, soc, outcome
        self._ended.append(visit.record)
        log.debug("t=%s %s leaves %s: %s", time, vid, rec.station, outcome)

    @staticmethod
    def _soc(api: Any, vid: str, visit: Visit) -> float | None:
        try:
            return float(api.vehicle.getParameter(vid, _LEVEL)) / visit.capacity
        except SUMO_ERRORS:
            return None

    @staticmethod
    def _set_rate(api: Any, vid: str, rate: str, time: float) -> bool:
        try:
            api.vehicle.setParameter(vid, _RATE, rate)
        except SUMO_ERRORS as exc:
            log.warning("t=%s cannot set the charge rate of %s: %s", time, vid, exc)
            return False
        return True

    # ------------------------------------------------------------------ caller's controls
    def hold(self, vid: str) -> None:
        """Never release ``vid`` automatically (also if it is already at a station)."""
        self._hold.add(vid)
        visit = self._visits.get(vid)
        if visit is not None:
            self._records[visit.record].hold = True

    def release(self, api: Any, vid: str, time: float) -> ChargeRecord:
        """Resume ``vid`` (waiting or charging) now; its point goes to the next in line at the next
        :meth:`update`. Returns its finished record.

        Raises:
            KeyError: ``vid`` is not at a station.
        """
        if vid not in self._visits:
            raise KeyError(f"vehicle {vid!r} is not at a charging station")
        self._hold.discard(vid)
        try:
            api.vehicle.resume(vid)
            outcome = Outcome.RELEASED
        except SUMO_ERRORS as exc:
            log.warning("t=%s could not resume %s: %s", time, vid, exc)
            outcome = Outcome.VANISHED
        record = self._visits[vid].record
        self._end(api, vid, time, outcome)
        return dataclasses.replace(self._records[record])

    # ------------------------------------------------------------------ queries
    def occupancy(self, station: str) -> int:
        """Vehicles at ``station`` (charging + waiting)."""
        st = self._st[station]
        return len(st.queue) + len(st.charging)

    def waiting(self, station: str) -> int:
        """Vehicles waiting for a point at ``station``."""
        return len(self._st[station].queue)

    def points_in_service(self, station: str, time: float) -> int:
        """Charging points of ``station`` in service at ``time`` (its points less its outages')."""
        return points_in_service(self._st[station].station.points, self._out[station], time)

    def charging(self, station: str) -> int:
        """Vehicles holding a point at ``station``."""
        return len(self._st[station].charging)

    def occupancies(self) -> list[int]:
        """:meth:`occupancy` of every station, in the order of :attr:`stations`."""
        return [len(st.queue) + len(st.charging) for st in self._st.values()]

    def queue(self, station: str) -> tuple[str, ...]:
        """Waiting vehicles at ``station``, head first."""
        return tuple(self._st[station].queue)

    def charging_vehicles(self, station: str) -> tuple[str, ...]:
        """Vehicles holding a point at ``station``."""
        return tuple(self._st[station].charging)

    def status(self, vid: str) -> str | None:
        """``"charging"``, ``"waiting"`` or ``None`` (not at a station)."""
        visit = self._visits.get(vid)
        if visit is None:
            return None
        return "charging" if vid in self._st[self._records[visit.record].station].charging else "waiting"

    def started_this_step(self) -> list[ChargeRecord]:
        """Visits that got a point in the last :meth:`update` (their ``start_time`` is exact)."""
        return [dataclasses.replace(self._records[i]) for i in self._started]

    def ended_this_step(self) -> list[ChargeRecord]:
        """Visits that ended in the last :meth:`update` or :meth:`release` since."""
        return [dataclasses.replace(self._records[i]) for i in self._ended]

    def current(self, vid: str) -> ChargeRecord | None:
        """The visit ``vid`` is on now, if any."""
        visit = self._visits.get(vid)
        return None if visit is None else dataclasses.replace(self._records[visit.record])

    @property
    def records(self) -> list[ChargeRecord]:
        """Every visit so far (finished and ongoing), in arrival order; copies."""
        return [dataclasses.replace(r) for r in self._records]

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        """The controller's state as plain, JSON-serialisable data."""
        return {
            "version": STATE_VERSION,
            "default_target_soc": self.default_target_soc,
            "hold": sorted(self._hold),
            "records": [r.to_dict() for r in self._records],
            "visits": {vid: dataclasses.asdict(v) for vid, v in self._visits.items()},
            "stations": {
                sid: {
                    "queue": list(st.queue),
                    "charging": list(st.charging),
                    "lot": sorted(st.lot),
                    "leaving": sorted(st.leaving),
                }
                for sid, st in self._st.items()
            },
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (pair it with the SUMO state saved at the same time).

        Raises:
            ValueError: the state is of another version or another set of stations.
        """
        if state.get("version") != STATE_VERSION:
            raise ValueError(f"charging state version {state.get('version')!r}, expected {STATE_VERSION}")
        if set(state["stations"]) != set(self._st):
            raise ValueError(
                f"charging state is for stations {sorted(state['stations'])}, not {sorted(self._st)}"
            )
        self._reset()
        self.default_target_soc = float(state["default_target_soc"])
        self._hold = set(state["hold"])
        self._records = [ChargeRecord.from_dict(r) for r in state["records"]]
        self._visits = {vid: Visit(**v) for vid, v in state["visits"].items()}
        for sid, data in state["stations"].items():
            st = self._st[sid]
            st.queue, st.charging = list(data["queue"]), list(data["charging"])
            st.lot, st.leaving = set(data["lot"]), set(data["leaving"])
            self._where.update(dict.fromkeys(st.lot, sid))
