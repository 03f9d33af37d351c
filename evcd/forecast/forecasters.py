"""Forecasts of the vehicles at each station when an EV would get there.

One interface, :class:`Forecaster`: given the time ``now``, the EV's estimated arrival time at each
station and the current day's :class:`~evcd.forecast.timeline.OccupancyTimeline` (known up to
``now``), the forecast number of vehicles at each station at its arrival time.

- :class:`HistoryForecaster`: the mean occupancy of past days in the arrival's time-of-day bin;
- :class:`TrendForecaster`: a straight line through the current day's last minutes;
- :class:`AnomalyForecaster`: the history plus today's deviation from it now, shrunk with the horizon
  as the deviations of the training days decayed;
- :class:`OracleForecaster`: the day's own future, an upper bound for analysis only.

The sessions forecaster is in :mod:`~evcd.forecast.sessions`; all are made by name in
:mod:`~evcd.forecast.registry`.

    forecaster = make_forecaster("history", training_days=past_days, bin_s=900.0)
    forecaster.forecast(now, arrival, today)       # arrival: (m,) or (k, m) seconds of the day
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from evcd.forecast.timeline import OccupancyTimeline
from evcd.utils.validation import check_real, require

#: Seconds between two samples of a timeline (history means, trend lines).
SAMPLE_S = 60.0


def sample_times(known_until: float, sample_s: float) -> np.ndarray:
    """The times ``0, sample_s, 2 sample_s, ...`` up to ``known_until`` (none where it is < 0)."""
    if known_until < 0:
        return np.empty(0)
    times = sample_s * np.arange(math.floor(known_until / sample_s + 1e-9) + 1)
    return times[times <= known_until]


def same_stations(stations: tuple[str, ...], today: OccupancyTimeline, owner: str) -> None:
    """Refuse a ``today`` whose stations are not the ``owner`` forecaster's ``stations``."""
    require(
        today.stations == stations,
        f"today's stations {list(today.stations)}: the {owner} forecaster "
        f"was made for {list(stations)} (same ids, same order)",
    )


def training_stations(days: Sequence[OccupancyTimeline], owner: str) -> tuple[str, ...]:
    """The stations of the training ``days`` of the ``owner`` forecaster (all days must share them).

    Raises:
        ValueError: no days, or days with other stations.
    """
    require(
        len(days) > 0, f"a {owner} forecaster needs training days (timelines of past days); none were given"
    )
    stations = days[0].stations
    for day in days:
        require(
            day.stations == stations,
            f"training days with stations {list(day.stations)} and "
            f"{list(stations)}: all days need the same stations",
        )
    return stations


class Forecaster(ABC):
    """Forecasts the number of vehicles at each station at an EV's arrival time there.

    Subclasses implement :meth:`_predict`; :meth:`forecast` checks the input for all of them.
    """

    name: ClassVar[str]
    #: whether it is fitted on past days (``make_forecaster(name, training_days)``)
    needs_days: ClassVar[bool] = False
    #: whether it reads the current day's counts up to now (else ``today`` only gives ``now``'s bounds)
    reads_today: ClassVar[bool] = False

    def forecast(
        self, now: float, arrival: Sequence[float] | np.ndarray, today: OccupancyTimeline
    ) -> np.ndarray:
        """Forecast vehicles at each station at its arrival time.

        Args:
            now: the decision time (seconds of the day).
            arrival: the EV's estimated arrival time at each station, shape ``(m,)``, or a batch
                ``(k, m)``; every time ``>= now``.
            today: the current day's timeline, known at least up to ``now`` (a forecaster never reads
                it beyond ``now``).

        Returns:
            float64 forecasts, the shape of ``arrival``.

        Raises:
            ValueError: an arrival before ``now``, a shape that does not end in the number of
                stations, ``today`` known only up to before ``now``, or stations other than those the
                forecaster was made for.
        """
        now = check_real("now", now)
        require(
            today.known_until >= now,
            f"today is known until {today.known_until:g}, before now={now:g}: "
            "a forecast needs the day up to now",
        )
        a = np.asarray(arrival, dtype=np.float64)
        m = len(today.stations)
        require(
            a.ndim in (1, 2) and a.shape[-1] == m,
            f"arrival of shape {a.shape}: must be (m,) or (k, m) with m={m} stations",
        )
        require(bool(np.isfinite(a).all()), f"arrival={arrival!r}: must be finite times")
        if a.size and (early := float(a.min())) < now:
            raise ValueError(f"arrival time {early:g} is before now={now:g}: arrival times must be >= now")
        out = self._predict(now, a.reshape(-1, m), today)
        return np.asarray(out, dtype=np.float64).reshape(a.shape)

    @abstractmethod
    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        """Forecasts for checked input: ``arrival`` of shape ``(k, m)``, all ``>= now``."""


