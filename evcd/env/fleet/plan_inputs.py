"""What the clairvoyant planner (:mod:`evcd.planner`) knows of a fleet episode, read in SUMO.

    inputs = read_episode(env, seed=0, options={"day": 0})   # one SUMO run of the episode
    result = solve(inputs.problem, hint=inputs.own)

The episode is played once with every guided EV kept on its trip's own station (the plain day:
nobody is sent anywhere; the day is built first if it is not cached, as for every episode), and read
on the way:

- **guided EVs that decide** (they become agents): at their first tick, the *request*, the drive time
  to each station from where they are (``T``, the route observer's estimate on the current edge
  speeds, :mod:`evcd.env.observation`; a station without a route is no option), and what they would
  charge there. The energy: their target state of charge less the charge on arrival, which is their
  own station's measured arrival charge moved by the day's mean consumption per metre (over the guided
  EVs' drives to their own stations) times the difference of the distances ``D``; the time: that
  energy over the station's power times its efficiency (read from SUMO's charging station). An EV
  waiting in its car park at its first tick keeps its arrival there. Deadline: its departure plus
  ``max_travel_time`` (the fleet truncates it then).
- **guided EVs that never decide** (they started charging before their first tick): their session at
  their own station, counted in the objective.
- **everybody else's sessions** (background EVs, sessions going on at the window's start): from the
  charging controller's records, run on to the latest arrival any plan could have; each keeps its
  station, arrival and measured time on a point (started before the window: fixed; still on a point
  or waiting at the end of the run: the energy it lacks over the station's power, read then).
- **outages**: the day's (:mod:`evcd.sim.outages`), as blocked points.

Guided EVs SUMO never inserted are left out (``dropped``). What the model leaves out is listed in
:mod:`evcd.loops.fleet_bound`.
"""

from __future__ import annotations

import math
import time as wallclock
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evcd.env.fleet.fleet_env import FleetEnv
from evcd.env.observation import UNREACHABLE_S, RouteObserver
from evcd.planner.model import Blocked, Job, Option, PlanProblem, PlanStation
from evcd.sim.charge_record import ChargeRecord
from evcd.sim.charging import TARGET_SOC_PARAM
from evcd.sim.driver import SUMO_ERRORS

_LEVEL = "device.battery.chargeLevel"  # Wh (SUMO's battery device)
_CAPACITY = "device.battery.capacity"  # Wh
_NOT_INSERTED = "not_inserted"  # the fleet's reason for a guided EV SUMO never inserted


@dataclass(frozen=True)
class Request:
    """A deciding guided EV at its first tick."""

    time: float  # s of day
    distance: np.ndarray  # D: m to each station
    drive: np.ndarray  # T: s to each station (0 where it waits)
    waiting_at: int | None  # the station whose car park it is in, if any
    level_wh: float
    capacity_wh: float
    target_soc: float


@dataclass(frozen=True)
class EpisodeInputs:
    """A fleet episode as the planner sees it.

    Attributes:
        problem: the stations and jobs (:class:`~evcd.planner.model.PlanProblem`).
        requests: per deciding guided EV, its :class:`Request` (the EVs the planner places).
        own: per guided EV, its trip's own station (the plain day; a hint for the search).
        day: the day's demand seed.
        guided: the episode's guided EVs.
        dropped: guided EVs left out (never inserted).
        consumption_wh_per_m: the day's mean consumption used for the other stations' energy.
        plain_travel: per guided EV that charged, its travel time in the plain day (s).
        wall_s: seconds the reading took (the SUMO run).
    """

    problem: PlanProblem
    requests: Mapping[str, Request]
    own: Mapping[str, int]
    day: int
    guided: int
    dropped: tuple[str, ...]
    consumption_wh_per_m: float
    plain_travel: Mapping[str, float]
    wall_s: float


