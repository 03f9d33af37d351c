"""The user's determinism check: ``scripts/bench.py --suite determinism`` and the run comparison."""

from __future__ import annotations

import csv
import json
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
import torch

from evcd.bench.determinism import compare_runs, first_difference, run_digest, state_sha256
from tests.conftest import run_script

ROWS = [
    {"episode": "0", "seed": "11", "travel_time": "120.0", "reason": "charging", "wall_s": "0.5"},
    {"episode": "1", "seed": "12", "travel_time": "300.0", "reason": "charging", "wall_s": "0.7"},
]


def write_rows(run: Path, rows: list[dict[str, str]], name: str = "episodes.csv") -> Path:
    run.mkdir(parents=True, exist_ok=True)
    with open(run / name, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return run


def test_state_digest_sees_every_value_and_ignores_key_order():
    state = {"online": {"w": torch.arange(6.0).reshape(2, 3), "b": torch.zeros(3)}, "steps": 7,
             "replay": np.ones(4, dtype=np.float32)}  # fmt: skip
    same = {"steps": 7, "replay": np.ones(4, dtype=np.float32),
            "online": {"b": torch.zeros(3), "w": torch.arange(6.0).reshape(2, 3)}}  # fmt: skip
    assert state_sha256(state) == state_sha256(same)
    bumped = {**same, "online": {**same["online"], "w": same["online"]["w"].clone()}}
    bumped["online"]["w"][1, 2] = torch.nextafter(torch.tensor(5.0), torch.tensor(6.0))  # one ulp
    assert state_sha256(bumped) != state_sha256(state)
    assert state_sha256({**state, "steps": 8}) != state_sha256(state)
    assert state_sha256({**state, "replay": np.ones(4, dtype=np.float64)}) != state_sha256(state)


def test_runs_that_differ_only_in_wall_time_are_identical(tmp_path):
    a = write_rows(tmp_path / "a", ROWS)
    b = write_rows(tmp_path / "b", [{**r, "wall_s": "9.9"} for r in ROWS])
    report = compare_runs(a, b)
    assert report["identical"] and report["first_difference"] is None
    assert report["rows"] == {"episodes.csv": 2}


def test_the_first_different_episode_is_named(tmp_path):
    a = write_rows(tmp_path / "a", ROWS)
    b = write_rows(tmp_path / "b", [ROWS[0], {**ROWS[1], "travel_time": "301.0"}])
    report = compare_runs(a, b)
    assert not report["identical"]
    assert report["first_difference"] == (
        "episodes.csv: row 1 (episode 1) differs in ['travel_time']: ['300.0'] vs ['301.0']"
    )
    c = write_rows(tmp_path / "c", ROWS[:1])
    assert first_difference(run_digest(a), run_digest(c)) == "episodes.csv: 2 rows vs 1"
    write_rows(tmp_path / "d", ROWS)
    write_rows(tmp_path / "d", ROWS, name="train_episodes.csv")
    assert "different episode files" in first_difference(run_digest(a), run_digest(tmp_path / "d"))


def test_the_evaluated_policy_of_any_learner_is_compared_by_its_recorded_digest(tmp_path):
    a = write_rows(tmp_path / "a", ROWS)
    b = write_rows(tmp_path / "b", ROWS)
    for run, digest in ((a, "aa11"), (b, "bb22")):
        training = {"transitions": 40, "policy_sha256": digest}
        (run / "results.json").write_text(json.dumps({"agent": "ppo", "training": training}))
    assert run_digest(a)["policy_sha256"] == "aa11"
    assert first_difference(run_digest(a), run_digest(b)) == "policy_sha256: aa11 vs bb22"


@pytest.mark.slow
def test_the_suite_trains_twice_in_fresh_processes_and_finds_them_identical(script_overrides, tmp_path):
    out = tmp_path / "determinism.json"
    tiny = [*script_overrides, "agent=dqn", "learner.hidden=[16,16]", "learner.learning_starts=4",
            "learner.batch_size=4", "train.episodes=6", "train.checkpoint_every=3", "eval.episodes=3",
            "eval.bootstrap_resamples=200"]  # fmt: skip
    proc = run_script("bench.py", "--suite", "determinism", "--evs", "30", "--out", out, *tiny)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(out.read_text())
    assert report["identical"] and "identical" in proc.stderr
    assert report["rows"] == {"baseline_greedy_episodes.csv": 3, "baseline_queue_aware_episodes.csv": 3,
                             "episodes.csv": 3, "train_episodes.csv": 6}  # fmt: skip
    assert report["transitions"][0] == report["transitions"][1] > 0
    assert report["policy_sha256"][0] == report["policy_sha256"][1] is not None
    assert report["agent_sha256"][0] == report["agent_sha256"][1]
    # the digest is named with the machine that made it (torch's kernels, one thread, the packages)
    machine = report["machine"]
    assert machine["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    assert machine["torch_threads"] == 1 and machine["packages"]["libsumo"] == version("libsumo")


@pytest.mark.slow
def test_overrides_are_refused_outside_the_suites_that_take_them(tmp_path):
    proc = run_script("bench.py", "--suite", "replay", "--out", tmp_path / "x.json", "agent=dqn")
    assert proc.returncode == 2 and "for --suite determinism or reproduce only" in proc.stderr