class HistoryForecaster(Forecaster):
    """The mean occupancy of the training days in the arrival's time-of-day bin (ignores today's counts).

    :meth:`fit` samples each training day every ``sample_s`` seconds over ``[0, known_until]`` and
    averages, per station and bin of ``bin_s`` seconds, all the samples of all days that fall in the
    bin. A bin without samples takes the mean of the nearest bin that has some (the earlier one on a
    tie); arrivals after the last bin take the last bin.

    Args:
        bin_s: width of a time-of-day bin (s), > 0.
        sample_s: seconds between two samples of a day, > 0.
    """

    name: ClassVar[str] = "history"
    needs_days: ClassVar[bool] = True

    def __init__(self, bin_s: float = 900.0, sample_s: float = SAMPLE_S) -> None:
        self.bin_s = check_real("bin_s", bin_s, low=0.0, low_open=True)
        self.sample_s = check_real("sample_s", sample_s, low=0.0, low_open=True)
        self.stations: tuple[str, ...] | None = None
        self._means: np.ndarray | None = None  # (bins, m)

    def fit(self, days: Sequence[OccupancyTimeline]) -> HistoryForecaster:
        """Learn the bin means from ``days`` (timelines of whole past days, same stations); returns self.

        Raises:
            ValueError: no days, days with other stations, or no sample in any day (all known only
                up to before 0).
        """
        days = list(days)
        stations = training_stations(days, self.name)
        n_bins = max(math.floor(max(d.known_until, 0.0) / self.bin_s) + 1 for d in days)
        sums = np.zeros((n_bins, len(stations)))
        counts = np.zeros(n_bins, dtype=np.int64)
        for day in days:
            times = sample_times(day.known_until, self.sample_s)
            if not times.size:
                continue
            bins = np.floor(times / self.bin_s).astype(np.int64)
            np.add.at(sums, bins, day.at(times))
            counts += np.bincount(bins, minlength=n_bins)
        full = np.flatnonzero(counts)
        require(
            full.size > 0,
            "the training days have no sample in [0, known_until]: each is known only up to before 0",
        )
        idx = np.arange(n_bins)
        pos = np.searchsorted(full, idx)
        left = full[np.clip(pos - 1, 0, full.size - 1)]
        right = full[np.clip(pos, 0, full.size - 1)]
        nearest = np.where(np.abs(idx - left) <= np.abs(right - idx), left, right)
        self._means = (sums[full] / counts[full, None])[np.searchsorted(full, nearest)]
        self.stations = stations
        return self

    @property
    def bin_means(self) -> np.ndarray:
        """The fitted means, shape ``(bins, m)``: row ``b`` covers ``[b * bin_s, (b + 1) * bin_s)``."""
        return self._fitted().copy()

    def _fitted(self) -> np.ndarray:
        require(self._means is not None, "a history forecaster needs training days: call fit(days) first")
        assert self._means is not None
        return self._means

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        means = self._fitted()
        assert self.stations is not None
        same_stations(self.stations, today, self.name)
        bins = np.clip(np.floor(arrival / self.bin_s), 0, len(means) - 1).astype(np.int64)
        return means[bins, np.arange(arrival.shape[1])]


class TrendForecaster(Forecaster):
    """A least-squares line through the current day's occupancy of each station, evaluated at the arrival.

    The occupancy is sampled every ``sample_s`` seconds back from ``now`` over
    ``[max(0, now - window_s), now]``; the line's value is clipped to >= 0. With fewer than 2 samples
    (``window_s`` < ``sample_s``, or ``now`` < ``sample_s``), the forecast is the occupancy now.

    Args:
        window_s: seconds of the past the line is fitted on, >= 0.
        sample_s: seconds between two samples, > 0.
    """

    name: ClassVar[str] = "trend"
    reads_today: ClassVar[bool] = True

    def __init__(self, window_s: float = 900.0, sample_s: float = SAMPLE_S) -> None:
        self.window_s = check_real("window_s", window_s, low=0.0)
        self.sample_s = check_real("sample_s", sample_s, low=0.0, low_open=True)

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        start = max(0.0, now - self.window_s)
        n = math.floor((now - start) / self.sample_s + 1e-9) if now >= start else -1
        x = -self.sample_s * np.arange(n, -1, -1, dtype=np.float64)  # sample times - now, ending at 0
        if x.size < 2:
            return np.broadcast_to(today.at(now).astype(np.float64), arrival.shape)
        y = today.at(now + x).astype(np.float64)  # (n, m), never after now
        dx = x - x.mean()
        slope = dx @ (y - y.mean(axis=0)) / (dx @ dx)
        line = y.mean(axis=0) + slope * (arrival - now - x.mean())
        return np.maximum(line, 0.0)


