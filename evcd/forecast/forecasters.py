"""Forecasts of the vehicles at each station when an EV would get there.

One interface, :class:`Forecaster`: given the time ``now``, the EV's estimated arrival time at each
station and the current day's :class:`~evcd.forecast.timeline.OccupancyTimeline` (known up to
``now``), the forecast number of vehicles at each station at its arrival time.

- :class:`HistoryForecaster`: the mean occupancy of past days in the arrival's time-of-day bin;
- :class:`TrendForecaster`: a straight line through the current day's last minutes;
- :class:`AnomalyForecaster`: the history plus today's deviation from it now, shrunk with the horizon
  as the deviations of the training days decayed;
- :class:`SessionsForecaster`: the vehicles there now, less the charging sessions likely to end before
  the arrival (given how long each has charged), plus the arrivals expected by then;
- :class:`OracleForecaster`: the day's own future, an upper bound for analysis only.

    forecaster = make_forecaster("history", training_days=past_days, bin_s=900.0)
    forecaster.forecast(now, arrival, today)       # arrival: (m,) or (k, m) seconds of the day
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from evcd.forecast.timeline import OccupancyTimeline
from evcd.utils.validation import check_choice, check_real, require

#: Seconds between two samples of a timeline (history means, trend lines).
SAMPLE_S = 60.0


def sample_times(known_until: float, sample_s: float) -> np.ndarray:
    """The times ``0, sample_s, 2 sample_s, ...`` up to ``known_until`` (none where it is < 0)."""
    if known_until < 0:
        return np.empty(0)
    times = sample_s * np.arange(math.floor(known_until / sample_s + 1e-9) + 1)
    return times[times <= known_until]


def _same_stations(stations: tuple[str, ...], today: OccupancyTimeline, owner: str) -> None:
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
        _same_stations(self.stations, today, self.name)
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


class SessionsForecaster(Forecaster):
    """The vehicles at the station now, less those whose charging session will likely have ended by the
    EV's arrival, plus the vehicles expected to arrive by then (what a charge point operator knows: the
    queue, and when each session in progress began).

    At ``now``, for an arrival ``h = arrival - now`` seconds later at station ``j``:

    - the vehicles waiting there now (no charging point yet) are all still there;
    - a session in progress for ``e`` seconds is still going with probability ``S(e + h) / S(e)``,
      ``S(x)`` the share of the training days' charging sessions longer than ``x`` (0 where no
      training session lasted ``e``);
    - the vehicles arriving by then are Poisson with mean ``history_weight * A_hist + (1 -
      history_weight) * A_today``: ``A_hist`` the training days' mean arrivals at ``j`` over
      ``[now, arrival]`` (a rate per time-of-day bin of ``bin_s``; the last bin's after the last), and
      ``A_today`` today's rate over the last ``window_s`` (clipped at midnight; the history alone at
      ``now = 0`` or ``window_s = 0``) times ``h``; each is assumed to stay until the arrival.

    The forecast is the median of that count (``statistic="median"``, the integer that minimises the
    expected absolute error) or its mean (``"mean"``).

    Args:
        bin_s: the time-of-day bin of the training days' arrival rate (s), > 0.
        window_s: the span of today's recent arrivals the current rate is read from (s), >= 0.
        history_weight: the weight of the training days' rate against today's, in [0, 1].
        statistic: ``"median"`` or ``"mean"``.
    """

    name: ClassVar[str] = "sessions"
    needs_days: ClassVar[bool] = True
    reads_today: ClassVar[bool] = True
    STATISTICS: ClassVar[tuple[str, ...]] = ("median", "mean")

    def __init__(
        self,
        bin_s: float = 900.0,
        window_s: float = 3600.0,
        history_weight: float = 0.5,
        statistic: str = "median",
    ) -> None:
        self.bin_s = check_real("bin_s", bin_s, low=0.0, low_open=True)
        self.window_s = check_real("window_s", window_s, low=0.0)
        self.history_weight = check_real("history_weight", history_weight, low=0.0, high=1.0)
        self.statistic = check_choice("statistic", statistic, self.STATISTICS)
        self.stations: tuple[str, ...] | None = None
        self._durations: np.ndarray | None = None  # sorted charging durations of the training days
        self._rates = np.zeros((1, 0))  # (bins, m) arrivals per second
        self._cumulative = np.zeros((1, 0))  # (bins, m) expected arrivals before each bin's start

    def fit(self, days: Sequence[OccupancyTimeline]) -> SessionsForecaster:
        """Learn the charging durations and the arrival rates of ``days``; returns self.

        Raises:
            ValueError: no days, days with other stations, or no charging session that ended in them.
        """
        days = list(days)
        stations = training_stations(days, self.name)
        durations = np.sort(np.concatenate([day.charge_durations() for day in days]))
        require(
            durations.size > 0,
            "the training days have no charging session that ended: the sessions forecaster learns "
            "how long a charge lasts from them",
        )
        n_bins = max(math.floor(max(d.known_until, 0.0) / self.bin_s) + 1 for d in days)
        counts = np.zeros((n_bins, len(stations)))
        for day in days:
            for j, times in enumerate(day.arrival_times()):
                bins = np.clip(np.floor(times / self.bin_s), 0, n_bins - 1).astype(np.int64)
                np.add.at(counts[:, j], bins, 1.0)
        self._rates = counts / (self.bin_s * len(days))
        self._cumulative = np.vstack([np.zeros(len(stations)), np.cumsum(counts / len(days), axis=0)[:-1]])
        self._durations = durations
        self.stations = stations
        return self

    def survival(self, seconds: np.ndarray | float) -> np.ndarray:
        """``S(x)``: the share of the training days' charging sessions that lasted longer than ``x``."""
        require(
            self._durations is not None, "a sessions forecaster needs training days: call fit(days) first"
        )
        assert self._durations is not None
        x = np.asarray(seconds, dtype=np.float64)
        return 1.0 - np.searchsorted(self._durations, x, side="right") / self._durations.size

    def expected_history_arrivals(self, t: np.ndarray) -> np.ndarray:
        """The training days' mean arrivals at each station from midnight to ``t`` (shape ``(k, m)``)."""
        n_bins = len(self._rates)
        bins = np.clip(np.floor(t / self.bin_s), 0, n_bins - 1).astype(np.int64)
        columns = np.arange(t.shape[1])
        into = np.maximum(t - bins * self.bin_s, 0.0)
        return self._cumulative[bins, columns] + self._rates[bins, columns] * into

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        self.survival(0.0)  # refuses an unfitted forecaster
        assert self.stations is not None
        _same_stations(self.stations, today, self.name)
        horizon = arrival - now
        since = today.charging_since(now)
        waiting = today.at(now) - np.array([len(x) for x in since])
        history = self.expected_history_arrivals(arrival) - self.expected_history_arrivals(
            np.full_like(arrival, now)
        )
        span = min(self.window_s, now)
        if span > 0:
            recent = np.array(
                [np.count_nonzero((a > now - span) & (a <= now)) for a in today.arrival_times()]
            )
            expected = self.history_weight * history + (1.0 - self.history_weight) * horizon * recent / span
        else:  # no recent span to read a rate from: the history alone
            expected = history
        out = np.empty_like(arrival)
        for j, starts in enumerate(since):
            elapsed = now - starts  # (n,)
            alive = self.survival(elapsed)
            later = self.survival(elapsed[None, :] + horizon[:, j, None])  # (k, n)
            stay = np.where(alive > 0, later / np.where(alive > 0, alive, 1.0), 0.0)
            for i in range(arrival.shape[0]):
                out[i, j] = waiting[j] + self._statistic(stay[i], float(expected[i, j]))
        return out

    def _statistic(self, stay: np.ndarray, mean_arrivals: float) -> float:
        """The median (or mean) of Bernoulli(``stay``) sessions plus Poisson(``mean_arrivals``) arrivals."""
        if self.statistic == "mean":
            return float(stay.sum()) + mean_arrivals
        pmf = np.ones(1)
        for p in stay:
            pmf = np.convolve(pmf, (1.0 - p, p))
        top = math.ceil(mean_arrivals + 10.0 * math.sqrt(mean_arrivals) + 10.0)
        poisson = np.empty(top + 1)
        poisson[0] = math.exp(-mean_arrivals)
        for n in range(1, top + 1):
            poisson[n] = poisson[n - 1] * mean_arrivals / n
        cdf = np.cumsum(np.convolve(pmf, poisson))
        return float(np.searchsorted(cdf, 0.5 - 1e-12))


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
        _same_stations(self.day.stations, today, self.name)
        return self.day.at_each(arrival, clip=True)


