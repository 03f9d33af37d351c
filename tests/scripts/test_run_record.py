"""Nothing written is lost: a refused run leaves the record of the run it refused to touch as it was,
and a run refused before its start leaves no directory behind (``evcd.cli.run_record``)."""

from __future__ import annotations

import csv
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from evcd import ENV_ID
from evcd.cli.run_record import discard_refused_run_dir
from evcd.report.stamp import NOT_RECORDED
from evcd.utils.provenance import code_record
from tests.conftest import SCRIPTS, run_script, shared_folder
from tests.scripts.test_train_script import KILL_MID_BATCH, KILLER

RECORD = ("config.yaml", "overrides.yaml", "hydra.yaml")


def record(run: Path) -> dict[str, bytes]:
    return {name: (run / ".hydra" / name).read_bytes() for name in RECORD}


@pytest.fixture(scope="module")
def sweep(script_overrides, tmp_path_factory) -> Path:
    """A finished 2-job multirun of greedy (seeds 0 and 1), made once per test run (:func:`shared_folder`)."""

    def run(root: Path) -> None:
        proc = run_script("train.py", "-m", *script_overrides, "agent=greedy", "seed=0,1", "eval.episodes=2",
                          "eval.bootstrap_resamples=200", f"hydra.sweep.dir={root / 'sweep'}")  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]

    return shared_folder(tmp_path_factory, "run_record_sweep", run) / "sweep"


def job_dirs(sweep: Path) -> list[Path]:
    return sorted(d for d in sweep.iterdir() if d.is_dir())


@pytest.mark.slow
def test_a_refused_run_leaves_the_record_of_the_run_it_refused(sweep, script_overrides, tmp_path):
    job = job_dirs(sweep)[0]
    before = record(job)
    assert b"seed=0" in before["overrides.yaml"]
    for extra in (["eval.episodes=3"], ["eval.episodes=3", "resume=true"]):
        proc = run_script("train.py", *script_overrides, "agent=greedy", "seed=0", *extra,
                          f"hydra.run.dir={job}")  # fmt: skip
        assert proc.returncode == 2, proc.stderr[-2000:]
        assert "already holds" in proc.stdout + proc.stderr or "complete" in proc.stdout + proc.stderr
        assert record(job) == before, extra
    table = run_script("make_table.py", str(sweep), "--out", str(tmp_path / "table"))
    assert table.returncode == 0, table.stderr[-2000:]  # both jobs still found through their records
    assert "2 of 2 expected jobs finished" in table.stdout + table.stderr
    page = (tmp_path / "table" / "results.md").read_text()  # stamped with what made it: today's code
    assert f"- Environment: `{ENV_ID}`" in page and "another environment" not in page
    assert f"evcd: `{code_record()['evcd']}`, commit `{code_record()['commit']}" in page
    with open(tmp_path / "table" / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {r["environment"] for r in rows} == {ENV_ID} and {r["commit"] for r in rows} != {NOT_RECORDED}


@pytest.mark.slow
def test_a_refused_resume_with_changed_settings_leaves_the_record(script_overrides, tmp_path):
    out = tmp_path / "run"
    args = [*script_overrides, "agent=dqn", "learner.hidden=[16,16]", "learner.learning_starts=4",
            "learner.batch_size=4", "train.episodes=4", "train.checkpoint_every=2", "eval.episodes=2",
            f"hydra.run.dir={out}"]  # fmt: skip
    killed = run_script("train.py", *args, code=KILLER.format(patch=textwrap.dedent(KILL_MID_BATCH.format(
        when=3)), script=str(SCRIPTS / "train.py")))  # fmt: skip
    assert killed.returncode == -9, killed.stderr[-2000:]
    before = record(out)
    proc = run_script("train.py", *args, "resume=true", "learner.lr=0.005")
    assert proc.returncode == 2 and "learner.lr" in proc.stdout + proc.stderr
    assert record(out) == before


@pytest.mark.slow
def test_a_run_refused_before_its_start_leaves_no_directory(script_overrides, tmp_path):
    out = tmp_path / "new-run"
    proc = run_script("train.py", *script_overrides, "agent=dqn", "learner.lr=-0.1", f"hydra.run.dir={out}")
    assert proc.returncode == 2 and "lr=-0.1" in proc.stdout + proc.stderr
    assert not out.exists()
    # the default dated directory under outputs/ of the working directory: none left either
    cmd = [sys.executable, str(SCRIPTS / "train.py"), *script_overrides, "agent=dqn", "learner.lr=-0.1"]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert not list((tmp_path / "outputs" / "train").glob("*"))


@pytest.mark.slow
def test_an_accepted_run_writes_its_record(sweep):
    for job, seed in zip(job_dirs(sweep), (0, 1), strict=True):
        rec = record(job)
        assert f"seed={seed}".encode() in rec["overrides.yaml"]
        assert f"seed: {seed}".encode() in rec["config.yaml"] and b"hydra:" in rec["hydra.yaml"]


def test_only_a_directory_of_this_process_logs_is_discarded(tmp_path):
    started = 1_800_000_000.0  # 2027-01-15: after every stamp below
    old = tmp_path / "old"
    old.mkdir()
    (old / "train.log").write_text("[2026-01-01 10:00:00,000][train][ERROR] - an earlier refusal\n")
    assert not discard_refused_run_dir(old, started) and old.exists()  # begun before this process
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "train.log").write_text("[2030-01-01 10:00:00,000][train][ERROR] - refused\n")
    (mine / "results.json").write_text("{}")
    assert not discard_refused_run_dir(mine, started) and mine.exists()  # holds a result
    (mine / "results.json").unlink()
    assert discard_refused_run_dir(mine, started) and not mine.exists()
    assert not discard_refused_run_dir(tmp_path / "absent", started)