def read_episode(env: FleetEnv, seed: int | None, options: Mapping[str, Any] | None = None) -> EpisodeInputs:
    """Play the episode ``env.reset(seed=seed, options=options)`` names with every guided EV on its own
    station, and read the planner's problem from it (module docstring). The env is left at the end of
    the run (its next ``reset`` starts afresh).

    Raises:
        ValueError: the day has no charging EV departing in the window (before SUMO starts), or a
            bad reset option.
    """
    t0 = wallclock.perf_counter()
    env.check_days()
    observer = RouteObserver(env.stations, env.graph, observe=("route_time",))
    env.reset(seed=seed, options=dict(options) if options else None)
    sim = env.simulation
    requests: dict[str, Request] = {}
    index = {st.id: i for i, st in enumerate(env.stations)}

    def note(agents: Sequence[str]) -> None:
        for a in agents:
            if a in requests:
                continue
            ev = env.guided[a]
            record = sim.controller.current(a)
            at = None if record is None else index[record.station]
            obs = observer.observe(sim.api, sim.controller, ev.road, ev.pos, at)
            level, capacity, target = _battery(sim.api, a, sim.controller.default_target_soc)
            requests[a] = Request(sim.time, obs.distance, obs.extra["T"], at, level, capacity, target)

    note(env.agents)
    while env.agents:
        env.step({a: env.guided[a].station for a in env.agents})
        note(env.agents)
    latest = [r.time + float(t) for r in requests.values() for t in r.drive if t < UNREACHABLE_S]
    until = math.ceil(max([sim.time, *latest]))
    sim.driver.step(until=until)
    records = sim.controller.records
    power = {i: _power(sim.api, st.id) for i, st in enumerate(env.stations)}
    window = env.config.departure_window[0]
    own = {ev.vehicle: ev.trip.station for ev in env.guided.values()}
    sessions = _sessions(records)
    consumption = _consumption(requests, sessions, own)
    jobs = [_guided_job(a, r, env, sessions.get(a), consumption, power) for a, r in requests.items()]
    deciding = set(requests)
    for record in records:
        if record.vehicle in deciding or not _matters(record, window):
            continue
        job = _session_job(record, env, index, power, sim.api, sim.time, window)
        if job is not None:
            jobs.append(job)
    blocked: dict[str, list[Blocked]] = {st.id: [] for st in env.stations}
    for o in sim.controller.outages:
        blocked[o.station].append(Blocked(o.points, o.start, o.end))
    stations = tuple(PlanStation(st.id, st.points, tuple(blocked[st.id])) for st in env.stations)
    outcomes = env.outcomes()
    plain = {o["vehicle"]: float(o["travel_time"]) for o in outcomes if o.get("reason") == "charging"}
    dropped = tuple(v for v, ev in env.guided.items() if ev.reason == _NOT_INSERTED)
    assert env.day is not None
    return EpisodeInputs(
        problem=PlanProblem(stations, tuple(jobs), window), requests=requests, own=own,
        day=env.days[env.day].demand_seed, guided=len(env.guided), dropped=dropped,
        consumption_wh_per_m=consumption, plain_travel=plain, wall_s=wallclock.perf_counter() - t0,
    )  # fmt: skip


def _battery(api: Any, vehicle: str, default_target: float) -> tuple[float, float, float]:
    """A vehicle's charge (Wh), capacity (Wh) and target state of charge."""
    get = api.vehicle.getParameter
    text = get(vehicle, TARGET_SOC_PARAM)
    try:
        target = float(text) if text else default_target
    except ValueError:
        target = default_target
    if not 0.0 < target <= 1.0:
        target = default_target
    return float(get(vehicle, _LEVEL)), float(get(vehicle, _CAPACITY)), target


def _power(api: Any, station: str) -> float:
    """What a point of ``station`` charges (W): SUMO's charging power times its efficiency."""
    cs = api.chargingstation
    return float(cs.getChargingPower(station)) * float(cs.getEfficiency(station))