FORECASTERS: dict[str, type[Forecaster]] = {
    f.name: f
    for f in (HistoryForecaster, TrendForecaster, AnomalyForecaster, SessionsForecaster, OracleForecaster)
}
#: The settings each forecaster takes by name.
SETTINGS: dict[str, tuple[str, ...]] = {
    "history": ("bin_s", "sample_s"),
    "trend": ("window_s", "sample_s"),
    "anomaly": ("bin_s", "sample_s", "max_lag_s"),
    "sessions": ("bin_s", "window_s", "history_weight", "statistic"),
    "oracle": ("day",),
}


def make_forecaster(
    name: str, training_days: Sequence[OccupancyTimeline] = (), **settings: Any
) -> Forecaster:
    """A forecaster by name: ``"history"``, ``"anomaly"`` or ``"sessions"`` (fitted on
    ``training_days``), ``"trend"`` or ``"oracle"`` (needs ``day=`` the played day's timeline);
    ``settings`` go to its constructor.

    Raises:
        ValueError: an unknown name or setting (listing the allowed ones), ``"history"`` or
            ``"anomaly"`` without training days, ``"oracle"`` without ``day``.
    """
    check_choice("forecaster", name, tuple(FORECASTERS))
    unknown = sorted(set(settings) - set(SETTINGS[name]))
    require(not unknown, f"settings {unknown} for the {name} forecaster: it takes {list(SETTINGS[name])}")
    cls = FORECASTERS[name]
    if cls.needs_days:
        require(
            len(training_days) > 0,
            f"the {name} forecaster needs training days (timelines of past days); none were given",
        )
        return cls(**settings).fit(training_days)  # type: ignore[attr-defined]
    if name == "oracle":
        require("day" in settings, "the oracle forecaster needs day= the timeline of the day it plays")
    return cls(**settings)
