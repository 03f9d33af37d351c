"""A forecast from the stations' charging sessions: the vehicles there now, less the sessions likely to
end before the EV's arrival (given how long each has charged), plus the arrivals expected by then.

    sessions = SessionsForecaster().fit(training_days)          # or make_forecaster("sessions", days)
    sessions.forecast(now, arrival, today)                      # the median count at each arrival
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from evcd.forecast.forecasters import Forecaster, same_stations, training_stations
from evcd.forecast.timeline import OccupancyTimeline
from evcd.utils.validation import check_choice, check_real, require


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
        durations = self._fitted()
        x = np.asarray(seconds, dtype=np.float64)
        return 1.0 - np.searchsorted(durations, x, side="right") / durations.size

    def _fitted(self) -> np.ndarray:
        """The training days' sorted charging durations; refuses a forecaster not fitted yet."""
        require(
            self._durations is not None, "a sessions forecaster needs training days: call fit(days) first"
        )
        assert self._durations is not None
        return self._durations

    def expected_history_arrivals(self, t: np.ndarray) -> np.ndarray:
        """The training days' mean arrivals at each station from midnight to ``t`` (shape ``(k, m)``)."""
        n_bins = len(self._rates)
        bins = np.clip(np.floor(t / self.bin_s), 0, n_bins - 1).astype(np.int64)
        columns = np.arange(t.shape[1])
        into = np.maximum(t - bins * self.bin_s, 0.0)
        return self._cumulative[bins, columns] + self._rates[bins, columns] * into

    def _predict(self, now: float, arrival: np.ndarray, today: OccupancyTimeline) -> np.ndarray:
        self._fitted()
        assert self.stations is not None
        same_stations(self.stations, today, self.name)
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
