"""The engine benchmark's measurements, on the small grid (real SUMO; figures only sanity-checked)."""

from __future__ import annotations

import math

import pytest

from evcd.agents.dqn import DQNConfig
from evcd.bench import engines as engine_bench
from tests.conftest import GRID_ENV


@pytest.fixture
def grid_kwargs(grid_env_dir, env_cache) -> dict:
    return {"scenario": grid_env_dir, "cache_dir": env_cache, **GRID_ENV}


@pytest.mark.slow
def test_compare_engines_reports_every_policy_and_batch_size(grid_kwargs):
    out = engine_bench.compare_engines(grid_kwargs, 8, [1, 4])
    names = {"greedy", "fixed0", "fixed1", "fixed2"}
    assert set(out["single"]) == names and set(out["batched"]) == {"1", "4"}
    for b in ("1", "4"):
        assert set(out["summary"][b]) == names
        for name, s in out["summary"][b].items():
            assert len(out["batched"][b][name]["T"]) == 8
            assert 0 <= s["identical_share"] <= 1
            if name.startswith("fixed"):  # a fixed station ends where it was sent
                assert s["same_station_share"] == 1.0
            assert s["mean_abs_dT"] <= s["max_abs_dT"]
    # one target per simulation starts like the single environment: (nearly) identical
    assert out["summary"]["1"]["greedy"]["identical_share"] >= 0.75


@pytest.mark.slow
def test_rates_and_scaling_are_measured(grid_kwargs):
    rates = engine_bench.engine_rates(grid_kwargs, 2, 6, 3)
    assert rates["single"]["episodes"] == 2 and rates["batched"]["episodes"] == 6
    assert all(r["episodes_per_s"] > 0 and r["transitions"] >= r["episodes"] for r in rates.values())
    scaling = engine_bench.parallel_scaling(grid_kwargs, 4, 2)
    assert scaling["scaling"] > 0 and math.isfinite(scaling["scaling"])


def test_kept_routes_play_the_same_episodes(grid_kwargs):
    out = engine_bench.kept_routes(grid_kwargs, 6, 3)
    assert out["kept"]["episodes"] == out["found_anew"]["episodes"] == 6
    assert out["same_rows"] is True
    assert out["speedup"] > 0 and math.isfinite(out["speedup"])


def test_the_learning_rate_counts_what_going_back_in_time_cost(grid_kwargs):
    """Two batches of one day: the second starts before the first one's end, so SUMO restarts once."""
    learner = DQNConfig(hidden=(8,), learning_starts=4, batch_size=4)
    out = engine_bench.learning_rate(grid_kwargs, learner, 6, 3)
    assert out["episodes"] == 6 and out["transitions_per_s"] > 0
    assert out["going_back_restarts"] >= 1 and 0 < out["going_back_share"] < 1
    assert out["going_back_s"] == pytest.approx(out["going_back_share"] * out["wall_s"])