class AnomalyForecaster(Forecaster):
    """The history's forecast plus today's deviation from the history now, shrunk with the horizon as
    the training days' deviations faded (climatology plus damped persistence).

    ``forecast = max(0, history(arrival) + beta(arrival - now) * (today(now) - history(now)))``: at a
    horizon of 0 it is the vehicles there now; far ahead, the history. ``beta(h)`` is fitted on the
    training days at the lags ``0, sample_s, ...`` up to ``max_lag_s``: the least-squares coefficient of
    a day's deviation ``h`` seconds later on its deviation at a time, pooled over every sample and
    station, ``sum a(t) a(t + h) / sum a(t)^2``, clipped to ``[0, 1]`` (``beta(0) = 1``). A day's
    deviations are taken from the history fitted on the *other* training days (on the day itself when
    only one is given), so that a day's own counts do not shrink them. Between lags ``beta`` is
    linear; beyond ``max_lag_s`` it is 0 (the history alone).

    Args:
        bin_s: the history's time-of-day bin (s), > 0.
        sample_s: seconds between two samples of a day, > 0.
        max_lag_s: the longest horizon the deviation is carried to (s), >= 0.
    """

    name: ClassVar[str] = "anomaly"
    needs_days: ClassVar[bool] = True
    reads_today: ClassVar[bool] = True

    def __init__(self, bin_s: float = 900.0, sample_s: float = SAMPLE_S, max_lag_s: float = 7200.0) -> None:
        self.history = HistoryForecaster(bin_s, sample_s)
        self.max_lag_s = check_real("max_lag_s", max_lag_s, low=0.0)
        self.lags = np.zeros(1)
        self.beta = np.ones(1)

    @property
    def stations(self) -> tuple[str, ...] | None:
        """The stations of the training days (None before :meth:`fit`)."""
        return self.history.stations

    def fit(self, days: Sequence[OccupancyTimeline]) -> AnomalyForecaster:
        """Fit the history on ``days`` and ``beta`` on their deviations; returns self.

        Raises:
            ValueError: as :meth:`HistoryForecaster.fit`.
        """
        days = list(days)
        self.history.fit(days)
        sample_s = self.history.sample_s
        k_max = math.floor(self.max_lag_s / sample_s + 1e-9)
        num = np.zeros(k_max + 1)
        den = np.zeros(k_max + 1)
        for i, day in enumerate(days):
            times = sample_times(day.known_until, sample_s)
            if times.size < 1:
                continue
            others = [d for j, d in enumerate(days) if j != i and d.known_until >= 0] or [day]
            reference = HistoryForecaster(self.history.bin_s, sample_s).fit(others)
            m = len(day.stations)
            expected = reference._predict(0.0, np.repeat(times[:, None], m, axis=1), day)
            dev = day.at(times) - expected  # (n, m)
            for k in range(min(k_max, len(times) - 1) + 1):
                num[k] += float((dev[: len(times) - k] * dev[k:]).sum())
                den[k] += float((dev[: len(times) - k] ** 2).sum())
        with np.errstate(invalid="ignore", divide="ignore"):
            beta = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
        self.lags = sample_s * np.arange(k_max + 1)
        self.beta = np.clip(beta, 0.0, 1.0)
        return self

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        m = arrival.shape[1]
        expected = self.history._predict(now, arrival, today)
        deviation = today.at(now) - self.history._predict(now, np.full((1, m), now), today)[0]
        beta = np.interp(arrival - now, self.lags, self.beta, right=0.0)
        return np.maximum(expected + beta * deviation, 0.0)


class OracleForecaster(Forecaster):
    """The day's own future: the exact occupancy at the arrival time (the value at ``day.known_until``
    for later arrivals).

    An upper bound on what a forecast can give, **for analysis only**: it reads the future, so a result
    that uses it is never a claim about a learner or a dispatcher that could run.

    Args:
        day: the timeline of the whole day being played.
    """

    name: ClassVar[str] = "oracle"

    def __init__(self, day: OccupancyTimeline) -> None:
        require(isinstance(day, OccupancyTimeline), f"day={day!r}: must be an OccupancyTimeline")
        self.day = day

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        same_stations(self.day.stations, today, self.name)
        return self.day.at_each(arrival, clip=True)
