"""evaluate_policy: any function of an observation played on an experiment's evaluation episodes
beside evcd's rules, on the same episodes, with evcd's statistics (the grid, real SUMO)."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.experiments import evaluate_policy


@pytest.mark.slow
def test_a_policy_that_is_greedy_ties_greedy_on_every_episode(script_overrides) -> None:
    """The policy "nearest station by road" (D, the first of the three blocks) is greedy: on the same
    episodes every pair is equal and the paired difference is exactly 0; queue_aware is paired the same
    way."""

    def nearest(obs: np.ndarray) -> int:
        return int(np.argmin(obs[: obs.size // 3]))

    report = evaluate_policy(nearest, experiment="peak", episodes=3, seed=1, rules=("greedy", "queue_aware"),
                             overrides=script_overrides)  # fmt: skip
    policy, greedy = report.results["policy"], report.results["greedy"]
    assert [r.seed for r in policy.rows] == [r.seed for r in greedy.rows] == [r.seed for r in report.results[
        "queue_aware"].rows]  # fmt: skip
    assert [r.travel_time for r in policy.rows] == [r.travel_time for r in greedy.rows]
    same = report.paired["greedy"]
    assert same["mean_difference"] == 0.0 and same["equal"] == same["pairs"] == policy.summary.completed
    other = report.paired["queue_aware"]
    assert other["pairs"] > 0 and other["agent_mean"] == pytest.approx(policy.summary.mean_travel_time)
    assert report.summary["greedy"] == greedy.summary


@pytest.mark.slow
def test_a_policy_that_returns_no_station_is_named(script_overrides) -> None:
    with pytest.raises(ValueError, match=r"the policy returned 7: it must return a station index in 0\.\.2"):
        evaluate_policy(lambda obs: 7, episodes=1, rules=(), overrides=script_overrides)
