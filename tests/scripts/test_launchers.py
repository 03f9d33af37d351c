"""Sweeps through Hydra launchers: the shipped launcher configs compose, and a joblib multirun of
``scripts/train.py`` runs its jobs in parallel processes (and makes a results table), a failing job
failing alone (in ``scripts/evaluate.py`` too).

The runs are tiny (rule agents, two evaluation episodes on a generated grid) so that a sweep takes
seconds; the two jobs of a sweep build the same day cache at once (the cache's lock serialises them).
"""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest
from omegaconf import DictConfig

from evcd.report.sweep import IncompleteSweepError
from evcd.report.table import CSV_NAME, MD_NAME, make_table
from tests.conftest import CONF, compose_config, run_script

SHIPPED = sorted(p.stem for p in (CONF / "hydra" / "launcher").glob("*.yaml"))

SUBMITIT = "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"
JOBLIB = "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"
RAY = "hydra_plugins.hydra_ray_launcher.ray_launcher.RayLauncher"

#: launcher -> (its _target_, settings it must have); the plugins' own configs as well as ours
EXPECTED = {
    "evcd_slurm": (SUBMITIT, {"cpus_per_task": 1, "tasks_per_node": 1, "nodes": 1, "mem_gb": 4,
                              "timeout_min": 120, "partition": None, "max_num_timeout": 0}),
    "evcd_ray": (RAY, {"ray": {"init": {"address": None}, "remote": {"num_cpus": 1}}}),
    "joblib": (JOBLIB, {"n_jobs": -1, "prefer": "processes"}),
    "submitit_slurm": (SUBMITIT, {"tasks_per_node": 1}),
}  # fmt: skip


def launcher_config(name: str, *overrides: str) -> DictConfig:
    """``hydra.launcher`` of scripts/train.py's config composed with ``hydra/launcher=name``."""
    cfg = compose_config("train", f"hydra/launcher={name}", "hydra.sweep.dir=/sweep", *overrides,
                         return_hydra_config=True)  # fmt: skip
    return cfg.hydra.launcher


def sweep(*overrides: str, script: str = "train.py") -> subprocess.CompletedProcess:
    """``script -m`` with the joblib launcher running two jobs at once."""
    launcher = ("-m", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    return run_script(script, *launcher, *overrides, timeout=600)


@pytest.fixture(scope="module")
def small(script_overrides) -> list[str]:
    """Overrides for a tiny rule-agent run on the grid."""
    return [*script_overrides, "eval.episodes=2", "eval.bootstrap_resamples=200"]


def results(job_dir: Path) -> dict:
    return json.loads((job_dir / "results.json").read_text())


# ---------------------------------------------------------------------------------------- configs
def test_every_shipped_launcher_is_checked():
    assert {"evcd_slurm", "evcd_ray"} <= set(SHIPPED)
    assert set(SHIPPED) <= set(EXPECTED), "add the new launcher config to EXPECTED"
    assert not {"joblib", "submitit_slurm", "ray"} & set(SHIPPED), "never shadow a plugin's own config"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_launcher_config_composes_with_the_train_config(name):
    target, settings = EXPECTED[name]
    launcher = launcher_config(name)
    assert launcher._target_ == target
    for key, value in settings.items():
        assert launcher[key] == value, key


def test_the_slurm_launcher_keeps_the_plugins_fields_and_writes_under_the_sweep_dir():
    ours, plugin = launcher_config("evcd_slurm"), launcher_config("submitit_slurm")
    assert set(ours) == set(plugin)  # only values changed: every field the launcher expects is there
    assert ours.submitit_folder == "/sweep/.submitit/%j"
    assert launcher_config("evcd_slurm", "hydra.launcher.partition=cpu").partition == "cpu"


def test_the_ray_launcher_has_the_fields_of_the_plugins_config():
    # hydra_ray_launcher's RayLauncherConf: _target_ and ray: {init: {address: null}, remote: {}}
    launcher = launcher_config("evcd_ray")
    assert set(launcher) == {"_target_", "ray"} and set(launcher.ray) == {"init", "remote"}


# ---------------------------------------------------------------------------------------- sweeps
@pytest.mark.slow
def test_a_joblib_sweep_runs_every_job(small, tmp_path):
    out = tmp_path / "sweep"
    proc = sweep(*small, "agent=greedy,random", f"hydra.sweep.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Joblib.Parallel(n_jobs=2" in proc.stdout + proc.stderr
    assert (out / "multirun.yaml").exists()
    for job, agent in (("0_greedy_evs30_seed0", "greedy"), ("1_random_evs30_seed0", "random")):
        data = results(out / job)
        assert data["agent"] == agent and data["summary"]["episodes"] == 2

    # make_table end to end on the real sweep: multirun.yaml, each job's overrides and results.json
    table = make_table([out], tmp_path / "table", resamples=200)
    assert (table.collection.expected, table.collection.gaps) == (2, ())
    with open(tmp_path / "table" / CSV_NAME, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["agent"], int(r["evs"]), int(r["seed"]), r["regime"]) for r in rows] == [
        ("random", 30, 0, "peak"), ("greedy", 30, 0, "peak")]  # fmt: skip
    assert {Path(r["job_dir"]).name for r in rows} == {"0_greedy_evs30_seed0", "1_random_evs30_seed0"}
    assert all(int(r["eval_episodes"]) == 2 for r in rows)
    md = (tmp_path / "table" / MD_NAME).read_text()
    assert md == table.markdown and "| EVs | random | greedy |" in md
    assert "## Regime `peak`" in md and "Jobs: 2 (2 agents, EV counts 30, 1 seeds: 0)" in md


@pytest.mark.slow
def test_a_failing_job_fails_alone_and_the_sweep_reports_it(small, tmp_path):
    out = tmp_path / "sweep"
    # job 0 has a bad value, job 1 is fine: job 0 must not take job 1 down with it
    proc = sweep(*small, "agent=greedy", "eval.episodes=0,2", f"hydra.sweep.dir={out}")
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert results(out / "1_greedy_evs30_seed0")["summary"]["episodes"] == 2
    failed = out / "0_greedy_evs30_seed0"
    assert not (failed / "results.json").exists()
    assert "eval.episodes=0: must be an integer >= 1" in (failed / "train.log").read_text()
    assert "Error executing job with overrides" in proc.stderr and "eval.episodes=0" in proc.stderr
    # the refused job has its own record (written at its refusal): the table names it, with why
    assert "eval.episodes=0" in (failed / ".hydra" / "overrides.yaml").read_text()
    with pytest.raises(IncompleteSweepError, match=r"failed: .*eval\.episodes=0.*must be an integer >= 1"):
        make_table([out], tmp_path / "table", resamples=200)


@pytest.mark.slow
def test_a_failing_evaluation_job_fails_alone_too(small, tmp_path):
    out = tmp_path / "sweep"
    evaluate = [o.replace("eval.", "") for o in small]  # scripts/evaluate.py: episodes=, bootstrap_resamples=
    proc = sweep(*evaluate, "agent=greedy", "episodes=0,2", f"hydra.sweep.dir={out}", script="evaluate.py")
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert results(out / "1_greedy_evs30_seed0")["summary"]["episodes"] == 2
    log = (out / "0_greedy_evs30_seed0" / "evaluate.log").read_text()
    assert "episodes=0: must be an integer >= 1" in log
