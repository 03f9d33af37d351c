"""The forecast block ``F`` (``observe=[..., forecast]``): each forecaster's values in the observation
equal the forecaster's own on the days' records (history fitted on ``forecast_days``, the trend on
the controller's records now, the anomaly and the sessions on both, the oracle on the played day's),
in both units; the forecast rule
reads it; bad input refused before SUMO."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.agents.heuristics import ForecastQueueAgent
from evcd.env.forecast_source import day_timeline
from evcd.env.observation import FORECAST_HORIZON_S
from evcd.forecast import OccupancyTimeline, make_forecaster
from evcd.sim.snapshots import DayCache, snapshot_times

OBSERVE = ["route_time", "forecast"]


def _arrival(env) -> tuple[float, np.ndarray]:
    o = env.last_observation
    now = env.simulation.time
    return now, now + np.minimum(o.extra["T"], FORECAST_HORIZON_S)


def _times(env) -> list[float]:
    return snapshot_times(env.config.departure_window, env.config.snapshot_every)


def test_the_oracle_forecasts_the_played_days_own_occupancy_at_arrival(make_env):
    """F is the played day's occupancy at now + T (clipped at the day's last snapshot), and that
    occupancy at departure is what the live controller counts."""
    env = make_env(observe=OBSERVE, forecaster="oracle", demand_seeds=(0, 1))
    assert env.layout == "DNZTF"
    ids = [st.id for st in env.stations]
    for day in (0, 1):
        env.reset(seed=5, options={"day": day})
        now, arrival = _arrival(env)
        timeline = day_timeline(env.simulation.caches[day], _times(env), ids)
        np.testing.assert_allclose(env.last_observation.extra["F"], timeline.at_each(arrival, clip=True))
        # the day's timeline is the live controller's count at departure (Z), read independently
        np.testing.assert_array_equal(timeline.at(now), env.last_observation.occupancy)


@pytest.mark.slow
def test_the_history_learns_from_the_forecast_days_only(make_env, env_cache):
    """F is the history forecaster fitted on the forecast days' timelines (days 3 and 4, not the
    played day 0), evaluated at each arrival; normalised, F is in multiples of the points."""
    env = make_env(observe=OBSERVE, forecaster={"name": "history", "bin_s": 600}, forecast_days=(3, 4))
    env.reset(seed=2)
    now, arrival = _arrival(env)
    ids = [st.id for st in env.stations]
    history = [DayCache(spec, env_cache) for spec in env.config.history_days(env.scenario)]
    assert [c.spec.demand_seed for c in history] == [3, 4]
    fitted = make_forecaster("history", [day_timeline(c, _times(env), ids) for c in history], bin_s=600)
    empty = OccupancyTimeline.from_records([], ids, known_until=now)
    expected = fitted.forecast(now, arrival, empty)
    np.testing.assert_allclose(env.last_observation.extra["F"], expected)
    scaled = make_env(observe=OBSERVE, forecaster={"name": "history", "bin_s": 600}, forecast_days=(3, 4),
                      normalize_obs=True)  # fmt: skip
    obs, _ = scaled.reset(seed=2)
    m, points = len(ids), np.array([st.points for st in scaled.stations])
    np.testing.assert_allclose(obs[4 * m :], expected / points, rtol=1e-6)


def test_the_trend_reads_todays_records_up_to_now(make_env):
    env = make_env(observe=OBSERVE, forecaster={"name": "trend", "window_s": 600})
    env.reset(seed=4)
    now, arrival = _arrival(env)
    ids = [st.id for st in env.stations]
    today = OccupancyTimeline.from_records(env.simulation.controller.records, ids, known_until=now)
    expected = make_forecaster("trend", window_s=600).forecast(now, arrival, today)
    np.testing.assert_allclose(env.last_observation.extra["F"], expected)


@pytest.mark.parametrize("name", ["anomaly", "sessions"])
def test_a_forecaster_that_learns_from_the_forecast_days_reads_todays_records_up_to_now(
    make_env, env_cache, name
):
    env = make_env(observe=OBSERVE, forecaster={"name": name, "bin_s": 600}, forecast_days=(3, 4))
    env.reset(seed=2)
    now, arrival = _arrival(env)
    ids = [st.id for st in env.stations]
    history = [DayCache(spec, env_cache) for spec in env.config.history_days(env.scenario)]
    fitted = make_forecaster(name, [day_timeline(c, _times(env), ids) for c in history], bin_s=600)
    today = OccupancyTimeline.from_records(env.simulation.controller.records, ids, known_until=now)
    expected = fitted.forecast(now, arrival, today)
    np.testing.assert_allclose(env.last_observation.extra["F"], expected)
    # today's counts matter: with an empty day the forecast would be another
    empty = OccupancyTimeline.from_records([], ids, known_until=now)
    assert today.at(now).sum() > 0
    assert not np.allclose(fitted.forecast(now, arrival, empty), expected)


def test_queue_forecast_counts_the_forecast_queue():
    """cs0 is nearer and empty now, but 4 vehicles are forecast there at arrival (2 points): the
    forecast rule goes to cs1; queue_aware, reading the queue now, to cs0."""
    rule = ForecastQueueAgent(2, np.random.default_rng(0), points=[2, 2])
    rule.layout = "DNZF"
    obs = np.array([1000.0, 3000.0, 0.0, 0.0, 0.0, 0.0, 4.0, 0.0])
    assert rule.act(obs) == 1
    plain = ForecastQueueAgent(2, np.random.default_rng(0), points=[2, 2])
    with pytest.raises(ValueError, match=r"reads the forecast block F: make the environment with observe"):
        plain.act(obs[:6])


def test_the_forecast_rule_plays_an_episode(make_env):
    env = make_env(observe=["forecast"], forecaster="trend")
    agent = make_agent_for_env("queue_forecast", env, np.random.default_rng(0))
    obs, _ = env.reset(seed=1)
    done = False
    while not done:
        obs, _, terminated, truncated, _ = env.step(agent.act(obs))
        done = terminated or truncated
    assert agent.layout == "DNZF"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"observe": ["forecast"]}, "forecaster=history needs training days: forecast_days=[...]"),
        (
            {"observe": ["forecast"], "forecaster": "anomaly"},
            "forecaster=anomaly needs training days: forecast_days=[...]",
        ),
        (
            {"observe": ["forecast"], "forecaster": "crystal_ball"},
            "the forecasters are history, trend, anomaly, sessions, oracle",
        ),
        (
            {"observe": ["forecast"], "forecaster": {"name": "sessions", "statistic": "mode"}},
            "statistic='mode': must be one of median, mean",
        ),
        ({"observe": ["forecast"], "forecaster": {"name": "trend", "bin_s": 5}}, "unknown setting 'bin_s'"),
        ({"observe": ["forecast"], "forecaster": "trend", "forecast_days": []}, "forecast_days=[]"),
        ({"observe": ["forecast"], "forecaster": "oracle", "protocol": "paper"}, "needs protocol='fast'"),
    ],
)
def test_bad_forecast_settings_are_refused_before_sumo(grid_env_dir, tmp_path, kwargs, message):
    from evcd.env import ChargingNavEnv

    with pytest.raises(ValueError, match=None) as info:
        ChargingNavEnv(scenario=grid_env_dir, cache_dir=tmp_path / "cache", **kwargs)
    assert message in str(info.value)
    assert not (tmp_path / "cache").exists()
