"""Same seed, same result, from any process: ``scripts/train.py`` on a congested grid (EVs queue for
hours at the stations, targets park and wait), batched engine, real SUMO and torch.

Each run is its own Python process with its own heap layout (address space randomisation is on):
one that builds the days in-process from an empty cache, and one that loads them from the warm
cache, started from another directory with another hash seed and an unrelated allocation first.
Both give the same training and evaluation episodes and the same network weights, to the last bit.
On 897e77b (SUMO loading an earlier snapshot into the running simulation, ``evcd.env.simulation``)
such runs gave different training results. A run killed in the middle of a batch and resumed gives
the same result too: tests/scripts/test_train_script.py (``test_a_killed_run_resumes_to_the_same_result``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from evcd.bench.determinism import ALLOCATE_FIRST
from tests.conftest import ROOT, SCRIPTS
from tests.scripts.test_train_script import final_weights, read_csv

pytestmark = pytest.mark.slow  # every test here takes seconds

#: A congested grid day: ~70 charging EVs in two hours for 3 stations of 2 points.
BUSY = [
    "evs=120", "scenario.demand.cars_per_day=800", "scenario.demand.min_trip_m=500",
    "scenario.demand.charging_share=0.6", f"scenario.demand.hourly_profile=[8,8{',0' * 22}]",
    "env.departure_window=[1200,3000]", "env.snapshot_every=300", "days.train=[0]", "days.tuning=[2]",
    "days.evaluation=[101]", "agent=dqn", "learner.hidden=[32,32]", "train.episodes=150",
    "train.checkpoint_every=50", "train.validation.every=0", "eval.episodes=10", "eval.baselines=[greedy]",
    "eval.bootstrap_resamples=200", "progress=false",
]  # fmt: skip
FILES = ("train_episodes.csv", "episodes.csv", "baseline_greedy_episodes.csv")


def train(
    out: Path,
    cache: Path,
    grid: Path,
    *extra: str,
    cwd: Path = ROOT,
    hash_seed: str = "0",
    code: str | None = None,
) -> subprocess.CompletedProcess[str]:
    """``python scripts/train.py`` (or ``python -c code``) on the congested grid, in ``cwd``."""
    cmd = [sys.executable, "-c", code] if code else [sys.executable, str(SCRIPTS / "train.py")]
    args = [*BUSY, f"scenario.path={grid}", f"env.cache_dir={cache}", f"hydra.run.dir={out}", *extra]
    env = {**os.environ, "PYTHONHASHSEED": hash_seed}
    proc = subprocess.run([*cmd, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    return proc


def assert_same_run(a: Path, b: Path) -> None:
    for name in FILES:
        rows_a, rows_b = read_csv(a / name), read_csv(b / name)
        first = next((i for i, (x, y) in enumerate(zip(rows_a, rows_b, strict=True)) if x != y), None)
        assert first is None, f"{name}: first different row {first}:\n{rows_a[first]}\n{rows_b[first]}"
    mine, ref = final_weights(a), final_weights(b)
    assert mine.keys() == ref.keys() and all(torch.equal(mine[k], ref[k]) for k in mine)
    ra, rb = (json.loads((d / "results.json").read_text()) for d in (a, b))
    for r in (ra, rb):
        r["summary"].pop("mean_wall_s")
    assert ra["summary"] == rb["summary"] and ra["training"]["transitions"] == rb["training"]["transitions"]


@pytest.fixture(scope="module")
def cold(script_grid, tmp_path_factory) -> tuple[Path, Path]:
    """A run that simulates its days in-process (empty cache): its directory and the cache."""
    root = tmp_path_factory.mktemp("reproducible")
    out, cache = root / "cold", root / "cache"
    proc = train(out, cache, script_grid)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "simulating a background day" in proc.stdout + proc.stderr  # the days were built in this process
    rows = read_csv(out / "train_episodes.csv")
    assert sum(r["reason"] == "charging" for r in rows) >= 50
    assert max(float(r["queue_wait"]) for r in rows) > 600  # congested: targets queue
    return out, cache


def test_the_same_training_from_a_warm_cache_in_another_process_is_identical(cold, script_grid, tmp_path):
    reference, cache = cold
    cwd = tmp_path / ("another-working-directory-with-a-much-longer-path" * 2)
    cwd.mkdir()
    script = str(SCRIPTS / "train.py")
    code = ALLOCATE_FIRST.format(script=script)  # another heap layout for SUMO's objects
    proc = train(tmp_path / "warm", cache, script_grid, cwd=cwd, hash_seed="4242", code=code)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "simulating a background day" not in proc.stdout + proc.stderr  # every day came from the cache
    assert_same_run(tmp_path / "warm", reference)
