"""``scripts/reproduce.py``: every published page from one command (:mod:`evcd.report.reproduce`).

A tiny page of four rule jobs on the 8 x 8 grid (two sweeps) runs end to end once per test run
(:func:`shared_folder`): its multiruns, the rendering (make_table, a dispatcher per seed, paired rows)
and the comparison; then ``--check`` on its run directories is equal to the data committed from it,
and names the cell edited in that data; a reproduction with a job of each sweep deleted resumes just
those, the two multiruns side by side on Hydra's joblib launcher with two slots.
The refusals run in one process (:func:`run_refusals`). Every shipped page's jobs compose against
``conf/`` (no SUMO), and the rows and sections its comparisons read are on its committed pages.
"""

from __future__ import annotations

import contextlib
import importlib.util
import itertools
import json
import re
import shutil
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
import yaml
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from evcd.experiments.schema import register_configs
from evcd.loops.run_files import TRAIN_CSV
from evcd.report.markdown import section_lines
from evcd.report.markdown import tables as md_tables
from evcd.report.reproduce.check import csv_differences, markdown_differences, region_differences
from evcd.report.reproduce.found import job_groups
from evcd.report.reproduce.launch import check_launcher, finished_keys, read_runs
from evcd.report.reproduce.records import keep_records
from evcd.report.reproduce.render import log_span, log_wall
from evcd.report.reproduce.spec import PageError, PageJob, job_key, known_pages, load_page
from evcd.report.sweep import collect, world_label
from tests.conftest import CONF, ROOT, SCRIPTS, run_refusals, run_script, shared_folder

PAGES = ROOT / "docs" / "reproduce"
#: The shipped pages and their jobs (what --dry-run counts).
SHIPPED_JOBS = {"results": 90, "fleet": 90, "readme": 20, "perturbed": 115, "room": 90}


def tiny_page(overrides: list[str]) -> dict[str, Any]:
    """A page of two sweeps of rule jobs (greedy seeds 0-1, queue_aware seeds 0-1), rendered three ways."""
    small = [*overrides, "seed=0,1", "eval.episodes=2", "eval.bootstrap_resamples=200"]
    sweep = {"script": "train.py", "task": "single", "regime": "peak"}
    page_md = "committed/page.md"
    return {
        "title": "a tiny page",
        "sweeps": [
            {"name": "greedy", **sweep, "overrides": [*small, "agent=greedy"]},
            {"name": "queue", **sweep, "overrides": [*small, "agent=queue_aware", "eval.baselines=[greedy]"]},
        ],
        "renders": [
            {"name": "table", "kind": "table", "sweeps": ["greedy", "queue"], "options": {"resamples": 200},
             "compare": [{"kind": "csv", "file": "results.csv", "committed": "committed/results.csv"},
                         {"kind": "markdown", "file": "results.md", "committed": page_md,
                          "section": "## Regime `peak`"}]},
            {"name": "seeds", "kind": "seed_rows", "sweeps": ["greedy"], "options": {"order": ["greedy"]},
             "compare": [{"kind": "markdown", "file": "seeds.md", "committed": page_md}]},
            {"name": "pairs", "kind": "paired_rows", "sweeps": ["greedy", "queue"],
             "options": {"header": ["what", "difference"], "rows": [
                 {"cells": ["queue_aware - greedy"], "a": "peak/queue_aware", "b": "peak/greedy"},
                 {"cells": ["by seed"], "a": "peak/queue_aware", "b": "peak/greedy", "by": "seed"}]},
             "compare": [{"kind": "markdown", "file": "pairs.md", "committed": page_md}]},
            {"name": "worlds", "kind": "compare", "sweeps": ["greedy", "queue"],
             "options": {"references": ["peak/greedy"], "against_calm": True, "worlds": ["peak"]},
             "compare": [{"kind": "markdown", "file": "worlds.md", "committed": page_md}]},
        ],
    }  # fmt: skip


@pytest.fixture(scope="module")
def reproduced(script_overrides, tmp_path_factory) -> Path:
    """The tiny page reproduced once per test run (``out/``), and its rendering committed (``root/``)."""

    def build(folder: Path) -> None:
        (folder / "page.yaml").write_text(yaml.safe_dump(tiny_page(script_overrides)))
        (folder / "root").mkdir()
        proc = run_script(
            "reproduce.py", folder / "page.yaml", "--out", folder / "out", "--root", folder / "root"
        )
        log = proc.stdout + proc.stderr
        assert proc.returncode == 1, log[-3000:]  # rendered; nothing committed yet to compare with
        assert "committed/results.csv: no such committed file" in log
        # each job named as it finishes, the time the others take at that pace
        assert "sweep 1/2 greedy: 1 of 2 jobs finished (0_greedy_evs30_seed0) after " in log
        first = r"sweep 2/2 queue: 1 of 2 jobs finished \(\d_queue_aware_evs30_seed\d\) after \d+ s; "
        assert re.search(first + r"about \d+ s left at this pace", log)
        assert "sweep 2/2 queue: 2 of 2 jobs finished" in log
        rendered, committed = folder / "out" / "rendered", folder / "root" / "committed"
        committed.mkdir()
        shutil.copy(rendered / "table" / "results.csv", committed / "results.csv")
        text = "".join((rendered / r / f).read_text() for r, f in
                       (("table", "results.md"), ("seeds", "seeds.md"), ("pairs", "pairs.md"),
                        ("worlds", "worlds.md")))  # fmt: skip
        (committed / "page.md").write_text(text)

    return shared_folder(tmp_path_factory, "reproduce_tiny_page", build)


