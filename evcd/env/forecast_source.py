"""Where an environment's forecast block ``F`` (:mod:`evcd.env.observation`) comes from.

    source = ForecastSource("history", {}, station_ids, history_days=[DayCache(spec) ...], times=times)
    source.prepare(close=simulation.close)      # before SUMO starts: fit on the history days
    source.use_day(cache)                       # the day about to be played (the oracle reads it)
    source(now, arrival, controller)            # per station, the vehicles forecast at its arrival

The forecasters (:mod:`evcd.forecast`) read occupancy timelines made from the stations' visit
records: the history days' from their cached snapshots (the controller's records at the last one:
the day up to the end of the departure window), the current day's from the controller now (the
trend's, the anomaly's and the sessions' input), the played day's own from its cache (the oracle's,
an upper bound for analysis: ``scripts/train.py`` refuses it).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from evcd.forecast import FORECASTERS, Forecaster, OccupancyTimeline, make_forecaster
from evcd.sim.charging import ChargingController
from evcd.sim.snapshots import DayCache


def day_timeline(cache: DayCache, times: Sequence[float], stations: Sequence[str]) -> OccupancyTimeline:
    """The occupancy of ``cache``'s day as its last snapshot among ``times`` records it (built where
    missing: this process's libsumo must then be free)."""
    last = cache.ensure(times)[-1]
    records = json.loads(last.controller.read_text(encoding="utf-8"))["records"]
    return OccupancyTimeline.from_records(records, stations, known_until=last.time)


class ForecastSource:
    """The forecast of the vehicles at each station at an EV's arrival (module docstring).

    Args:
        name: ``"history"``, ``"trend"``, ``"anomaly"``, ``"sessions"`` or ``"oracle"``.
        settings: the forecaster's settings (``bin_s``, ``window_s``, ``sample_s``, ``max_lag_s``).
        stations: the station ids, in action order.
        history_days: the days the forecasters that learn are fitted on (the training days).
        times: the snapshot times the days are built at (the environment's).
    """

    def __init__(
        self,
        name: str,
        settings: Mapping[str, Any],
        stations: Sequence[str],
        history_days: Sequence[DayCache],
        times: Sequence[float],
    ) -> None:
        self.name = name
        self.settings = dict(settings)
        self.stations = tuple(stations)
        self.history_days = list(history_days)
        self.times = list(times)
        self._forecaster: Forecaster | None = None
        self._today: OccupancyTimeline | None = None  # the current day up to the last time asked

    def prepare(self, close: Callable[[], None]) -> None:
        """Fit a forecaster that learns from past days once (building their snapshots where missing,
        after ``close`` freed this process's libsumo); the trend needs nothing."""
        if self._forecaster is not None or self.name == "oracle":
            return
        if FORECASTERS[self.name].needs_days:
            timelines = []
            for cache in self.history_days:
                if not cache.has(self.times):
                    close()
                timelines.append(day_timeline(cache, self.times, self.stations))
            self._forecaster = make_forecaster(self.name, timelines, **self.settings)
        else:
            self._forecaster = make_forecaster(self.name, **self.settings)

    def use_day(self, cache: DayCache) -> None:
        """The day about to be played (its snapshots ensured): the oracle's future."""
        self._today = None
        if self.name == "oracle":
            self._forecaster = make_forecaster("oracle", day=day_timeline(cache, self.times, self.stations))

    def __call__(self, now: float, arrival: np.ndarray, controller: ChargingController) -> np.ndarray:
        """The forecast vehicles at each station at its ``arrival`` time (s of day, >= ``now``)."""
        if self._forecaster is None:
            raise RuntimeError("the forecast source is not prepared (EpisodeSimulation.start_at does it)")
        # the history and the oracle do not read today's counts: an empty day known up to now. One
        # timeline per simulation time: every target deciding at a tick shares it.
        if self._today is None or self._today.known_until != now:
            records = controller.records if FORECASTERS[self.name].reads_today else []
            self._today = OccupancyTimeline.from_records(records, self.stations, known_until=now)
        today = self._today
        return self._forecaster.forecast(now, np.maximum(arrival, now), today)
