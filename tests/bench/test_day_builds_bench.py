"""The days suite's measurement (evcd.bench.day_builds) on the grid: both builds happen, from empty caches."""

from __future__ import annotations

import pytest

from evcd.bench.day_builds import day_build_speedup
from tests.conftest import GRID_ENV


@pytest.mark.slow
def test_the_days_are_built_both_ways_and_timed(grid_env_dir):
    report = day_build_speedup({"scenario": grid_env_dir, **GRID_ENV, "demand_seeds": [3, 4]}, workers=2)
    assert report["days"] == 2 and report["workers"] == 2
    assert report["one_by_one_s"] > 0 and report["side_by_side_s"] > 0
    assert report["day_build_speedup"] == pytest.approx(report["one_by_one_s"] / report["side_by_side_s"])


def test_one_worker_or_one_day_is_refused(grid_env_dir):
    with pytest.raises(ValueError, match="workers=1: side by side needs at least 2"):
        day_build_speedup({"scenario": grid_env_dir, **GRID_ENV}, workers=1)
    with pytest.raises(ValueError, match="a world of 1 day has nothing to build side by side"):
        day_build_speedup({"scenario": grid_env_dir, **GRID_ENV, "demand_seeds": [0]}, workers=2)
