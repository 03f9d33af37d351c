"""The vector suite of the benchmark (evcd.bench.vector) on the grid: every figure measured in one
run, the sweep's episodes replayed alone."""

from __future__ import annotations

import math

import pytest

from evcd.bench.vector import sweep_benchmark
from tests.conftest import GRID_ENV

pytestmark = pytest.mark.slow  # every test here takes seconds


def test_the_vector_suite_measures_speed_and_equivalence_in_one_run(grid_env_dir, env_cache) -> None:
    world = {**GRID_ENV, "scenario": grid_env_dir, "cache_dir": env_cache, "reward": "time"}
    report = sweep_benchmark(world, num_envs=4, steps=30, single_episodes=5, replay=10)
    sweep, single, two = report["sweep"], report["single"], report["make_vector_env_2"]
    assert sweep["decisions"] == 120 and sweep["episodes"] >= 10
    for figures in (sweep, single, two):
        assert figures["decisions_per_s"] > 0 and figures["wall_s"] > 0
    assert math.isclose(report["speedup"], sweep["decisions_per_s"] / single["decisions_per_s"])
    eq = report["equivalence"]
    assert eq["replayed"] == 10 and 0 < eq["pairs"] <= 10 and eq["mean_abs_difference_s"] >= 0
