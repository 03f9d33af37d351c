"""The observation options on the fleet (``observe=[route_time, forecast]``): each agent's ``F`` is the
forecaster's count at its own arrival, after ``H``; the forecast rule dispatches a fleet on it."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.env.observation import FORECAST_HORIZON_S
from evcd.forecast import OccupancyTimeline, make_forecaster

OBSERVE = ["route_time", "forecast"]


def test_each_agents_forecast_is_the_trend_at_its_own_arrival(make_fleet):
    """Layout [D, N, Z, H, T, F]; at every tick, F of every agent is the trend (on the day's records up
    to now) at now + its own T (clipped at the horizon): agents elsewhere get other counts."""
    env = make_fleet(observe=OBSERVE, forecaster={"name": "trend", "window_s": 600})
    assert env.layout == "DNZHTF"
    obs, _ = env.reset(seed=0)
    ids = [st.id for st in env.stations]
    m = len(ids)
    trend = make_forecaster("trend", window_s=600)
    checked, differ = 0, False
    while env.agents and not (differ and checked >= 10):
        now = env.simulation.time
        today = OccupancyTimeline.from_records(env.simulation.controller.records, ids, known_until=now)
        rows = [obs[a] for a in env.agents]
        for agent, row in zip(env.agents, rows, strict=True):
            t = row[4 * m : 5 * m]
            np.testing.assert_allclose(t, env.guided[agent].obs.extra["T"])
            expected = trend.forecast(now, now + np.minimum(t, FORECAST_HORIZON_S), today)
            np.testing.assert_allclose(row[5 * m :], expected, rtol=1e-5)
            checked += 1
        differ = differ or any(not np.allclose(r[5 * m :], rows[0][5 * m :]) for r in rows[1:])
        obs, *_ = env.step({})  # every agent keeps its station
    assert checked >= 10 and differ


@pytest.mark.slow
def test_the_forecast_rule_dispatches_a_fleet(make_fleet):
    env = make_fleet(observe=["forecast"], forecaster="trend")
    agent = make_agent_for_env("queue_forecast", env, np.random.default_rng(0))
    obs, _ = env.reset(seed=1)
    decisions = 0
    while env.agents:
        rows = np.stack([obs[a] for a in env.agents])
        actions = agent.decide(rows, [None] * len(rows))
        # the rule's choice is queue_aware's estimate with the forecast count in place of the queue now
        estimate = agent.estimate(rows)
        np.testing.assert_array_equal(actions, np.argmin(estimate, axis=-1))
        obs, *_ = env.step(dict(zip(env.agents, actions.tolist(), strict=True)))
        decisions += len(rows)
    assert agent.layout == "DNZHF" and decisions > 0
    assert any(o.get("reason") == "charging" for o in env.outcomes())