def _sessions(records: Sequence[ChargeRecord]) -> dict[str, ChargeRecord]:
    """Each vehicle's last visit that got a point (a guided EV's one charge in the plain day)."""
    out: dict[str, ChargeRecord] = {}
    for r in records:
        if r.start_time is not None:
            out[r.vehicle] = r
    return out


def _consumption(
    requests: Mapping[str, Request], sessions: Mapping[str, ChargeRecord], own: Mapping[str, int]
) -> float:
    """The guided EVs' mean consumption (Wh per m) on their drive from the request to their own
    station (0 if none drove; never below 0: braking into a car park may recuperate more than a short
    drive used)."""
    used = metres = 0.0
    for vehicle, r in requests.items():
        s = sessions.get(vehicle)
        if s is None or r.waiting_at is not None or s.arrival_time < r.time:
            continue
        used += r.level_wh - s.soc_arrival * r.capacity_wh
        metres += float(r.distance[own[vehicle]])
    return max(used / metres, 0.0) if metres > 0 else 0.0


def _guided_job(
    vehicle: str,
    r: Request,
    env: FleetEnv,
    session: ChargeRecord | None,
    consumption: float,
    power: Mapping[int, float],
) -> Job:
    """A deciding guided EV: one option per station it has a route to."""
    ev = env.guided[vehicle]
    # the charge on arrival at a station: measured at its own (where it waits, or where the plain day
    # took it), moved by the consumption over the difference in distance; without a visit of its own
    # (it was truncated), from its charge at the request
    if session is not None:
        base_wh, base_m = session.soc_arrival * r.capacity_wh, float(r.distance[ev.trip.station])
    else:
        base_wh, base_m = r.level_wh, 0.0
    options = []
    for s, drive in enumerate(r.drive):
        if drive >= UNREACHABLE_S:
            continue
        arrival = r.time + float(drive)
        if s == r.waiting_at and session is not None:
            arrival = session.arrival_time
        level = base_wh + consumption * (base_m - float(r.distance[s]))
        need = max(r.target_soc * r.capacity_wh - level, 0.0)
        options.append(Option(s, arrival, need / power[s] * 3600.0))
    depart = ev.trip.depart
    return Job(vehicle, tuple(options), depart=depart, deadline=depart + env.config.max_travel_time)


def _matters(record: ChargeRecord, window: float) -> bool:
    """Whether a visit can meet the episode's sessions: it got or may get a point after the start."""
    if record.release_time is not None and record.release_time <= window:
        return False
    return record.start_time is not None or record.release_time is None


def _session_job(
    record: ChargeRecord,
    env: FleetEnv,
    index: Mapping[str, int],
    power: Mapping[int, float],
    api: Any,
    now: float,
    window: float,
) -> Job | None:
    """Another vehicle's visit as a fixed-station job (``None`` if it vanished before a point)."""
    s = index[record.station]
    if record.start_time is not None and record.release_time is not None:
        duration = record.release_time - record.start_time
    else:
        try:
            level, capacity = float(api.vehicle.getParameter(record.vehicle, _LEVEL)), float(
                api.vehicle.getParameter(record.vehicle, _CAPACITY))  # fmt: skip
        except SUMO_ERRORS:
            if record.start_time is None:
                return None
            level, capacity = math.inf, 0.0
        remaining = max(record.target_soc * capacity - level, 0.0) / power[s] * 3600.0
        duration = remaining + (now - record.start_time if record.start_time is not None else 0.0)
    started = record.start_time if record.start_time is not None and record.start_time <= window else None
    ev = env.guided.get(record.vehicle)
    option = (Option(s, record.arrival_time, duration),)
    if ev is None:  # a background session
        return Job(f"{record.vehicle}@{record.arrival_time:g}", option, started=started)
    depart = ev.trip.depart  # a guided EV that charged before its first tick: it counts
    return Job(record.vehicle, option, depart=depart, deadline=depart + env.config.max_travel_time,
               started=started)  # fmt: skip
