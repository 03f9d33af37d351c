"""The environment's SUMO side: which background day runs, and how an episode reaches its departure.

:class:`EpisodeSimulation` owns this process's one libsumo simulation (a :class:`SumoDriver`) and
the stations' :class:`ChargingController`, and positions both at the target's departure time:

- ``fast``: the latest day snapshot before the departure is loaded and simulated from there to
  the departure. Snapshots are built on first use of a day (:mod:`evcd.sim.snapshots`). The
  driver of the current day stays alive while the loads go *forward* (a snapshot at or after the
  simulation's current time); a load that goes back in time, to a snapshot earlier than the time
  the simulation has reached, first restarts SUMO (:func:`needs_restart`). Two things make that
  necessary, both measured on SUMO 1.28:

  * going back in time without a restart did not reproduce (2026-11-26, f87639c; measured on the batched
    engine): the same run gave other episodes from process to process, with the heap's layout
    (address space randomisation, the hash seed, an unrelated allocation, a day built earlier in
    the same process), and so did the learners trained on them. Each first difference traced
    (three) was a background EV reaching a car park: it entered at once in one process and waited
    on the lane in another. SUMO's car park keeps per-step bookkeeping of the vehicles about to
    enter (``MSParkingArea``: the time step of its reservations, their count, pointers to the
    vehicles) that loadState does not reset, so a load to an earlier time meets the reservations
    of a later step of the replaced run. A load going forward (reservations older than the loaded
    time are renewed at the next step) gave the same episodes as a restart before every load, in
    every process (``tests/env/test_reproducible.py``);
  * SUMO re-reads the route file after a loadState but skips the vehicles it already took from a
    later time, so going back would also lose every background vehicle departing in between (seen:
    74 of 300 in 15 min).

  A restart (start and close) costs about 0.23 s on Jurong West; the engines' rates in
  ``scripts/bench.py --suite throughput`` include them. ``--route-steps 0`` (every future vehicle
  in every snapshot: 10x slower loads) is no alternative for the second reason and none for the
  first.
- ``paper``: a fresh simulation from 00:00 every episode, simulated to the departure; after the
  episode :meth:`finish_day` runs it on to ``day_end`` (23:59).

A failed load or a simulation left broken by a SUMO error is recovered from by restarting SUMO
(and rebuilding a snapshot that turned out corrupted).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from time import perf_counter
from typing import Any

from evcd.env.episode_rules import TIME_EPS
from evcd.env.forecast_source import ForecastSource
from evcd.scenario.scenario import Scenario
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SUMO_ERRORS, SumoDriver
from evcd.sim.road_player import RoadPlayer, attach
from evcd.sim.snapshots import CacheError, DayCache, DaySpec, snapshot_times

log = logging.getLogger(__name__)


def needs_restart(now: float, snapshot_time: float) -> bool:
    """Whether loading a snapshot of ``snapshot_time`` into a simulation at ``now`` needs a fresh SUMO:
    when it goes back in time (module docstring; a load at or after ``now`` reproduces exactly)."""
    return snapshot_time < now - TIME_EPS


class EpisodeSimulation:
    """SUMO and the charging queues of the environment's background days.

    Args:
        scenario: the scenario.
        days: the background days an episode may run in.
        protocol: ``"fast"`` or ``"paper"``.
        window: departure window (s of day): which snapshots are needed.
        snapshot_every: seconds between snapshots.
        cache_dir: snapshot cache root (default :func:`evcd.sim.snapshots.default_cache_dir`).
        day_end: where :meth:`finish_day` stops (paper protocol).
        gui: run the episodes' simulation in ``sumo-gui`` through TraCI.
        forecast: the observation's forecast source, prepared before SUMO starts and told each day
            played (:mod:`evcd.env.forecast_source`).
    """

    def __init__(
        self,
        scenario: Scenario,
        days: Sequence[DaySpec],
        protocol: str,
        window: tuple[float, float],
        snapshot_every: float,
        cache_dir: str | Path | None = None,
        day_end: float = 86_340.0,
        gui: bool = False,
        forecast: ForecastSource | None = None,
    ) -> None:
        self.scenario = scenario
        self.forecast = forecast
        self.caches = [DayCache(spec, cache_dir) for spec in days]
        self.protocol = protocol
        self.times = snapshot_times(window, snapshot_every)
        self.day_end = day_end
        self.gui = gui
        self.controller = ChargingController(scenario.stations)
        self._fresh_controller = self.controller.state_dict()
        self._driver: SumoDriver | None = None
        self._day: int | None = None  # day of the running driver
        self._roads: RoadPlayer | None = None  # plays the running day's road events, if any
        self._ready: set[int] = set()  # days whose snapshots (or routes) this process verified
        self.restarts = 0  # SUMO starts (for the benchmark)
        self.back_restarts = 0  # of which to go back in time (needs_restart)
        self.back_restart_s = 0.0  # their wall time: what reproducibility costs (scripts/bench.py)

    # ------------------------------------------------------------------ state
    @property
    def driver(self) -> SumoDriver:
        """The running driver (raises if none)."""
        if self._driver is None or not self._driver.running:
            raise RuntimeError("no simulation is running; reset the environment first")
        return self._driver

    @property
    def api(self) -> Any:
        """The running simulation's API (libsumo)."""
        return self.driver.api

    @property
    def time(self) -> float:
        """Current simulation time (s of day)."""
        return self.driver.time

    @property
    def running(self) -> bool:
        """Whether a simulation is running."""
        return self._driver is not None and self._driver.running

    # ------------------------------------------------------------------ positioning
    def cached(self, day: int) -> bool:
        """Whether day ``day`` is ready without a build (``fast``: every snapshot it needs is cached;
        ``paper`` builds nothing ahead)."""
        return day in self._ready or self.protocol != "fast" or self.caches[day].has(self.times)

    def prepare(self, day: int) -> None:
        """Make day ``day``'s inputs ready: its routes, and in ``fast`` its snapshots (may build)."""
        if day in self._ready:
            return
        cache = self.caches[day]
        if self.protocol == "fast":
            if not cache.has(self.times):
                self.close()  # building needs this process's libsumo
            cache.ensure(self.times)
        else:
            cache.ensure_routes()
        self._ready.add(day)

    def start_at(self, day: int, time: float) -> None:
        """Position the simulation of day ``day`` at ``time`` (s of day), controller included (with the
        day's charger outages), roads too (its incidents, rain and road works)."""
        self.prepare(day)
        if self.forecast is not None:
            self.forecast.prepare(self.close)
            self.forecast.use_day(self.caches[day])
        self.controller.use_outages(self.caches[day].spec.outages)
        if self.protocol == "paper":
            self._restart(day)
            self.controller.load_state_dict(self._fresh_controller)
        else:
            self._load_snapshot(day, time)
        self.driver.step(until=time)

    def _load_snapshot(self, day: int, time: float) -> None:
        cache = self.caches[day]
        for attempt in range(2):
            snap = cache.latest_before(time)
            back = self.running and self._day == day and needs_restart(self.time, snap.time)
            if back:
                started = perf_counter()
                self._restart(day)
                self.back_restarts += 1
                self.back_restart_s += perf_counter() - started
            elif not self.running or self._day != day:
                self._restart(day)
            try:
                t = cache.load(snap, self.driver, self.controller)
                if self._roads is not None:  # the roads as they are at the snapshot, whatever it holds
                    self._roads.sync(self.api, t)
                return
            except CacheError as exc:
                if attempt:
                    raise
                log.warning("%s; rebuilding the day's snapshots", exc)
                self.close()
                cache.ensure(self.times)
            except RuntimeError as exc:  # SUMO refused the state: start afresh and try once more
                if attempt:
                    raise
                log.warning("loading a snapshot failed (%s); restarting SUMO", exc)
                self.close()

    def _restart(self, day: int) -> None:
        self.close()
        driver = self.caches[day].make_driver(gui=self.gui)
        driver.start()
        driver.add_listener(self.controller.update)
        self._roads = attach(driver, self.caches[day].spec.roads)
        self._driver, self._day = driver, day
        self.restarts += 1

    # ------------------------------------------------------------------ after an episode
    def finish_day(self) -> None:
        """Run the simulation on to ``day_end`` (paper protocol: every episode lasts the whole day)."""
        if self.running and self.time < self.day_end:
            try:
                self.driver.step(until=self.day_end)
            except SUMO_ERRORS as exc:
                log.warning("SUMO error while finishing the day: %s", exc)
                self.close()

    def close(self) -> None:
        """Close the simulation (idempotent)."""
        driver, self._driver, self._day = self._driver, None, None
        if driver is not None:
            driver.close()
