"""The committed results table (docs/results.csv) is what docs/RESULTS.md says it is: every job of
the sweep, its days named, at least five held-out days, none of them used for training, tuning or
calibration by the experiment that made it."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from omegaconf import OmegaConf

from evcd.report.table import AGENT_ORDER

ROOT = Path(__file__).resolve().parents[2]


def _rows() -> list[dict[str, str]]:
    with open(ROOT / "docs" / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_the_shipped_table_holds_every_job_of_its_sweep():
    rows = _rows()
    jobs = {(r["regime"], r["agent"], int(r["evs"]), int(r["seed"])) for r in rows}
    assert len(jobs) == len(rows), "a job appears twice"
    expected = {("table", a, evs, seed) for a in AGENT_ORDER for evs in (200, 300, 400) for seed in range(5)}
    assert jobs == expected
    assert all(int(r["eval_episodes"]) == 50 for r in rows)


def test_the_shipped_table_is_evaluated_on_held_out_days_of_its_experiment():
    days = OmegaConf.load(ROOT / "conf" / "experiment" / "table.yaml")["days"]
    held_out = set(days["evaluation"])
    not_for_evaluation = set(days["train"]) | set(days["tuning"]) | set(days["calibration"])
    seen: set[int] = set()
    for r in _rows():
        eval_days = set(json.loads(r["eval_days"]))
        assert eval_days, r["job_dir"]
        assert eval_days <= held_out and not eval_days & not_for_evaluation, r["job_dir"]
        if r["agent"] in ("dqn", "dueling_ddqn"):
            assert json.loads(r["train_days"]) == list(days["train"])
        # every agent of a seed plays the same day (the cells are paired by seed)
        assert eval_days == {days["evaluation"][int(r["seed"]) % len(days["evaluation"])]}
        seen |= eval_days
    assert len(seen) >= 5