# ---------------------------------------------------------------------------------------- end to end
@pytest.mark.slow
def test_a_page_runs_renders_and_checks_equal_then_names_an_edited_cell(reproduced, tmp_path):
    out = reproduced / "out"
    manifest = json.loads((out / "reproduce.json").read_text())
    assert [(x["sweep"], x["jobs"], x["returncode"]) for x in manifest["launches"]] == [
        ("greedy", 2, 0),
        ("queue", 2, 0),
    ]
    assert all(x["wall_s"] > 0 and "python scripts/train.py -m" in x["command"] for x in manifest["launches"])
    summary = (out / "rendered" / "reproduce.md").read_text()
    assert "- Environment: `evcd/ChargingNav-v1`" in summary and "## Jobs" in summary
    assert (
        summary.count("| greedy | seed=") == 2 and summary.count("| queue | seed=") == 2
    )  # each job's wall time
    assert "| queue_aware - greedy | " in (out / "rendered" / "pairs" / "pairs.md").read_text()
    # compare_runs.py's table: every world and dispatcher, each paired with the reference (none calm)
    worlds = (out / "rendered" / "worlds" / "worlds.md").read_text()
    assert "| world | dispatcher | seeds | mean travel time (s) | - peak / greedy |" in worlds
    assert re.search(r"\| peak \| queue_aware \| 2 \| [\d.]+ \[[-\d.]+, [\d.]+\] \| [-+]", worlds)

    page, root = reproduced / "page.yaml", reproduced / "root"
    same = run_script(
        "reproduce.py", page, "--check", out / "sweeps", "--out", tmp_path / "a", "--root", root
    )
    assert same.returncode == 0, (same.stdout + same.stderr)[-3000:]
    assert "equal to the committed data" in same.stderr

    edited = tmp_path / "root"
    shutil.copytree(root, edited)
    csv_file = edited / "committed" / "results.csv"
    lines = csv_file.read_text().splitlines()
    header = lines[0].split(",")
    row = next(i for i, line in enumerate(lines) if line.startswith("peak,greedy,30,1,"))
    cells = lines[row].split(",")
    old = cells[header.index("mean_travel_time")]
    cells[header.index("mean_travel_time")] = "999.5"
    lines[row] = ",".join(cells)
    csv_file.write_text("\n".join(lines) + "\n")
    md = edited / "committed" / "page.md"
    pair = next(line for line in md.read_text().splitlines() if line.startswith("| queue_aware - greedy |"))
    md.write_text(md.read_text().replace(pair, "| queue_aware - greedy | EDITED |"))
    proc = run_script(
        "reproduce.py", page, "--check", out / "sweeps", "--out", tmp_path / "b", "--root", edited
    )
    assert proc.returncode == 1, (proc.stdout + proc.stderr)[-3000:]
    assert proc.stdout.splitlines() == [
        f"committed/results.csv: row regime=peak agent=greedy evs=30 seed=1: column 'mean_travel_time': "
        f"'999.5' -> '{old}'",
        next(
            line
            for line in proc.stdout.splitlines()
            if "column 'difference' of row 'queue_aware - greedy'" in line
        ),
    ]
    assert f"'EDITED' -> '{pair.split('|')[2].strip()}'" in proc.stdout


