"""``bench.py --suite reproduce`` (:mod:`evcd.report.reproduce.cost`): a page's small version run
through the reproduce command cold and warm, on a one-sweep page of the 8 x 8 grid."""

from __future__ import annotations

import json
import os

import pytest
import yaml

from evcd.report.reproduce.cost import measured_wall, small_page
from evcd.report.reproduce.launch import parallel_jobs
from evcd.report.reproduce.spec import PageError, load_page
from tests.conftest import ROOT, run_script

PAGES = ROOT / "docs" / "reproduce"


def test_the_small_version_is_each_sweeps_first_job_on_the_benchs_cache(tmp_path):
    page = load_page("readme", PAGES)
    small = small_page(page, tmp_path / "cache", ["eval.episodes=5"])
    assert small["renders"] == [] and [s["name"] for s in small["sweeps"]] == ["evcd", "sb3"]
    evcd, sb3 = (set(s["overrides"]) for s in small["sweeps"])
    assert {"agent=dueling_ddqn", "seed=0", "evs=400", "eval.episodes=5"} <= evcd
    assert {"sb3=ppo", "seed=0"} <= sb3
    for overrides in (evcd, sb3):
        assert not any("," in o for o in overrides)  # one job each
        caches = [o for o in overrides if o.startswith("env.cache_dir=")]
        assert caches == [f"env.cache_dir={tmp_path / 'cache'}"]
    # a job's own cache is replaced, not given twice
    page_file = tmp_path / "p.yaml"
    page_file.write_text(yaml.safe_dump({"title": "t", "renders": [], "sweeps": [
        {"name": "a", "script": "train.py", "task": "single", "regime": "peak",
         "overrides": ["agent=greedy,queue_aware", "seed=3,4", "env.cache_dir=/elsewhere"]}]}))  # fmt: skip
    only = small_page(load_page(str(page_file), PAGES), tmp_path / "c")["sweeps"][0]["overrides"]
    assert sorted(only) == sorted(["agent=greedy", "seed=3", f"env.cache_dir={tmp_path / 'c'}"])


def test_parallel_jobs_and_a_finished_reproduction_are_read(tmp_path):
    assert parallel_jobs([]) == 1
    assert parallel_jobs(["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]) == 2
    assert parallel_jobs(["hydra.launcher.n_jobs=-1"]) == (os.cpu_count() or 1)
    for bad in ("two", "0", "-2"):
        with pytest.raises(PageError, match=f"n_jobs='{bad}': give a whole number >= 1"):
            parallel_jobs([f"hydra.launcher.n_jobs={bad}"])
    # b starts 60 s into a's first launch and ends 10.5 s after it; a's second launch comes later
    launches = [{"sweep": sweep, "jobs": jobs, "started": f"2026-11-30T10:0{minute}:00", "wall_s": wall,
                 "returncode": 0} for sweep, jobs, minute, wall in (("a", 3, 0, 100.0), ("b", 2, 1, 50.5),
                                                                    ("a", 1, 5, 20.0))]  # fmt: skip
    (tmp_path / "reproduce.json").write_text(json.dumps({"page": "p", "launches": launches}))
    done = measured_wall(tmp_path)
    assert done == {"page": "p", "wall_s": 130.5, "jobs": 6, "sweeps_s": {"a": 120.0, "b": 50.5}}
    launches[1]["returncode"] = 1
    (tmp_path / "reproduce.json").write_text(json.dumps({"page": "p", "launches": launches}))
    with pytest.raises(PageError, match=r"sweeps \['b'\] failed"):
        measured_wall(tmp_path)
    with pytest.raises(PageError, match=r"no reproduce\.json"):
        measured_wall(tmp_path / "nowhere")


@pytest.mark.slow
def test_the_suite_runs_the_small_version_cold_then_warm(script_overrides, tmp_path):
    page = tmp_path / "tiny.yaml"
    small = [o for o in script_overrides if not o.startswith("env.cache_dir=")]
    page.write_text(yaml.safe_dump({"title": "tiny", "renders": [], "sweeps": [
        {"name": "rules", "script": "train.py", "task": "single", "regime": "peak",
         "overrides": [*small, "agent=greedy,queue_aware", "seed=0,1", "eval.episodes=2"]}]}))  # fmt: skip
    work, out = tmp_path / "work", tmp_path / "bench.json"
    # a --full that is no reproduction is refused before anything runs
    proc = run_script("bench.py", "--suite", "reproduce", "--page", page, "--work", work, "--out", out,
                      "--full", tmp_path)  # fmt: skip
    assert proc.returncode == 2 and "no reproduce.json" in proc.stderr and not work.exists()
    proc = run_script("bench.py", "--suite", "reproduce", "--page", page, "--work", work, "--out", out,
                      "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    report = json.loads(out.read_text())
    counts = (report["page"], report["small_jobs"], report["full_jobs"], report["parallel_jobs"])
    assert counts == ("tiny", 1, 4, 2)
    assert report["small_cold_s"] > 0 and report["small_warm_s"] > 0
    # the cold run built the day into the bench's own cache; the warm run built nothing
    assert any((work / "cache").rglob("*")), "the cold run built no day into the bench's cache"
    cold_log = next((work / "cold" / "logs").glob("*.log")).read_text()
    warm_log = next((work / "warm" / "logs").glob("*.log")).read_text()
    assert " background days " in cold_log and " background days " not in warm_log
    expected = report["day_builds_s"] + report["small_warm_sweeps_s"]["rules"] * 4 / 2
    assert report["full_minutes_extrapolated"] == pytest.approx(expected / 60)
    assert report["day_builds_s"] == pytest.approx(max(0.0, report["small_cold_s"] - report["small_warm_s"]))
