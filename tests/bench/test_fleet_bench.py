"""The fleet benchmark on the grid: the overhead ratio and the learning rate are measured, not assumed."""

from __future__ import annotations

import pytest

from evcd.agents.dqn import DQNConfig
from evcd.bench.fleet import fleet_learning_rate, fleet_overhead
from tests.conftest import FLEET_DEMAND, FLEET_WINDOW

pytestmark = pytest.mark.slow  # every test here takes seconds


def test_fleet_overhead_and_learning_rate_on_the_grid(grid_env_dir, env_cache, one_torch_thread) -> None:
    """The overhead compares like with like: the day alone is simulated over the very span of the fleet
    episode, which runs until its last guided EV is done; the learning rate is timed while the learner
    really learns."""
    kwargs = {"scenario": grid_env_dir, "cache_dir": env_cache, "demand": FLEET_DEMAND,
              "departure_window": FLEET_WINDOW, "guided_share": 1.0}  # fmt: skip
    out = fleet_overhead(kwargs, episodes=1)
    (row,) = out["episodes"]
    assert row["fleet_s"] > 0 and row["alone_s"] > 0 and row["decisions"] > row["guided"] >= 10
    assert row["alone_span_s"] == row["sim_span_s"] > FLEET_WINDOW[1] - FLEET_WINDOW[0]
    rate = fleet_learning_rate({**kwargs, "reward": "time"}, DQNConfig(hidden=(16,), learning_starts=10), 1)
    assert rate["transitions"] > 10 and rate["gradient_steps"] > 0
    assert rate["fleet_transitions_per_second"] > 0