@pytest.mark.slow
def test_a_reproductions_records_render_it_and_resume_it_elsewhere_side_by_side(reproduced, tmp_path):
    page, root, records = reproduced / "page.yaml", reproduced / "root", tmp_path / "records"
    assert _main()([str(page), "--out", str(reproduced / "out"), "--records", str(records)]) == 0
    files = {p.relative_to(records).as_posix() for p in records.rglob("*") if p.is_file()}
    job = "sweeps/greedy/0_greedy_evs30_seed0"
    assert {
        f"{job}/.hydra/overrides.yaml",
        f"{job}/.hydra/config.yaml",
        f"{job}/results.json",
        f"{job}/episodes.csv",
        f"{job}/train.log",
        "sweeps/greedy/multirun.yaml",
        "reproduce.json",
    } <= files
    assert sum(name.endswith("/results.json") for name in files) == 4
    assert not [
        name for name in files if name.endswith(".png") or "/checkpoints/" in name or "/tensorboard/" in name
    ]
    # the page rendered from its records alone, no simulation: equal to the committed data
    same = run_script(
        "reproduce.py", page, "--check", records / "sweeps", "--out", tmp_path / "a", "--root", root
    )
    log = same.stdout + same.stderr
    assert same.returncode == 0 and "equal to the committed data" in log, log[-3000:]

    # a copy of the records, two jobs taken out, resumes as an output folder of the page
    out = tmp_path / "out"
    shutil.copytree(records, out)
    kept = out / "sweeps" / "greedy" / "0_greedy_evs30_seed0" / "results.json"
    before = kept.read_bytes()
    shutil.rmtree(out / "sweeps" / "greedy" / "1_greedy_evs30_seed1")
    shutil.rmtree(next((out / "sweeps" / "queue").glob("*_seed0")))
    joblib = ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]
    proc = run_script(
        "reproduce.py", reproduced / "page.yaml", *joblib, "--out", out, "--root", reproduced / "root"
    )
    # the same numbers as the jobs run one at a time: same seed, same result
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    launches = json.loads((out / "reproduce.json").read_text())["launches"]
    left = sorted(launches[2:], key=lambda x: x["sweep"])
    assert [(x["sweep"], x["jobs"], Path(x["dir"]).name) for x in left] == [
        ("greedy", 1, "greedy-resume1"),
        ("queue", 1, "queue-resume1"),
    ]
    assert "seed=1" in left[0]["command"] and "seed=0,1" not in left[0]["command"]
    assert "seed=0" in left[1]["command"] and "seed=0,1" not in left[1]["command"]
    # one job each on two slots: the second multirun starts beside the first, not after it
    assert "sweep 2/2 queue: 1 job(s)" in proc.stderr and ", beside sweep 1/2 greedy" in proc.stderr
    first, second = (datetime.fromisoformat(x["started"]).timestamp() for x in left)
    assert abs(second - first) < left[0]["wall_s"]
    assert kept.read_bytes() == before and (out / "sweeps" / "greedy-resume1" / "multirun.yaml").is_file()

    # the resumed folder's records add the jobs it ran to the ones kept; a kept record that differs, or
    # records of another reproduction, are refused and nothing is written
    kept_before = {p: p.read_bytes() for p in records.rglob("*") if p.is_file()}
    assert _main()([str(page), "--out", str(out), "--records", str(records)]) == 0
    added = {
        p.relative_to(records).as_posix() for p in records.rglob("*") if p.is_file() and p not in kept_before
    }
    assert {a.split("/")[1] for a in added if a.endswith("results.json")} == {
        "greedy-resume1",
        "queue-resume1",
    }
    assert all(p.read_bytes() == data for p, data in kept_before.items() if p.name != "reproduce.json")
    assert json.loads((records / "reproduce.json").read_text()) == json.loads(
        (out / "reproduce.json").read_text()
    )
    edited = records / "sweeps" / "greedy" / "0_greedy_evs30_seed0" / "results.json"
    edited.write_text(edited.read_text().replace("greedy", "GREEDY", 1))
    mine = tmp_path / "mine"
    shutil.copytree(records / "sweeps", mine / "sweeps")
    (mine / "reproduce.json").write_text(json.dumps({"page": "other", "launches": []}))
    state = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    cases = {
        "keeps 1 record file(s) with other content than": records,
        "holds records of another reproduction": mine,
    }
    for message, dest in cases.items():
        proc = run_script("reproduce.py", page, "--out", out, "--records", dest)
        assert proc.returncode == 2 and message in proc.stderr, (proc.stdout + proc.stderr)[-3000:]
    assert state == {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}


