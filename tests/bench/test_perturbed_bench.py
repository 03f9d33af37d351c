"""The perturbed suite of the benchmark (evcd.bench.perturbed) on the grid: both days built in
turns into empty caches, the ratio computed from the same run's builds, the events drawn."""

from __future__ import annotations

import math

import pytest

from evcd.bench.perturbed import perturbed_build_cost
from tests.conftest import GRID_ENV

pytestmark = pytest.mark.slow  # every test here takes seconds


def test_the_perturbed_suite_builds_both_days_in_turns(grid_env_dir, env_cache) -> None:
    world = {**GRID_ENV, "scenario": grid_env_dir, "cache_dir": env_cache}
    roads = {"incidents": {"per_day": 10.0, "start_window": [0, 3600]}, "rain": {"chance": 1.0}}
    report = perturbed_build_cost(world, roads, repeats=2)
    builds = report["builds"]
    assert [b["day"] for b in builds] == ["calm", "perturbed"] * 2 and all(b["wall_s"] > 0 for b in builds)
    calm = sum(b["wall_s"] for b in builds if b["day"] == "calm")
    hit = sum(b["wall_s"] for b in builds if b["day"] == "perturbed")
    assert math.isclose(report["perturbed_build_ratio"], hit / calm, rel_tol=0.01)
    assert report["events"]["incidents"] > 0 and report["events"]["rain"] == 1
