"""The benchmark runs end to end on a small scenario and reports its ratios (no timing asserts)."""

from __future__ import annotations

import json
import math

import pytest

from evcd.bench.protocols import run_bench
from evcd.scenario.demand import DemandConfig
from tests.conftest import make_grid_scenario, run_script

pytestmark = pytest.mark.slow  # every test here takes seconds

SMALL = DemandConfig(cars_per_day=1500, evs=150, min_trip_m=500.0, charging_share=0.5)


def test_bench_measures_every_ratio(tmp_path):
    scenario = make_grid_scenario(tmp_path / "grid")
    kwargs = {"scenario": scenario, "evs": 150, "demand": SMALL, "departure_window": (25_200.0, 26_400.0)}
    result = run_bench(kwargs, fast_episodes=3, paper_episodes=1, cache_dir=tmp_path / "cache",
                       paper_day_end=27_000.0)  # fmt: skip
    s = result.summary()
    assert len(result.fast) == 3 and len(result.paper) == 1 and len(result.raw_sumo_s) == 3
    for key in ("episode_speedup_vs_paper", "overhead_vs_raw_sumo", "snapshot_build_s"):
        assert s[key] is not None and s[key] > 0, key
    # the fast episodes started from the snapshot before their departure, the paper one from 00:00
    for e in result.fast:
        assert e.start_snapshot <= e.departure < e.start_snapshot + 300.0
        assert e.load_s > 0
    assert result.paper[0].seed == result.fast[0].seed
    assert s["fast_vs_paper_abs_dT_s"]["n"] <= 1
    json.dumps(s)  # serialisable


def test_bench_script_refuses_to_overwrite(tmp_path):
    out = tmp_path / "bench.json"
    out.write_text("{}")
    proc = run_script("bench.py", "--quick", "--out", str(out), timeout=120)
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert out.read_text() == "{}"


def test_bench_script_times_the_replay_buffer(tmp_path):
    out = tmp_path / "bench.json"
    proc = run_script("bench.py", "--suite", "replay", "--out", str(out), timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(out.read_text())["summary"]
    # the documented setting: a batch of 32 from a full buffer of 10,000
    assert (summary["capacity"], summary["batch_size"]) == (10_000, 32)
    for key in ("per_sample_update_us", "per_transition_us", "replay_sample_us", "replay_update_us"):
        assert math.isfinite(summary[key]) and summary[key] > 0, key
    assert summary["goals"]["per_sample_update_us"] == "<= 100"
