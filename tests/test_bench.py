"""The benchmark runs end to end on a small scenario and reports its ratios (no timing asserts)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from evcd.bench import run_bench
from evcd.scenario.demand import DemandConfig
from tests.scenario.conftest import make_grid_scenario

ROOT = Path(__file__).resolve().parents[1]
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
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench.py"), "--quick", "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert out.read_text() == "{}"


def test_bench_script_times_the_replay_buffer(tmp_path):
    out = tmp_path / "bench.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench.py"), "--suite", "replay", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(out.read_text())["summary"]
    assert 0 < summary["per_transition_us"] < summary["per_sample_update_us"] == summary["replay_batch_us"]
    assert summary["goals"]["per_sample_update_us"] == "<= 100"
