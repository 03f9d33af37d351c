"""The forecasters (history, trend, anomaly, sessions, oracle), make_forecaster and the error table,
every value hand-computed on toy days of a few visits."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

from evcd.forecast import (
    AnomalyForecaster,
    Forecaster,
    HistoryForecaster,
    OccupancyTimeline,
    OracleForecaster,
    SessionsForecaster,
    TrendForecaster,
    forecast_errors,
    format_mae_table,
    make_forecaster,
)


def day(visits: list[tuple[str, float, float | None]], known_until: float, stations=("a", "b")):
    """A timeline of ``(station, arrival, release)`` visits."""
    records = [
        {"station": s, "arrival_time": float(a), "release_time": None if r is None else float(r)}
        for s, a, r in visits
    ]
    return OccupancyTimeline.from_records(records, stations, known_until)


# ------------------------------------------------------------------------------------------ history
#: Two training days sampled every 60 s over [0, 1200]; bins of 600 s: bin 0 holds 0..540 (10 samples
#: a day), bin 1 600..1140 (10), bin 2 only 1200 (1).
DAY1 = day([("a", 0, 600), ("b", 300, 900)], 1200.0)
DAY2 = day([("a", 120, None), ("b", 600, 1200), ("b", 630, None)], 1200.0)
# a: day 1 has 1 at the 10 samples of bin 0; day 2 has 1 from 120 (8 samples of bin 0, all later ones)
#    bin 0: (10 + 8) / 20, bin 1: (0 + 10) / 20, bin 2: (0 + 1) / 2
# b: day 1 has 1 at 300..540 (5 samples of bin 0) and 600..840 (5 of bin 1); day 2 has 1 at 600, 2 at
#    660..1140 (9 samples), 1 at 1200 (the visit released at 1200 is gone)
#    bin 0: 5 / 20, bin 1: (5 + 1 + 18) / 20, bin 2: (0 + 1) / 2
MEANS = [[0.9, 0.25], [0.5, 1.2], [0.5, 0.5]]


def test_the_history_forecast_is_the_mean_of_the_training_days_in_the_arrivals_bin():
    history = HistoryForecaster(bin_s=600.0).fit([DAY1, DAY2])
    assert history.bin_means == pytest.approx(np.array(MEANS))
    today = day([("a", 0, None)], 0.0)  # its counts are not read
    assert history.forecast(0.0, [300.0, 300.0], today) == pytest.approx([0.9, 0.25])
    batch = history.forecast(0.0, [[600.0, 1199.0], [5000.0, 0.0]], today)
    assert batch.dtype == np.float64 and batch.shape == (2, 2)
    assert batch == pytest.approx(np.array([[0.5, 1.2], [0.5, 0.25]]))  # 5000: after the last bin


def test_a_history_bin_without_samples_takes_the_nearest_one_the_earlier_on_a_tie():
    # bins of 30 s, samples every 60 s: bins 0, 2, 4 hold the samples 0, 60, 120 (0, 1, 1 vehicles)
    history = HistoryForecaster(bin_s=30.0).fit([day([("a", 60, None)], 120.0, stations=("a",))])
    assert history.bin_means[:, 0].tolist() == [0.0, 0.0, 1.0, 1.0, 1.0]
    today = day([], 0.0, stations=("a",))
    assert history.forecast(0.0, [[45.0], [95.0]], today).tolist() == [[0.0], [1.0]]


def test_a_history_forecaster_needs_training_days():
    with pytest.raises(ValueError, match="needs training days"):
        HistoryForecaster().fit([])
    with pytest.raises(ValueError, match="needs training days"):
        HistoryForecaster().forecast(0.0, [10.0, 10.0], DAY1)
    with pytest.raises(ValueError, match="same stations"):
        HistoryForecaster().fit([DAY1, day([], 1200.0, stations=("b", "a"))])
    fitted = HistoryForecaster().fit([DAY1])
    with pytest.raises(ValueError, match=r"today's stations \['b', 'a'\]"):
        fitted.forecast(0.0, [10.0, 10.0], day([], 100.0, stations=("b", "a")))
    with pytest.raises(ValueError, match="bin_s=0"):
        HistoryForecaster(bin_s=0.0)


# ------------------------------------------------------------------------------------------ anomaly
#: One station, samples every 60 s over [0, 240], one bin. Day A: a vehicle over [0, 120): 1 1 0 0 0
#: (mean 0.4); day B: one from 120: 0 0 1 1 1 (mean 0.6). Each day's deviations are from the OTHER
#: day's mean: A 0.4 0.4 -0.6 -0.6 -0.6, B -0.4 -0.4 0.6 0.6 0.6.
#: beta(0) = 1; beta(60) = 2 x (.16 - .24 + .36 + .36) / 2 x (.16 + .16 + .36 + .36) = 1.28 / 2.08;
#: beta(120) = 2 x (-.24 - .24 + .36) / ... < 0 -> 0; likewise 180 and 240.
DAY_A = day([("a", 0, 120)], 240.0, stations=("a",))
DAY_B = day([("a", 120, None)], 240.0, stations=("a",))
BETA_60 = 1.28 / 2.08


def test_the_anomaly_fits_the_lag_coefficients_of_the_days_deviations_from_the_other_days():
    anomaly = AnomalyForecaster(bin_s=1e6, max_lag_s=240.0).fit([DAY_A, DAY_B])
    assert anomaly.lags.tolist() == [0.0, 60.0, 120.0, 180.0, 240.0]
    assert anomaly.beta == pytest.approx([1.0, BETA_60, 0.0, 0.0, 0.0])
    # the history is both days' mean, 0.5; today has 1 vehicle at 60: a deviation of +0.5, carried
    # fully at horizon 0, by beta(60) at 60, linearly between, not at all from 120 or past max_lag_s
    today = day([("a", 0, None)], 60.0, stations=("a",))
    got = anomaly.forecast(60.0, [[60.0], [90.0], [120.0], [180.0], [400.0]], today)[:, 0]
    assert got == pytest.approx([1.0, 0.5 + 0.5 * (1 + BETA_60) / 2, 0.5 + 0.5 * BETA_60, 0.5, 0.5])
    # it reads today only up to now: a vehicle arriving after now changes nothing
    later = day([("a", 0, None), ("a", 90, None)], 60.0, stations=("a",))
    assert anomaly.forecast(60.0, [120.0], later) == pytest.approx(got[2:3])


def test_one_training_day_gives_its_deviations_from_itself():
    # A alone: mean 0.4, deviations 0.6 0.6 -0.4 -0.4 -0.4; beta(60) = (.36 - .24 + .16 + .16) / (.36 +
    # .36 + .16 + .16) = .44 / 1.04
    anomaly = AnomalyForecaster(bin_s=1e6, max_lag_s=60.0).fit([DAY_A])
    assert anomaly.beta == pytest.approx([1.0, 0.44 / 1.04])
    assert anomaly.stations == ("a",)


def test_an_anomaly_forecaster_needs_training_days_and_a_lag_of_at_least_zero():
    with pytest.raises(ValueError, match=r"the anomaly forecaster needs training days .* none were given"):
        make_forecaster("anomaly")
    with pytest.raises(ValueError, match="max_lag_s=-1"):
        AnomalyForecaster(max_lag_s=-1.0)
    with pytest.raises(ValueError, match="call fit"):
        AnomalyForecaster().forecast(0.0, [10.0], DAY_A)
    made = make_forecaster("anomaly", [DAY_A, DAY_B], bin_s=1e6, max_lag_s=60.0)
    assert isinstance(made, AnomalyForecaster) and made.beta == pytest.approx([1.0, BETA_60])


# ------------------------------------------------------------------------------------------ trend
#: a rises by one vehicle a minute (arrivals at 60, 120, ..., 900, none leave); b falls by one a
#: minute from 10 at 0 (releases at 60, ..., 600). Known until 1000.
RISING = [("a", 60.0 * k, None) for k in range(1, 16)]
FALLING = [("b", 0.0, 60.0 * k) for k in range(1, 11)]
TODAY = day(RISING + FALLING, 1000.0)


def test_the_trend_extrapolates_the_line_through_the_last_window_and_clips_at_zero():
    trend = TrendForecaster(window_s=600.0)
    # samples 0, 60, ..., 600: a = t / 60, b = 10 - t / 60
    assert trend.forecast(600.0, [600.0, 600.0], TODAY) == pytest.approx([10.0, 0.0], abs=1e-12)
    assert trend.forecast(600.0, [900.0, 1140.0], TODAY) == pytest.approx([15.0, 0.0], abs=1e-12)
    # b's line is at 10 - 630 / 60 = -0.5 at 630: clipped to 0; a's at 10.5
    out = trend.forecast(600.0, [[630.0, 630.0], [1200.0, 600.0]], TODAY)
    assert out == pytest.approx(np.array([[10.5, 0.0], [20.0, 0.0]]), abs=1e-12)
    # b at 300 samples over [0, 300]: 10, 9, ..., 5 -> at 420: 3
    assert trend.forecast(300.0, [300.0, 420.0], TODAY) == pytest.approx([5.0, 3.0], abs=1e-12)


def test_the_trend_reads_today_only_up_to_now():
    trend = TrendForecaster()
    full = trend.forecast(600.0, [900.0, 900.0], TODAY)
    assert trend.forecast(600.0, [900.0, 900.0], TODAY.truncated(600.0)).tolist() == full.tolist()


def test_the_trends_window_is_clipped_at_midnight_and_too_few_samples_give_the_occupancy_now():
    # now = 120: samples at 0, 60, 120 only (a: 0, 1, 2; b: 10, 9, 8) -> at 300: a 5, b 5
    assert TrendForecaster(window_s=900.0).forecast(120.0, [300.0, 300.0], TODAY) == pytest.approx(
        [5.0, 5.0], abs=1e-12
    )
    # one sample: the occupancy now (a: 10, b: 0 at 600; a: 0, b: 10 at 30)
    assert TrendForecaster(window_s=30.0).forecast(600.0, [[900.0, 900.0]], TODAY).tolist() == [[10.0, 0.0]]
    assert TrendForecaster(window_s=900.0).forecast(30.0, [900.0, 900.0], TODAY).tolist() == [0.0, 10.0]


# ------------------------------------------------------------------------------------------ oracle
def test_the_oracle_forecasts_the_days_own_future_exactly():
    oracle = OracleForecaster(TODAY)
    arrival = np.array([[300.0, 300.0], [930.0, 590.0], [5000.0, 5000.0]])
    # a: 5 at 300, 15 from 900; b: 5 at 300, 1 at 590, 0 from 600; 5000: the value at 1000
    out = oracle.forecast(200.0, arrival, TODAY.truncated(200.0))
    assert out.dtype == np.float64 and out.tolist() == [[5.0, 5.0], [15.0, 1.0], [15.0, 0.0]]


# ------------------------------------------------------------------------------------------ sessions
def sday(visits: list[tuple[str, float, float | None, float | None]], known_until: float):
    """A timeline of ``(station, arrival, start, release)`` visits at stations a and b."""
    records = [
        {"station": s, "arrival_time": float(a), "start_time": None if t is None else float(t),
         "release_time": None if r is None else float(r)}
        for s, a, t, r in visits
    ]  # fmt: skip
    return OccupancyTimeline.from_records(records, ("a", "b"), known_until)


#: Training sessions of 600, 400, 800 and 200 s (the one from 900 has not ended); with bins of 600 s a
#: arrives twice in bin 0 of one day and once in bin 1 of the other, b twice in bin 0.
S_DAY1 = sday([("a", 0, 0, 600), ("a", 100, 600, 1000), ("b", 300, 300, 1100)], 1200.0)
S_DAY2 = sday([("b", 0, 0, 200), ("a", 900, 900, None)], 1200.0)
#: Today at 600 (known until 700): a has sessions charging for 400 and 40 s and one vehicle waiting (the
#: arrival at 650 is after now); b one session for 150 s (the visit released at 300 is gone).
S_TODAY = sday(
    [("a", 200, 200, None), ("a", 500, None, None), ("a", 550, 560, None), ("a", 650, None, None),
     ("b", 100, 150, 300), ("b", 400, 450, None)],
    700.0,
)  # fmt: skip


def test_the_sessions_forecaster_learns_the_charging_durations_and_the_arrival_rates():
    sessions = SessionsForecaster(bin_s=600.0, window_s=600.0).fit([S_DAY1, S_DAY2])
    # durations 200, 400, 600, 800: S(x) is the share longer than x
    got = sessions.survival([0.0, 200.0, 399.0, 400.0, 700.0, 800.0])
    assert got.tolist() == [1, 0.75, 0.75, 0.5, 0.25, 0]
    # arrivals before t, means of the two days: a 2 in bin 0, 1 in bin 1 (0.5 a day); b 2 in bin 0
    t = np.array([[0.0, 0.0], [300.0, 300.0], [600.0, 600.0], [900.0, 900.0], [3000.0, 3000.0]])
    assert sessions.expected_history_arrivals(t).tolist() == [
        [0.0, 0.0], [0.5, 0.5], [1.0, 1.0], [1.25, 1.0], [1.5, 1.0]  # 3000: the last bin's rate, 0
    ]  # fmt: skip


def test_the_sessions_forecast_keeps_the_queue_ends_sessions_and_adds_arrivals_by_hand():
    fitted = [S_DAY1, S_DAY2]
    mean = SessionsForecaster(bin_s=600.0, window_s=600.0, statistic="mean").fit(fitted)
    # a at 900 (h = 300): 1 waiting; sessions at 400 s stay with S(700)/S(400) = 0.25/0.5, at 40 s with
    # S(340)/S(40) = 0.75; arrivals 0.5 * 0.25 (history over [600, 900]) + 0.5 * 300 * 3/600 (today's
    # 3 arrivals in (0, 600]) = 0.875 -> 3.125. b: session at 150 s stays with S(450)/S(150) = 0.5;
    # arrivals 0.5 * 0 + 0.5 * 300 * 2/600 = 0.5 -> 1.0
    assert mean.forecast(600.0, [900.0, 900.0], S_TODAY) == pytest.approx([3.125, 1.0])
    # at the decision time itself: every session stays, nobody arrives: the vehicles there now
    assert mean.forecast(600.0, [600.0, 600.0], S_TODAY) == pytest.approx([3.0, 1.0])
    median = SessionsForecaster(bin_s=600.0, window_s=600.0).fit(fitted)
    # a: 1 + median of Bernoulli(0.5) + Bernoulli(0.75) + Poisson(0.875): P(<= 1) = 0.306, P(<= 2) = 0.665
    # b: median of Bernoulli(0.5) + Poisson(0.5): P(0) = 0.303, P(<= 1) = 0.758
    got = median.forecast(600.0, [[900.0, 900.0], [600.0, 600.0]], S_TODAY)
    assert got.tolist() == [[3.0, 1.0], [3.0, 1.0]]
    # no recent window: the history alone (a: 1 + 1.25 + 0.25, b: 0.5)
    history_only = SessionsForecaster(bin_s=600.0, window_s=0.0, statistic="mean").fit(fitted)
    assert history_only.forecast(600.0, [900.0, 900.0], S_TODAY) == pytest.approx([2.5, 0.5])
    # a session longer than any training one ends: b's from 150 has charged 850 s at 1000
    later = sday([("b", 100, 150, None)], 1000.0)
    assert history_only.forecast(1000.0, [1000.0, 1100.0], later).tolist() == [0.0, 0.0]


def test_a_sessions_forecaster_needs_ended_sessions_and_good_settings():
    with pytest.raises(ValueError, match=r"the sessions forecaster needs training days .* none were given"):
        make_forecaster("sessions")
    with pytest.raises(ValueError, match="no charging session that ended"):
        SessionsForecaster().fit([day([("a", 0, 100)], 1200.0)])
    with pytest.raises(ValueError, match=r"history_weight=1\.5"):
        SessionsForecaster(history_weight=1.5)
    with pytest.raises(ValueError, match="statistic='mode': must be one of median, mean"):
        make_forecaster("sessions", [S_DAY1], statistic="mode")
    with pytest.raises(ValueError, match="call fit"):
        SessionsForecaster().forecast(600.0, [900.0, 900.0], S_TODAY)
    made = make_forecaster("sessions", [S_DAY1, S_DAY2], bin_s=600.0, window_s=600.0, history_weight=0.0)
    assert isinstance(made, SessionsForecaster) and made.history_weight == 0.0


# ------------------------------------------------------------------------------------------ the interface
def test_bad_forecast_input_is_refused():
    trend = TrendForecaster()
    with pytest.raises(ValueError, match=r"arrival time 500 is before now=600: arrival times must be >= now"):
        trend.forecast(600.0, [700.0, 500.0], TODAY)
    with pytest.raises(ValueError, match=r"shape \(3,\): must be \(m,\) or \(k, m\) with m=2"):
        trend.forecast(600.0, [700.0, 700.0, 700.0], TODAY)
    with pytest.raises(ValueError, match="before now=600"):
        trend.forecast(600.0, [700.0, 700.0], TODAY.truncated(500.0))
    with pytest.raises(ValueError, match="window_s=-1"):
        TrendForecaster(window_s=-1.0)


def test_make_forecaster_makes_each_by_name_and_refuses_what_it_cannot():
    history = make_forecaster("history", [DAY1, DAY2], bin_s=600.0)
    assert isinstance(history, HistoryForecaster) and history.bin_means == pytest.approx(np.array(MEANS))
    trend = make_forecaster("trend", window_s=300.0)
    assert isinstance(trend, TrendForecaster) and trend.window_s == 300.0
    oracle = make_forecaster("oracle", day=TODAY)
    assert isinstance(oracle, OracleForecaster) and oracle.day is TODAY
    with pytest.raises(ValueError, match="'arima': must be one of history, trend, anomaly, sessions, "):
        make_forecaster("arima")
    with pytest.raises(ValueError, match=r"needs training days .* none were given"):
        make_forecaster("history")
    with pytest.raises(ValueError, match="needs day="):
        make_forecaster("oracle")
    with pytest.raises(ValueError, match=r"settings \['bins'\] for the trend forecaster: it takes"):
        make_forecaster("trend", bins=3)


# ------------------------------------------------------------------------------------------ errors
#: The played day, known until 3720: a gets a vehicle at 3610 (0 at 3600, 1 at 3660 and 3720); b has
#: one until 3650 (1 at 3600, 0 at 3660 and 3720).
PLAYED = day([("a", 3610, None), ("b", 0, 3650)], 3720.0)
#: Training: a has 2 all day; b has 1 until 5400: bin 1 (3600..7140) has 30 samples of 1 in 60 -> 0.5.
TRAINING = day([("a", 0, None), ("a", 0, None), ("b", 0, 5400)], 7200.0)
WINDOW = (3540.0, 3720.0)  # decisions at 3540 (hour 0), 3600 and 3660 (hour 1)
HORIZONS = (60.0, 120.0)  # arrivals 3600, 3660 | 3660, 3720 | 3720 (3780 is after known_until)


def test_the_oracle_has_no_error_and_the_history_its_hand_computed_one():
    oracle = forecast_errors(OracleForecaster(PLAYED), [PLAYED], WINDOW, HORIZONS, every_s=60.0)
    assert oracle == [
        {"station": "a", "hour": 0, "mae": 0.0, "n": 2},
        {"station": "a", "hour": 1, "mae": 0.0, "n": 3},
        {"station": "b", "hour": 0, "mae": 0.0, "n": 2},
        {"station": "b", "hour": 1, "mae": 0.0, "n": 3},
    ]
    history = make_forecaster("history", [TRAINING], bin_s=3600.0)  # forecasts a: 2, b: 0.5 after 3600
    rows = forecast_errors(history, [PLAYED, PLAYED], WINDOW, HORIZONS, every_s=60.0)
    # a, hour 0: |2 - 0| and |2 - 1| -> 1.5; hour 1: |2 - 1| three times -> 1.0
    # b, hour 0: |0.5 - 1| and |0.5 - 0| -> 0.5; hour 1: |0.5 - 0| three times -> 0.5
    assert rows == [
        {"station": "a", "hour": 0, "mae": 1.5, "n": 4},
        {"station": "a", "hour": 1, "mae": 1.0, "n": 6},
        {"station": "b", "hour": 0, "mae": 0.5, "n": 4},
        {"station": "b", "hour": 1, "mae": 0.5, "n": 6},
    ]
    assert format_mae_table(rows) == "station    00    01\na        1.50  1.00\nb        0.50  0.50"


class Peeking(Forecaster):
    """Notes how far today is known at each forecast."""

    name: ClassVar[str] = "peeking"

    def __init__(self) -> None:
        self.seen: list[tuple[float, float]] = []

    def _predict(self, now, arrival, today):
        self.seen.append((now, today.known_until))
        return np.zeros_like(arrival)


def test_the_forecaster_sees_the_day_only_up_to_each_decision_time():
    peeking = Peeking()
    forecast_errors(peeking, [PLAYED], WINDOW, HORIZONS)
    assert peeking.seen == [(3540.0, 3540.0), (3600.0, 3600.0), (3660.0, 3660.0)]


def test_the_table_marks_missing_cells_and_bad_error_input_is_refused():
    rows = [
        {"station": "b", "hour": 7, "mae": 0.25, "n": 1},
        {"station": "a", "hour": 12, "mae": 2.0, "n": 1},
    ]
    assert format_mae_table(rows) == "station    07    12\na           -  2.00\nb        0.25     -"
    assert format_mae_table([]) == "no forecast errors (no rows)"
    oracle = OracleForecaster(PLAYED)
    with pytest.raises(ValueError, match="at least one day"):
        forecast_errors(oracle, [], WINDOW)
    with pytest.raises(
        ValueError, match=r"window=\(3720.0, 3540.0\): must be \(start, end\) with start < end"
    ):
        forecast_errors(oracle, [PLAYED], (3720.0, 3540.0))
    with pytest.raises(ValueError, match="every_s=0"):
        forecast_errors(oracle, [PLAYED], WINDOW, every_s=0.0)
    with pytest.raises(ValueError, match=r"horizons_s\[1\]=-60"):
        forecast_errors(oracle, [PLAYED], WINDOW, (60.0, -60.0))
    # no (t, h) fits in the day: no rows
    assert forecast_errors(oracle, [PLAYED], WINDOW, (600.0,)) == []
