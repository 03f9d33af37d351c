"""The replay benchmark times exactly the buffer's own work: each timed interval holds one ``sample``
or one ``update_priorities`` call, averaged per batch (checked with a clock that counts the calls;
no timing asserts)."""

from __future__ import annotations

import math

from evcd.agents.replay import PrioritizedReplayBuffer
from evcd.bench.replay import time_replay


def test_each_interval_holds_one_sample_or_one_priority_update(monkeypatch):
    calls = {"sample": 0, "update": 0, "sizes": []}
    sample, update = PrioritizedReplayBuffer.sample, PrioritizedReplayBuffer.update_priorities

    def counted_sample(self, batch_size, rng, beta):
        calls["sample"] += 1
        calls["sizes"].append((len(self), batch_size))
        return sample(self, batch_size, rng, beta)

    def counted_update(self, indices, td_errors):
        calls["update"] += 1
        return update(self, indices, td_errors)

    monkeypatch.setattr(PrioritizedReplayBuffer, "sample", counted_sample)
    monkeypatch.setattr(PrioritizedReplayBuffer, "update_priorities", counted_update)
    # the "time" is 1 s per sample and 100 s per priority update done so far
    result = time_replay(capacity=64, batch_size=8, obs_dim=3, iterations=30, seed=1,
                         clock=lambda: calls["sample"] + 100.0 * calls["update"])  # fmt: skip
    assert result["replay_sample_us"] == 1e6 and result["replay_update_us"] == 1e8
    assert result["per_sample_update_us"] == result["replay_batch_us"] == 1e6 + 1e8
    assert result["per_transition_us"] == (1e6 + 1e8) / 8
    assert (result["capacity"], result["batch_size"]) == (64, 8)
    # 20 warm-up rounds and 30 timed ones, each on a full buffer, batches of 8
    assert calls["sample"] == 50 and set(calls["sizes"]) == {(64, 8)}
    assert calls["update"] == 1 + 50  # the initial priorities, then one per round


def test_time_replay_on_the_real_clock_reports_positive_finite_numbers():
    result = time_replay(capacity=64, batch_size=8, obs_dim=3, iterations=20, seed=1)
    for key, value in result.items():
        assert math.isfinite(value) and value > 0, key