def _sessions() -> dict[int, int]:
    """Every live process of this machine: pid -> session id (zombies left out)."""
    out = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError):
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                if fields[0] != "Z":
                    out[int(entry.name)] = int(fields[3])
    return out


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the processes from /proc")
def test_a_stopped_reproduction_ends_its_processes_and_continues_a_learner_from_its_checkpoint(
    script_overrides, tmp_path
):
    learner = [*script_overrides, "agent=dueling_ddqn", "train.episodes=40", "train.checkpoint_every=2",
               "train.validation.every=0", "learner.hidden=[16,16]", "learner.learning_starts=4",
               "learner.batch_size=4", "learner.exploration_steps=10", "eval.episodes=2", "eval.baselines=[]",
               "eval.bootstrap_resamples=200"]  # fmt: skip
    page = tmp_path / "page.yaml"
    definition = {"name": "learner", "script": "train.py", "task": "single", "regime": "peak"}
    page.write_text(yaml.safe_dump({"title": "a learner", "renders": [],
                                    "sweeps": [{**definition, "overrides": learner}]}))  # fmt: skip
    out = tmp_path / "out"
    cmd = [str(c) for c in (sys.executable, SCRIPTS / "reproduce.py", page, "--out", out, "--root", tmp_path)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sweep = f"hydra.sweep.dir={out / 'sweeps' / 'learner'}"
    pointer = out / "sweeps" / "learner" / "0_dueling_ddqn_evs30_seed0" / "checkpoints" / "latest.json"
    deadline, group = time.monotonic() + 180, None
    while not pointer.is_file() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
        for pid in _sessions() if group is None else ():
            with contextlib.suppress(OSError):
                if sweep in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0"):
                    group = pid
    assert group is not None and pointer.is_file() and proc.poll() is None, "no checkpoint while it ran"
    proc.send_signal(signal.SIGTERM)  # training, after its first checkpoint
    log, _ = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, log[-3000:]
    assert f"stopped: ending the sweep running (process group {group})" in log
    assert group not in _sessions().values()  # nothing of the sweep left running
    assert not (out / "rendered").exists()
    (launch,) = json.loads((out / "reproduce.json").read_text())["launches"]  # its wall time kept
    assert launch["stopped"] is True and launch["wall_s"] > 0 and launch["returncode"] != 0

    stopped = pointer.parent.parent
    assert not (stopped / "results.json").exists()
    before = {p.relative_to(stopped): p.read_bytes() for p in stopped.rglob("*") if p.is_file()}
    episodes = int(json.loads(pointer.read_text())["file"].removeprefix("ckpt_").removesuffix(".pt"))
    again = run_script("reproduce.py", page, "--out", out, "--root", tmp_path)
    log = again.stdout + again.stderr
    assert again.returncode == 0, log[-3000:]  # every job finished; nothing to compare with
    assert f"sweep 1/1 learner: continues {stopped} from its last checkpoint, in a copy" in log
    launches = json.loads((out / "reproduce.json").read_text())["launches"]
    assert [x.get("stopped", False) for x in launches] == [True, False] and launches[0] == launch
    resumed = out / "sweeps" / "learner-resume1" / stopped.name
    train_log = (resumed / "train.log").read_text()
    assert f"resuming after {episodes} training episodes" in train_log, train_log[-2000:]
    results = json.loads((resumed / "results.json").read_text())
    assert results["training"]["sessions"] == 2 and results["training"]["episodes"] == 40
    assert len((resumed / "train_episodes.csv").read_text().splitlines()) == 1 + 40
    # the continuing multirun is a sweep make_table reads like any other (resume=true makes no other job)
    read = collect([resumed.parent])
    assert (read.expected, [j.job_dir for j in read.jobs], read.gaps) == (1, [resumed], ())
    # its wall time counts both sessions, not the time between them
    begin, end = log_span(resumed)
    assert 0 < log_wall(resumed) < (end - begin).total_seconds() - 1
    # the stopped run stays as it was
    assert {p.relative_to(stopped): p.read_bytes() for p in stopped.rglob("*") if p.is_file()} == before


@pytest.mark.slow
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(reproduced, tmp_path):
    page, root, sweeps = reproduced / "page.yaml", reproduced / "root", reproduced / "out" / "sweeps"
    job = sweeps / "greedy" / "0_greedy_evs30_seed0"

    def edited_job(name: str, edit) -> Path:
        copy = tmp_path / name / job.name
        shutil.copytree(job, copy)
        data = json.loads((copy / "results.json").read_text())
        edit(data)
        (copy / "results.json").write_text(json.dumps(data))
        return copy.parent

    fleet = edited_job("fleet_run", lambda d: d.update(task="fleet"))
    table = edited_job("table_run", lambda d: d["config"].update(regime="table"))
    incomplete = tmp_path / "incomplete"
    shutil.copytree(sweeps, incomplete)
    shutil.rmtree(incomplete / "greedy" / "1_greedy_evs30_seed1")
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "notes.txt").write_text("mine")
    (tmp_path / "empty").mkdir()
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({**tiny_page([]), "colour": "red"}))
    no_row = yaml.safe_load(page.read_text())
    no_row["renders"][-1]["options"]["references"] = ["peak/nope"]
    (tmp_path / "no_row.yaml").write_text(yaml.safe_dump(no_row))
    out = tmp_path / "outs"
    check = ["--root", root, "--check"]
    cases = {
        "no page 'nope': the pages are fleet, perturbed, readme, results, room": ["nope", "--out", out / "a"],
        "is a fleet run (task=fleet); the jobs of page page here are single-target (task=single)":
            [page, *check, fleet, "--out", out / "b"],
        "is a run of regime 'table' (experiment=table); the jobs of page page here are of regime 'peak'":
            [page, *check, table, "--out", out / "c"],
        "page page: 1 of 4 jobs did not finish": [page, *check, incomplete, "--out", out / "d"],
        "exists and is not a reproduction's folder": [page, "--out", taken],
        "unknown key(s) colour": [bad, "--out", out / "f"],
        "holds no run directory": [page, *check, tmp_path / "empty", "--out", out / "g"],
        "compare: references='peak/nope' is not a row of the jobs; the rows: peak/greedy; peak/queue_aware":
            [tmp_path / "no_row.yaml", *check, sweeps, "--out", out / "j"],
        "--records keeps the records of an earlier run: give its --out": [page, "--records", out / "k"],
        f"{reproduced / 'out'} is a run of page 'page', not of page 'fleet'":
            ["fleet", "--out", reproduced / "out", "--records", out / "l"],
        f"{taken} is not a reproduction's folder (no reproduce.json)":
            [page, "--out", taken, "--records", out / "m"],
        "env.cache_dir=x does not exist (an override? overrides go before --check)":
            [page, *check, sweeps, "env.cache_dir=x", "--out", out / "i"],
    }  # fmt: skip
    if importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is None:  # else it would run
        ray = 'plugin hydra_plugins.hydra_ray_launcher, which is not installed: pip install -e ".[ray]"'
        cases[ray] = [page, "hydra/launcher=evcd_ray", "--out", out / "h"]
    results = run_refusals("reproduce.py", list(cases.values()), tmp_path / "refusals")
    for (message, _), (code, log) in zip(cases.items(), results, strict=True):
        assert code == 2, (message, log[-2000:])
        errors = [line for line in log.splitlines() if " ERROR " in line]
        assert len(errors) == 1 and message in errors[0], (message, log[-2000:])
    missing = results[3][1]
    assert (
        "  missing: greedy: " in missing and "seed=1" in missing.split("missing: greedy:")[1].splitlines()[0]
    )
    assert "complete them with:" in missing and f"hydra.sweep.dir={out / 'd'}-completion/greedy-0" in missing
    assert (
        f"then: python scripts/reproduce.py {page} --check {incomplete} {out / 'd'}-completion --root {root}"
        in missing
    )
    assert not out.exists() and [p.name for p in taken.iterdir()] == ["notes.txt"]


