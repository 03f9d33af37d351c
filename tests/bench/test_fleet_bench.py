"""The fleet benchmark on the grid: the overhead ratio and the learning rate are measured, not assumed."""

from __future__ import annotations

import pytest

from evcd.agents.dqn import DQNConfig
from evcd.bench.fleet import fleet_learning_rate, fleet_overhead
from tests.conftest import FLEET_DEMAND, FLEET_WINDOW

pytestmark = pytest.mark.slow  # every test here takes seconds


def test_fleet_overhead_and_learning_rate_on_the_grid(grid_env_dir, env_cache, one_torch_thread) -> None:
    kwargs = {"scenario": grid_env_dir, "cache_dir": env_cache, "demand": FLEET_DEMAND,
              "departure_window": FLEET_WINDOW, "guided_share": 1.0}  # fmt: skip
    out = fleet_overhead(kwargs, episodes=1)
    (row,) = out["episodes"]
    assert row["fleet_s"] > 0 and row["alone_s"] > 0 and row["decisions"] > row["guided"] >= 10
    assert out["fleet_overhead"] == pytest.approx(row["fleet_s"] / row["alone_s"], rel=1e-2)
    assert row["sim_span_s"] > FLEET_WINDOW[1] - FLEET_WINDOW[0]  # run until every guided EV is done
    rate = fleet_learning_rate({**kwargs, "reward": "time"}, DQNConfig(hidden=(16,), learning_starts=10), 1)
    assert (
        rate["transitions"] > 0
        and rate["fleet_transitions_per_second"] == rate["transitions"] / rate["wall_s"]
    )
