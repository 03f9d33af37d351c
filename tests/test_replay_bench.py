"""The replay benchmark runs on a tiny buffer and reports every number (no timing asserts)."""

from __future__ import annotations

import math

from evcd.replay_bench import time_replay


def test_time_replay_reports_positive_finite_numbers():
    result = time_replay(capacity=64, batch_size=8, obs_dim=3, iterations=20, seed=1)
    assert set(result) == {"replay_batch_us", "per_sample_update_us", "per_transition_us", "replay_sample_us",
                           "replay_update_us", "capacity", "batch_size"}  # fmt: skip
    for key, value in result.items():
        assert math.isfinite(value) and value > 0, key
    assert result["capacity"] == 64 and result["batch_size"] == 8
    assert math.isclose(result["replay_batch_us"], result["replay_sample_us"] + result["replay_update_us"])
    assert result["per_sample_update_us"] == result["replay_batch_us"]  # one batch of 8
    assert math.isclose(result["per_transition_us"], result["replay_batch_us"] / 8)