# ---------------------------------------------------------------------------------------- no SUMO
def test_a_missing_launcher_plugin_names_the_extra_that_installs_it():
    absent = lambda module: False  # noqa: E731
    with pytest.raises(PageError, match=r'hydra/launcher=evcd_slurm needs .*: pip install -e "\.\[slurm\]"'):
        check_launcher(["hydra/launcher=evcd_slurm", "hydra.launcher.partition=cpu"], absent)
    with pytest.raises(PageError, match=r'pip install -e "\.\[ray\]"'):
        check_launcher(["hydra/launcher=evcd_ray"], absent)
    with pytest.raises(PageError, match=r"installed: pip install -e \.$"):
        check_launcher(["hydra/launcher=joblib"], absent)
    check_launcher(["hydra/launcher=evcd_slurm"], lambda module: True)
    check_launcher(["hydra.launcher.n_jobs=2", "hydra/launcher=basic"], absent)  # no plugin needed


def _main():
    spec = importlib.util.spec_from_file_location("reproduce_script", SCRIPTS / "reproduce.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


@pytest.mark.parametrize("page", sorted(SHIPPED_JOBS))
def test_a_dry_run_lists_the_jobs_and_their_commands_and_runs_nothing(page, tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        _main()([page, "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", "--dry-run", "--out", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    definition = load_page(page, PAGES)
    assert f"{SHIPPED_JOBS[page]} jobs to run in {len(definition.sweeps)} multirun(s)" in text
    commands = [line.strip() for line in text.splitlines() if line.startswith("  python ")]
    for sweep, command in zip(definition.sweeps, commands, strict=True):
        assert command.startswith(f"python scripts/{sweep.script} -m ")
        assert command.endswith(
            f"hydra/launcher=joblib hydra.launcher.n_jobs=2 hydra.sweep.dir={out}/sweeps/{sweep.name}"
        )
    assert sum(1 for line in text.splitlines() if line.startswith("    ")) == SHIPPED_JOBS[page]
    assert not out.exists()


def test_the_shipped_pages_rows_and_sections_are_on_their_committed_pages():
    assert known_pages(PAGES) == sorted(SHIPPED_JOBS)
    for name in known_pages(PAGES):
        page = load_page(name, PAGES)
        assert len(page.jobs()) == SHIPPED_JOBS[name]
        for render in page.renders:
            for entry in render.compare:
                text = (ROOT / entry.committed).read_text()
                section = md_tables(section_lines(text, entry.section))
                if render.kind == "paired_rows":  # every row's label cells are a row of the page's table
                    header = [str(h) for h in render.options["header"]]
                    rows = [cells for _, h, rs in section if h == header for _, cells in rs]
                    for row in render.options["rows"]:
                        assert any(cells[: len(row["cells"])] == row["cells"] for cells in rows), (name, row)
                if render.kind == "seed_rows":
                    header = [h for _, h, _ in section if h[0] == "dispatcher"]
                    assert header and header[0][1:6] == [f"seed {s}" for s in range(5)], name
                    rows = [cells[0] for _, h, rs in section if h[0] == "dispatcher" for _, cells in rs]
                    assert list(render.options["order"]) == rows, name


def test_the_fleet_tables_records_render_the_committed_fleet_table(tmp_path):
    """The fleet table's records (``docs/fleet_table/runs``, kept by ``reproduce.py fleet --records``)
    hold every job of the page; rendered from them alone, nothing simulated, the page is the committed
    one: its csv row by row, its tables cell by cell, the generated regions of the README and the fleet
    page (those reading the records' episodes among them). The jobs ran with ``env.cache_dir`` set: where
    the days were cached does not make them other jobs."""
    records = ROOT / "docs" / "fleet_table" / "runs"
    assert "env.cache_dir=" in (records / "reproduce.json").read_text()
    proc = run_script("reproduce.py", "fleet", "--check", records / "sweeps", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    assert (tmp_path / "out" / "rendered" / "fleet" / "fleet_results.csv").is_file()


def test_the_perturbed_pages_records_render_the_committed_page(tmp_path):
    """The perturbed page's records (``docs/perturbed/runs``, kept by ``reproduce.py perturbed
    --records`` across the machines that ran it) hold every job of the page; rendered from them alone,
    nothing simulated, every table of the page made from training runs is the committed one, cell by
    cell."""
    records = ROOT / "docs" / "perturbed" / "runs"
    page = load_page("perturbed", PAGES)
    keys = {PageJob(s, combo).key for s in page.sweeps for combo in s.jobs()}
    assert keys <= finished_keys(read_runs(records / "sweeps")), "the page's records lack jobs"
    proc = run_script("reproduce.py", "perturbed", "--check", records / "sweeps", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    assert "equal to the committed data" in proc.stderr
    rendered = {p.parent.name for p in (tmp_path / "out" / "rendered").glob("*/*.md")}
    assert {"goal", "single", "kinds", "fleet", "fleet_g", "fleet_kinds"} <= rendered, rendered
    for name in ("kinds", "fleet_kinds"):  # the figures the page shows, drawn from the same records
        png = tmp_path / "out" / "rendered" / name / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert f"](perturbed/{name}.png)" in (ROOT / "docs" / "PERTURBED.md").read_text()
        assert (ROOT / "docs" / "perturbed" / f"{name}.png").is_file()


def test_records_keep_what_a_page_reads_and_leave_a_learners_training_rows_behind(tmp_path):
    """A learner's records (the perturbed page's, committed) are its config, results, evaluation
    episodes and log; its ``train_episodes.csv`` (3,000 rows no page reads) is left behind, so no
    committed record holds one."""
    committed = ROOT / "docs" / "perturbed" / "runs"
    assert not [p for p in ROOT.glob(f"docs/*/runs/sweeps/**/{TRAIN_CSV}")]
    out, dest = tmp_path / "out", tmp_path / "records"
    shutil.copytree(committed, out)
    learner = next(p.parent for p in sorted((out / "sweeps").rglob("results.json"))
                   if "ddqn" in str(p) and p.parent.parent.name.startswith("single"))  # single target
    (learner / TRAIN_CSV).write_text("episode,seed,travel_time\n0,7,93.0\n")  # as training writes it
    copied = {p.as_posix() for p in keep_records(out, dest, "perturbed")}
    rel = learner.relative_to(out).as_posix()
    assert {f"{rel}/results.json", f"{rel}/episodes.csv", f"{rel}/baseline_greedy_episodes.csv",
            f"{rel}/train.log", f"{rel}/.hydra/config.yaml", "reproduce.json"} <= copied  # fmt: skip
    assert not [name for name in copied if name.endswith(TRAIN_CSV)]
    assert (learner / TRAIN_CSV).is_file()  # the output folder keeps it


@pytest.mark.slow
@pytest.mark.parametrize("page", sorted(SHIPPED_JOBS))
def test_every_job_of_a_shipped_page_composes(page):
    """Every value of every swept axis, with the sweep's other overrides, composed by Hydra against
    ``conf/`` (each job's overrides are a product of these values: a typo fails here); the jobs record
    the task and regime the page says, and the rows its renders read are rows the jobs make."""
    definition = load_page(page, PAGES)
    register_configs(CONF)
    rows = set()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        for sweep in definition.sweeps:
            jobs = sweep.jobs()
            axes = [sorted({job[i] for job in jobs}) for i in range(len(jobs[0]))]
            for k in range(max(map(len, axes))):  # lockstep over the axes: every value at least once
                overrides = [values[k % len(values)] for values in axes]
                cfg = compose(Path(sweep.script).stem, overrides=overrides)
                assert (cfg.task, cfg.regime) == (sweep.task, sweep.regime), (sweep.name, overrides)
                world = world_label(OmegaConf.to_container(cfg, resolve=True))
                agent = f"sb3_{cfg.sb3.algo}" if sweep.script == "train_sb3.py" else str(cfg.agent.name)
                rows |= {(world, a) for a in [agent, *cfg.eval.baselines]}
    for render in definition.renders:
        for row in render.options.get("rows", ()):
            for side in ("a", "b"):
                assert tuple(row[side].rsplit("/", 1)) in rows, (row[side], sorted(rows))
        assert set(render.options.get("order", ())) <= {a for _, a in rows}
        for ref in render.options.get("references", ()):  # compare renders
            assert tuple(ref.rsplit("/", 1)) in rows, (render.name, ref, sorted(rows))
        assert set(render.options.get("worlds", ())) <= {w for w, _ in rows}, (render.name, sorted(rows))


def test_a_page_definition_is_checked_with_the_allowed_values_named(tmp_path):
    def refused(data: dict[str, Any]) -> str:
        path = tmp_path / "p.yaml"
        path.write_text(yaml.safe_dump(data))
        with pytest.raises(PageError) as info:
            load_page(str(path), PAGES)
        return str(info.value)

    page = tiny_page(["evs=30"])
    sweep = page["sweeps"][0]
    assert "script='run.py': choose among train.py, evaluate.py, train_sb3.py" in refused(
        {**page, "sweeps": [{**sweep, "script": "run.py"}, page["sweeps"][1]]})  # fmt: skip
    assert "kind='pie': choose among table, fleet_table, seed_rows, paired_rows" in refused(
        {**page, "renders": [{**page["renders"][0], "kind": "pie"}]})  # fmt: skip
    assert "sweeps ['nope']: the page's sweeps are greedy, queue" in refused(
        {**page, "renders": [{**page["renders"][0], "sweeps": ["nope"]}]})  # fmt: skip
    csv_entry = page["renders"][0]["compare"][0]
    table = {**page["renders"][0], "compare": [{**csv_entry, "ignore_regions": ["fleet-cost"]}]}
    assert "ignore_regions belongs to a regions compare entry, not csv" in refused(
        {**page, "renders": [table]})  # fmt: skip
    assert "two sweeps share a job" in refused(
        {**page, "sweeps": [sweep, {**sweep, "name": "again"}], "renders": []}
    )
    worlds = page["renders"][-1]  # a compare render: its figure draws each row minus itself calm
    plain = {**worlds, "options": {**worlds["options"], "against_calm": False, "figure": True}}
    assert "figure: True is drawn by a compare render with against_calm: true" in refused(
        {**page, "renders": [plain]})  # fmt: skip
    seeds = {**page["renders"][1], "options": {"order": ["greedy"], "figure": True}}  # not a compare render
    assert "figure: True is drawn by a compare render" in refused({**page, "renders": [seeds]})
    with pytest.raises(
        PageError, match=r"no page 'results\.yml': the pages are fleet, perturbed, readme, results, room"
    ):
        load_page("results.yml", PAGES)


def test_missing_jobs_are_grouped_into_the_fewest_multiruns():
    page = load_page("results", PAGES)
    jobs = page.jobs()
    left = [
        j for j in jobs if "evs=400" in j.overrides and ("seed=3" in j.overrides or "seed=4" in j.overrides)
    ]
    ((sweep, overrides, n),) = job_groups(left)
    assert n == 12 and "seed=3,4" in overrides and "evs=400" in overrides
    assert "agent=dueling_ddqn,dqn,hindsight,queue_aware,greedy,random" in overrides
    odd = [jobs[0], jobs[-1]]
    assert [g[1] for g in job_groups(odd)] == [j.overrides for j in odd]
    # a sweep stopped after its first four jobs resumes as three multiruns, not 86 one after another
    groups = job_groups(jobs[4:])
    assert [n for _, _, n in groups] == [2, 9, 75]
    assert "seed=1" in groups[0][1] and "evs=300,400" in groups[0][1]
    assert "seed=2,3,4" in groups[1][1] and "agent=dqn,hindsight,queue_aware,greedy,random" in groups[2][1]
    covered = [
        job_key(combo)
        for _, overrides, _ in groups
        for combo in itertools.product(*([f"{k}={v}" for v in vs.split(",")]
                                         for k, vs in (o.split("=") for o in overrides)))
    ]  # fmt: skip
    assert len(covered) == 86 and set(covered) == {j.key for j in jobs[4:]}
    assert isinstance(jobs[0], PageJob) and sweep.name == "table"


# ---------------------------------------------------------------------------------------- comparisons
def test_csv_rows_are_compared_by_job_key_and_column(tmp_path):
    committed, rendered = tmp_path / "old.csv", tmp_path / "new.csv"
    committed.write_text("agent,seed,mean,wall,old_only\ngreedy,0,1.0,5,x\ngreedy,1,nan,5,x\ndqn,0,2.0,5,x\n")
    rendered.write_text("agent,seed,mean,wall,new_only\ngreedy,1,nan,7,y\ngreedy,0,1,9,y\nrandom,0,3.0,1,y\n")
    found, notes = csv_differences(rendered, committed, ("agent", "seed"), ("wall",), "old.csv")
    assert found == ["old.csv: row agent=dqn seed=0: in the committed file, not rendered",
                     "old.csv: row agent=random seed=0: rendered, not in the committed file"]  # fmt: skip
    assert notes == ["old.csv: column 'new_only' only in the rendering: not compared",
                     "old.csv: column 'old_only' only in the committed file: not compared"]  # fmt: skip
    rendered.write_text("agent,seed,mean\ngreedy,0,1.5\ngreedy,1,nan\ndqn,0,2.0\n")
    found, _ = csv_differences(rendered, committed, ("agent", "seed"), (), "old.csv")
    assert found == ["old.csv: row agent=greedy seed=0: column 'mean': '1.0' -> '1.5'"]


PAGE = """# A page

```bash
# a comment in code, not a heading
```

## Section

| agent | EVs | mean | wall |
|---|---:|---:|---:|
| greedy | 200 | **1.0** | 5 |
| greedy | 300 | 2.0 | 5 |
| other | 200 | 9.0 | 5 |

## Next

| agent | EVs | mean | wall |
|---|---:|---:|---:|
| greedy | 200 | 7.0 | 5 |
"""


def test_markdown_tables_are_compared_by_header_row_and_column():
    rendered = "\n".join(["| agent | EVs | mean | wall |", "|---|---|---|---|", "| greedy | 200 | 1.0 | 6 |",
                          "| greedy | 300 | 2.5 | 6 |"])  # fmt: skip
    found, notes = markdown_differences(rendered, PAGE, "p.md", "## Section", ("wall",))
    assert found == ["p.md:12: column 'mean' of row 'greedy | 300': '2.0' -> '2.5'"]  # bold and wall ignored
    assert notes == ["p.md:9: 1 row(s) of table 'agent | EVs | mean | wall' not made by this page's jobs"]
    found, _ = markdown_differences(
        rendered.replace("| 300 |", "| 400 |"), PAGE, "p.md", "## Section", ("wall",)
    )
    assert found == ["p.md:9: row 'greedy | 400' of table 'agent | EVs | mean | wall': not on the page"]
    found, _ = markdown_differences(rendered, PAGE, "p.md", "## Next", ("wall",))
    assert found[0] == "p.md:19: column 'mean' of row 'greedy | 200': '7.0' -> '1.0'"
    assert markdown_differences(rendered, PAGE, "p.md", "## Absent")[0] == ["p.md: no heading '## Absent'"]
    # a section whose tables are of another shape than the rendering's compares nothing: a difference
    reshaped = rendered.replace("| mean | wall |", "| mean (s) | wall |", 1)
    found, notes = markdown_differences(reshaped, PAGE, "p.md", "## Section", ("wall",))
    assert notes == ["p.md: no table 'agent | EVs | mean (s) | wall' on the page under '## Section'"]
    assert found == ["p.md: none of the 1 rendered table(s) is on the page under '## Section' (its tables: "
                     "'agent | EVs | mean | wall')"]  # fmt: skip
    assert section_lines(PAGE, "## Section")[0][0] == 8  # the code's "#" is not a heading


def test_a_pages_generated_regions_are_rendered_from_the_new_data(tmp_path):
    assert region_differences("README.md", ROOT, {"docs/results.csv": ROOT / "docs" / "results.csv"}) == []
    new = tmp_path / "results.csv"
    row = "table,random,200,0,50,50,0,"
    new.write_text((ROOT / "docs" / "results.csv").read_text().replace(f"{row}480.1,", f"{row}481.1,", 1))
    (found,) = region_differences("README.md", ROOT, {"docs/results.csv": new})
    assert (
        "README.md:" in found and "column 'random' of row '200': '536.8 [471.4, 602.2]' -> '537.0 [" in found
    )
    # an ignored region is not rendered (the changed data leave the page as it is); a name the page lacks
    # is a difference
    assert region_differences("README.md", ROOT, {"docs/results.csv": new}, ignore=["results-headline"]) == []
    ignore = ["results-headline", "no-such"]
    (lacking,) = region_differences("README.md", ROOT, {"docs/results.csv": new}, ignore=ignore)
    assert lacking.startswith("README.md: no generated region 'no-such' to ignore (its regions: results-")
