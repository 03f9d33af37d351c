"""scripts/make_table.py, evcd.report.table and evcd.report.sweep on synthetic multirun directories
(no SUMO; the statistics alone: tests/report/test_seed_stats.py).

A helper writes what ``scripts/train.py -m`` leaves behind: ``multirun.yaml`` with the sweep's task
overrides, one subdirectory per job with ``.hydra/overrides.yaml``, ``train.log``, ``results.json`` and,
for learners, ``train_episodes.csv``. The numbers are chosen so that every mean, interval and share
can be computed here by hand.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import statistics
import subprocess
from collections.abc import Callable
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
import yaml

from evcd.env.runners import EpisodeRow
from evcd.loops.run_files import episodes_csv_text
from evcd.report.sweep import IncompleteSweepError, ResultsError, collect, expand_sweep, job_overrides
from evcd.report.table import (
    BARS_PNG,
    CSV_COLUMNS,
    CSV_NAME,
    CURVES_PNG,
    MD_NAME,
    VALIDATION_PNG,
    make_table,
    validation_gaps,
    validation_points,
    validation_rule_means,
)
from tests.conftest import run_script

T_0975_4 = 2.7764451051977987  # Student t, 97.5% quantile, 4 degrees of freedom

AGENTS = ("random", "greedy", "queue_aware", "hindsight", "dqn", "dueling_ddqn")
LEARNERS = ("dqn", "dueling_ddqn")
SEEDS = (0, 1, 2, 3, 4)
EVS = (200, 300)
#: (agent, evs) -> the mean of its seeds' evaluation means; seed s adds SPREAD[s] (+ NOISE for some).
BASE = {
    ("random", 200): 900.0, ("greedy", 200): 400.0, ("queue_aware", 200): 300.0,
    ("hindsight", 200): 200.0, ("dqn", 200): 300.0, ("dueling_ddqn", 200): 250.0,
    ("random", 300): 1300.0, ("greedy", 300): 500.0, ("queue_aware", 300): 480.0,
    ("hindsight", 300): 500.0, ("dqn", 300): 520.0, ("dueling_ddqn", 300): 510.0,
}  # fmt: skip
SPREAD = (-10.0, -5.0, 0.0, 5.0, 10.0)
#: per-seed noise added to some cells, so that their gap share has a real interval / no room
NOISE = {
    ("dueling_ddqn", 200): (12.0, -7.0, 3.0, -15.0, 7.0),
    ("greedy", 300): (0.5, -0.3, 0.2, 0.1, -0.4),
}


def travel(agent: str, evs: int, seed: int) -> float:
    """The synthetic evaluation mean travel time of a job."""
    return BASE[agent, evs] + SPREAD[seed] + NOISE.get((agent, evs), (0.0,) * 5)[seed]


def training_rows(n: int, start: float, end: float, seed: int) -> list[EpisodeRow]:
    """``n`` training episodes whose travel time falls from ``start`` to ``end``; every 17th truncated."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        t = start + (end - start) * i / max(1, n - 1) + float(rng.normal(0, 30))
        trunc = i % 17 == 5
        row = EpisodeRow(episode=i, seed=1000 + i, departure=30000.0, origin="e1", day=0, choices="1-1",
                         station=1, station_id="cs1", travel_time=7200.0 if trunc else t, queue_wait=10.0,
                         reason="slots" if trunc else "charging", truncated=trunc, episode_return=-t / 3600,
                         wall_s=0.1, switches=0)  # fmt: skip
        rows.append(row)
    return rows


def results_json(agent: str, evs: int, seed: int, regime: str | None = "table", truncated: int = 0) -> dict:
    """A results.json as scripts/train.py writes it (the fields make_table reads, and some others)."""
    learns = agent in LEARNERS
    config = {"evs": evs, "seed": seed, "agent": {"name": agent}, "train": {"days": [0], "episodes": 200},
              "eval": {"days": [1], "episodes": 20}, "env": {"demand_seeds": [0]}}  # fmt: skip
    if regime is not None:
        config["regime"] = regime
    mean = travel(agent, evs, seed)
    out = {
        "agent": agent,
        "seed": seed,
        "summary": {
            "episodes": 20,
            "completed": 20 - truncated,
            "truncated": truncated,
            "mean_travel_time": mean,
            "median_travel_time": mean - 7.0,
            "ci_low": mean - 30.0,
            "ci_high": mean + 30.0,
            "ci_level": 0.95,
            "mean_queue_wait": 40.0 + seed,
            "mean_return": -mean / 3600,
            "mean_wall_s": 0.2,
        },
        "episodes": [],
        "config": config,
        "training": {
            "episodes": 200 if learns else 0,
            "episodes_done": 200 if learns else 0,
            "wall_s": 100.0 + 10 * seed if learns else 0.0,
            "day_build_s": 50.0 if learns else 0.0,
            "truncated": 0,
            "mean_travel_time": 600.0 + seed if learns else None,
        },
    }
    if agent == "hindsight":
        out["hindsight"] = {"best_station": [1] * 20}
    return out


def write_sweep(
    root: Path,
    agents: tuple[str, ...] = AGENTS,
    evs: tuple[int, ...] = EVS,
    seeds: tuple[int, ...] = SEEDS,
    regime: str | None = "table",
    experiment: str = "table",
) -> Path:
    """A multirun directory of ``experiment=... agent=... seed=... evs=...`` with every job finished."""
    root.mkdir(parents=True)
    task = [f"experiment={experiment}", f"agent={','.join(agents)}", f"seed={','.join(map(str, seeds))}",
            f"evs={','.join(map(str, evs))}"]  # fmt: skip
    (root / "multirun.yaml").write_text(yaml.safe_dump({
        "hydra": {"mode": "MULTIRUN", "sweep": {"dir": str(root), "subdir": "${hydra.job.num}_..."},
                  "overrides": {"hydra": ["hydra.mode=MULTIRUN"], "task": task}},
        "evs": 400, "seed": 0,
    }))  # fmt: skip
    for num, (agent, seed, n) in enumerate(itertools.product(agents, seeds, evs)):
        job = root / f"{num}_{agent}_evs{n}_seed{seed}"
        (job / ".hydra").mkdir(parents=True)
        overrides = [f"experiment={experiment}", f"agent={agent}", f"seed={seed}", f"evs={n}"]
        (job / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
        (job / ".hydra" / "config.yaml").write_text(yaml.safe_dump({"evs": n, "seed": seed}))
        (job / "train.log").write_text(f"[2026-11-23 10:00:00,000][train][INFO] - {agent} evs={n}\n")
        (job / "results.json").write_text(json.dumps(results_json(agent, n, seed, regime), indent=1))
        if agent in LEARNERS:
            rows = training_rows(200, 900.0, 350.0 if agent == "dqn" else 300.0, seed)
            (job / "train_episodes.csv").write_text(episodes_csv_text(rows))
    return root


def job_dir(sweep: Path, agent: str, evs: int, seed: int) -> Path:
    (found,) = sweep.glob(f"*_{agent}_evs{evs}_seed{seed}")
    return found


def table_row(markdown: str, first_header: str, first_cell: str) -> dict[str, str]:
    """The row starting with ``first_cell`` of the first table whose header starts with ``first_header``."""
    lines = markdown.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    header = [c.strip() for c in lines[start].strip("|").split("|")]
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[0] == first_cell:
            return dict(zip(header, cells, strict=True))
    raise AssertionError(f"no row {first_cell!r} under {first_header!r}")


def hand_cell(values: list[float], quantile: float = T_0975_4) -> str:
    mean = statistics.fmean(values)
    half = quantile * statistics.stdev(values) / math.sqrt(len(values))
    return f"{mean:.1f} [{mean - half:.1f}, {mean + half:.1f}] n={len(values)}"


@pytest.fixture
def sweep(tmp_path: Path) -> Path:
    return write_sweep(tmp_path / "multirun")


@pytest.fixture
def run_table(tmp_path: Path) -> Callable[..., object]:
    def run(*dirs: Path, **kwargs: object):
        kwargs.setdefault("out_dir", tmp_path / "out")
        kwargs.setdefault("resamples", 2000)
        return make_table(list(dirs), **kwargs)

    return run


# ---------------------------------------------------------------------------------------- the sweep
def test_expand_sweep_uses_hydras_parser():
    combos = expand_sweep(["experiment=table", "agent=random,greedy", "seed=range(0,2)", "evs=200"])
    assert combos == [
        ("experiment=table", "agent=random", "seed=0", "evs=200"),
        ("experiment=table", "agent=random", "seed=1", "evs=200"),
        ("experiment=table", "agent=greedy", "seed=0", "evs=200"),
        ("experiment=table", "agent=greedy", "seed=1", "evs=200"),
    ]
    assert expand_sweep(["train.days=[0,2]", "+tag='a,b'"]) == [("train.days=[0,2]", "+tag='a,b'")]
    with pytest.raises(ResultsError, match="interval"):
        expand_sweep(["learner.lr=interval(0.1,0.2)"])
    with pytest.raises(ResultsError, match="parse"):
        expand_sweep(["agent=dqn,"])


def test_collect_reads_every_job(sweep):
    c = collect([sweep])
    assert len(c.jobs) == c.expected == len(AGENTS) * len(SEEDS) * len(EVS)
    assert not c.gaps
    assert [j.key for j in c.jobs] == sorted(j.key for j in c.jobs)
    job = next(j for j in c.jobs if j.key == ("table", "dqn", 300, 2))
    assert job.mean_travel_time == travel("dqn", 300, 2)
    assert (job.train_episodes, job.train_wall_s, job.train_days, job.eval_days) == (200, 120.0, (0,), (1,))
    rule = next(j for j in c.jobs if j.key == ("table", "greedy", 200, 0))
    assert rule.train_episodes == 0 and math.isnan(rule.train_mean_travel_time)


# ---------------------------------------------------------------------------------------- the outputs
@pytest.mark.slow
def test_csv_rows_and_order(sweep, run_table, tmp_path):
    out = run_table(sweep)
    with open(tmp_path / "out" / CSV_NAME, newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        rows = list(reader)
    assert CSV_COLUMNS[:4] == ("regime", "agent", "evs", "seed") and CSV_COLUMNS[-1] == "job_dir"
    order = ("random", "greedy", "queue_aware", "dqn", "dueling_ddqn", "hindsight")
    expected = [(a, n, s) for a in order for n in EVS for s in SEEDS]
    assert [(r["agent"], int(r["evs"]), int(r["seed"])) for r in rows] == expected
    assert [(j.agent, j.evs, j.seed) for j in out.collection.jobs] == expected  # the table's order too
    row = rows[expected.index(("dueling_ddqn", 200, 3))]
    assert row["regime"] == "table"
    assert float(row["mean_travel_time"]) == travel("dueling_ddqn", 200, 3)
    assert float(row["median_travel_time"]) == travel("dueling_ddqn", 200, 3) - 7.0
    assert (int(row["eval_episodes"]), int(row["completed"]), int(row["truncated"])) == (20, 20, 0)
    assert (float(row["mean_queue_wait"]), int(row["train_episodes"])) == (43.0, 200)
    assert (float(row["train_mean_travel_time"]), float(row["train_wall_s"]), float(row["day_build_s"])) == (
        603.0, 130.0, 50.0)  # fmt: skip
    assert (row["train_days"], row["eval_days"]) == ("[0]", "[1]")
    assert Path(row["job_dir"]) == job_dir(sweep, "dueling_ddqn", 200, 3)
    greedy = rows[expected.index(("greedy", 300, 0))]
    assert greedy["train_mean_travel_time"] == "nan" and int(greedy["train_episodes"]) == 0


def test_markdown_cells_match_a_hand_computation(sweep, run_table, tmp_path):
    out = run_table(sweep)
    md = (tmp_path / "out" / MD_NAME).read_text()
    assert md == out.markdown
    for evs in EVS:
        row = table_row(md, "EVs", str(evs))
        for agent in AGENTS:
            assert row[agent] == hand_cell([travel(agent, evs, s) for s in SEEDS]), (agent, evs)
    row = table_row(md, "EVs", "200")
    assert row["greedy"] == "400.0 [390.2, 409.8] n=5"  # 2.776 * stdev 7.906 / sqrt(5) = 9.8
    assert (row["paper random"], row["paper greedy"], row["paper DQN"], row["paper Dueling DDQN"]) == (
        "942", "750", "545", "632")  # fmt: skip
    assert table_row(md, "EVs", "300")["paper Dueling DDQN"] == "587"
    assert "Jobs: 60 (6 agents, EV counts 200, 300, 5 seeds: 0, 1, 2, 3, 4); 20 evaluation episodes" in md
    assert "200 training episodes per learner; training days [0], evaluation days [1]." in md


def test_markdown_gap_shares(sweep, run_table):
    md = run_table(sweep).markdown
    gap_lines = md[md.index("### Share of the greedy") :]
    row = table_row(gap_lines, "EVs", "200")
    assert row["queue_aware"] == "0.50 [0.50, 0.50] n=5" and row["dqn"] == "0.50 [0.50, 0.50] n=5"
    assert row["dueling_ddqn"].startswith("0.75 [")
    assert row["greedy - hindsight (s)"] == "200.0 [200.0, 200.0] n=5"
    row = table_row(gap_lines, "EVs", "300")
    assert row["queue_aware"] == row["dqn"] == row["dueling_ddqn"] == "no room"


def test_details_and_no_paper_table_without_paper_jobs(sweep, run_table):
    md = run_table(sweep).markdown
    details = md[md.index("### Per agent and EV count") :]
    row = table_row(details, "agent", "dqn")
    assert row == {"agent": "dqn", "EVs": "200", "seeds": "5", "truncated / episodes": "0 / 100",
                   "mean queue wait (s)": "42.0", "training wall time (s)": "120"}  # fmt: skip
    assert table_row(details, "agent", "greedy")["training wall time (s)"] == "—"
    assert "The paper's way" not in md


def test_several_dirs_a_paper_sweep_and_a_single_run(sweep, run_table, tmp_path):
    paper = write_sweep(tmp_path / "paper", agents=("greedy", "dqn"), evs=(200,), seeds=(0, 1),
                        regime="paper", experiment="paper")  # fmt: skip
    single = tmp_path / "single"
    (single / ".hydra").mkdir(parents=True)
    (single / "results.json").write_text(json.dumps(results_json("random", 200, 0, regime=None)))
    out = run_table(sweep, paper, single)
    md = out.markdown
    assert "## Regime `paper`" in md and "## Regime `table`" in md and "## Regime `unknown`" in md
    part = md[md.index("### The paper's way") :]
    row = table_row(part, "agent", "dqn")
    assert row["training mean (s)"] == hand_cell([600.0, 601.0], quantile=12.7062047362)
    assert row["evaluation mean (s)"] == hand_cell([travel("dqn", 200, s) for s in (0, 1)], 12.7062047362)
    assert row["paper (s)"] == "545"
    assert table_row(part, "agent", "greedy")["training mean (s)"] == "—"
    unknown = md[md.index("## Regime `unknown`") :]
    assert table_row(unknown, "EVs", "200")["random"] == f"{travel('random', 200, 0):.1f} n=1"
    assert len(out.collection.jobs) == 60 + 4 + 1


def test_failed_and_missing_jobs_stop_the_table(sweep, run_table, tmp_path):
    failed = job_dir(sweep, "dqn", 300, 3)
    (failed / "results.json").unlink()
    (failed / "train.log").write_text(
        "[2026-11-23 10:00:00,000][train][INFO] - training\n"
        "Traceback (most recent call last):\n"
        '  File "scripts/train.py", line 10, in main\n'
        "    train(cfg)\n"
        "RuntimeError: SUMO crashed at step 4711\n"
        "[2026-11-23 10:00:02,000][train][INFO] - closing\n"
    )  # fmt: skip
    broken = job_dir(sweep, "greedy", 200, 1)
    (broken / "results.json").write_text('{"agent": "greedy", "summ')
    missing = job_dir(sweep, "hindsight", 200, 4)
    for path in sorted(missing.rglob("*"), reverse=True):
        path.unlink() if path.is_file() else path.rmdir()
    missing.rmdir()
    with pytest.raises(IncompleteSweepError) as info:
        run_table(sweep)
    msg = str(info.value)
    assert "3 of 60 expected jobs" in msg
    assert "failed: experiment=table agent=dqn seed=3 evs=300" in msg and str(failed) in msg
    assert "RuntimeError: SUMO crashed at step 4711" in msg
    assert "failed: experiment=table agent=greedy seed=1 evs=200" in msg and "unreadable" in msg
    assert "missing: experiment=table agent=hindsight seed=4 evs=200" in msg
    assert {g.status for g in info.value.gaps} == {"failed", "missing"}
    assert isinstance(info.value, ValueError)
    assert not (tmp_path / "out").exists()  # nothing written

    out = run_table(sweep, allow_incomplete=True)
    md = out.markdown
    assert "## Missing or failed jobs (1 missing, 2 failed)" in md
    assert "- missing: experiment=table agent=hindsight seed=4 evs=200" in md
    assert "RuntimeError: SUMO crashed at step 4711" in md
    assert len(out.collection.jobs) == 57
    assert table_row(md, "EVs", "300")["dqn"] == hand_cell([travel("dqn", 300, s) for s in (0, 1, 2, 4)],
                                                           quantile=3.1824463053)  # fmt: skip


def test_an_error_line_of_the_log_names_a_failed_job(sweep):
    failed = job_dir(sweep, "random", 200, 0)
    (failed / "results.json").unlink()
    with open(failed / "train.log", "a") as f:
        f.write("[2026-11-23 10:00:01,000][train][ERROR] - evs=-1: must be an integer >= 0\n")
    with pytest.raises(IncompleteSweepError, match="evs=-1: must be an integer >= 0"):
        collect([sweep])


def test_a_job_without_results_or_error_may_still_be_running(sweep):
    running = job_dir(sweep, "random", 200, 0)
    (running / "results.json").unlink()
    with pytest.raises(IncompleteSweepError) as info:
        collect([sweep])
    assert f"in {running}: no results.json; no error in its log: stopped, or still running" in str(info.value)


def test_duplicate_jobs_and_non_run_directories_are_refused(sweep, tmp_path):
    with pytest.raises(ResultsError, match="same \\(regime, agent, evs, seed\\)"):
        collect([sweep, job_dir(sweep, "dqn", 200, 0)])
    (tmp_path / "empty").mkdir()
    with pytest.raises(ResultsError, match="neither a multirun directory"):
        collect([tmp_path / "empty"])


@pytest.mark.slow
def test_refuses_to_overwrite(sweep, run_table, tmp_path):
    run_table(sweep)
    md = tmp_path / "out" / MD_NAME
    md.write_text("edited by hand\n")
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        run_table(sweep)
    assert md.read_text() == "edited by hand\n"
    run_table(sweep, overwrite=True)
    assert md.read_text().startswith("# Results over seeds")


def test_default_output_is_the_first_directory(sweep):
    out = make_table([sweep], resamples=200)
    assert {p.name for p in out.paths} == {CSV_NAME, MD_NAME, BARS_PNG, CURVES_PNG}
    assert all(p.parent == sweep for p in out.paths)


def test_both_figures_are_written(sweep, run_table, tmp_path):
    run_table(sweep)
    for name in (BARS_PNG, CURVES_PNG):
        path = tmp_path / "out" / name
        assert path.stat().st_size > 20_000, name
        image = matplotlib.image.imread(path)
        assert image.shape[0] > 400 and image.shape[1] > 800 and image.std() > 0.05, name
    assert not list((tmp_path / "out").glob(".*.tmp"))


def test_no_learning_curves_without_learners(tmp_path, run_table, caplog):
    rules = write_sweep(tmp_path / "rules", agents=("random", "greedy"), evs=(200,), seeds=(0, 1))
    with caplog.at_level("INFO"):
        out = run_table(rules)
    assert (tmp_path / "out" / BARS_PNG).is_file() and not (tmp_path / "out" / CURVES_PNG).exists()
    assert "not drawn" in caplog.text
    assert "Needs greedy, hindsight" in out.markdown


# ---------------------------------------------------------------------------------------- the script
def make_table_script(*args: object) -> subprocess.CompletedProcess[str]:
    return run_script("make_table.py", *map(str, args), "--resamples", "500", timeout=300)


@pytest.mark.slow
def test_script_exit_codes(tmp_path):
    agents = ("greedy", "hindsight", "dqn")
    sweep = write_sweep(tmp_path / "multirun", agents=agents, evs=(200,), seeds=(0, 1))
    done = make_table_script(sweep, "--out", tmp_path / "out")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("# Results over seeds") and "| 200 |" in done.stdout
    assert (tmp_path / "out" / MD_NAME).read_text() == done.stdout

    again = make_table_script(sweep, "--out", tmp_path / "out")
    assert again.returncode == 2 and "refusing to overwrite" in again.stderr

    (job_dir(sweep, "dqn", 200, 1) / "results.json").unlink()
    failed = make_table_script(sweep, "--out", tmp_path / "out2")
    assert failed.returncode == 1
    assert "failed: experiment=table agent=dqn seed=1 evs=200" in failed.stderr
    assert "--allow-incomplete" in failed.stderr and not (tmp_path / "out2").exists()

    partial = make_table_script(sweep, "--out", tmp_path / "out2", "--allow-incomplete")
    assert partial.returncode == 0, partial.stderr
    assert "- failed: experiment=table agent=dqn seed=1 evs=200" in partial.stdout
    rows = list(csv.DictReader(io.StringIO((tmp_path / "out2" / CSV_NAME).read_text())))
    assert len(rows) == 5

    for missing, why in ((tmp_path / "nonexistent", "does not exist"), (tmp_path / "out2" / CSV_NAME,
                                                                        "is not a directory")):  # fmt: skip
        bad = make_table_script(missing, "--out", tmp_path / "out3")
        assert bad.returncode == 2 and f"{missing} {why}" in bad.stderr


# ---------------------------------------------------------------------------------------- days and pairs
#: queue_aware's travel times of the 4 evaluation episodes of seed s are QA + 10 s; dqn adds
#: DQN_OFFSET + 4 s (mean difference 5 + 4 s); dueling_ddqn adds DDQN_OFFSET to dqn's, and its last
#: episode of seed 2 is truncated (left out of its pairs).
QA = (100.0, 200.0, 300.0, 400.0)
DQN_OFFSET = (10.0, -20.0, 30.0, 0.0)
DDQN_OFFSET = (5.0, 5.0, 5.0, -15.0)


def episode_times(agent: str, seed: int) -> list[float]:
    qa = [t + 10 * seed for t in QA]
    dqn = [q + d + 4 * seed for q, d in zip(qa, DQN_OFFSET, strict=True)]
    return {
        "queue_aware": qa,
        "dqn": dqn,
        "dueling_ddqn": [t + d for t, d in zip(dqn, DDQN_OFFSET, strict=True)],
    }[agent]


def write_day_sweep(root: Path) -> Path:
    """Three agents, three seeds, each seed evaluated on its own day (101 + seed), 4 episodes each."""
    agents, seeds = ("queue_aware", "dqn", "dueling_ddqn"), (0, 1, 2)
    write_sweep(root, agents=agents, evs=(200,), seeds=seeds)
    for agent, seed in itertools.product(agents, seeds):
        path = job_dir(root, agent, 200, seed) / "results.json"
        data = json.loads(path.read_text())
        times = episode_times(agent, seed)
        truncated = [agent == "dueling_ddqn" and seed == 2 and k == 3 for k in range(4)]
        data["episodes"] = [
            {"episode": k, "seed": 500 + k, "day": 101 + seed, "travel_time": t, "truncated": trunc}
            for k, (t, trunc) in enumerate(zip(times, truncated, strict=True))
        ]
        data["config"]["eval"]["days"] = [101, 102, 103]  # day_per_seed: the configured list, one played
        path.write_text(json.dumps(data))
    return root


def section_row(markdown: str, section: str, first_header: str, first_cell: str) -> dict[str, str]:
    """:func:`table_row` within the section headed ``section``."""
    lines = markdown.splitlines()
    return table_row("\n".join(lines[lines.index(section) :]), first_header, first_cell)


def test_cells_name_their_days_and_their_per_day_means(tmp_path):
    sweep = write_day_sweep(tmp_path / "days")
    jobs = {(j.agent, j.seed): j for j in collect([sweep]).jobs}
    assert jobs["queue_aware", 1].eval_days == (102,)  # the day it played, not the configured list
    assert jobs["queue_aware", 1].day_means == ((102, statistics.mean(QA) + 10),)
    out = make_table([sweep], tmp_path / "out", resamples=200)
    days = section_row(out.markdown, "### Evaluation days", "agent", "queue_aware")
    assert days["days"] == "3"
    assert (
        days["per day: mean travel time (s)"]
        == "101 (seed 0): 250.0, 102 (seed 1): 260.0, 103 (seed 2): 270.0"
    )
    rows = list(csv.DictReader(io.StringIO((tmp_path / "out" / CSV_NAME).read_text())))
    assert {r["eval_days"] for r in rows} == {"[101]", "[102]", "[103]"}


def test_paired_differences_are_by_episode_within_seed_then_across_seeds(tmp_path):
    out = make_table([write_day_sweep(tmp_path / "days")], tmp_path / "out", resamples=200)
    row = section_row(out.markdown, "### Paired differences (s)", "EVs", "200")
    # dqn - queue_aware: per seed 5 + 4 s -> 5, 9, 13; mean 9, t interval 9 +- t(0.975, 2) * 4 / sqrt(3)
    half = 4.302652729911275 * 4.0 / math.sqrt(3)
    # faster / slower pairs: one faster in each seed (the -20), the others slower but seed 0's 0
    assert row["dqn - queue_aware"] == f"+9.0 [{9 - half:+.1f}, {9 + half:+.1f}] n=3; 3 / 8 of 12"
    # dueling_ddqn - dqn: 0 in seeds 0 and 1; seed 2 without its truncated episode: +5
    assert row["dueling_ddqn - dqn"].startswith("+1.7 [") and row["dueling_ddqn - dqn"].endswith(
        "; 2 / 9 of 11"
    )
    per_seed = section_row(out.markdown, "### Paired differences (s)", "pair", "dqn - queue_aware")
    assert per_seed["per seed (seed: mean difference, s)"] == "0: +5.0 / 1: +9.0 / 2: +13.0"


def test_validation_curves_average_the_seeds_and_stay_out_of_the_csv(tmp_path):
    root = write_sweep(tmp_path / "val", agents=("greedy", "dqn"), evs=(200,), seeds=(0, 1))
    for seed in (0, 1):
        path = job_dir(root, "dqn", 200, seed) / "results.json"
        data = json.loads(path.read_text())
        data["validation"] = {
            "points": [{"episodes_done": e, "transitions": 10 * e, "mean": 500.0 - e / 2 + seed * 10,
                        "travel_times": []} for e in (100, 200)],
            "rules": {},
            "rule_means": {"greedy": 450.0 + seed, "queue_aware": 320.0 + 3 * seed},
        }  # fmt: skip
        path.write_text(json.dumps(data))
    jobs = {(j.agent, j.seed): j for j in collect([root]).jobs}
    assert jobs["dqn", 1].validation == ((100, 460.0), (200, 410.0))
    assert jobs["greedy", 0].validation == ()
    assert validation_rule_means(jobs.values()) == {("table", 200): {"greedy": 450.5, "queue_aware": 321.5}}
    seeds = [[(100, 450.0), (200, 400.0)], [(100, 460.0), (200, 410.0)]]
    assert validation_points(jobs.values())[("table", 200)]["dqn"] == seeds
    # paired with each seed's own queue_aware mean on the same episodes (320 and 323 s)
    assert validation_gaps(jobs.values()) == {
        ("table", 200): {"dqn": [[(100, 130.0), (200, 80.0)], [(100, 137.0), (200, 87.0)]]}
    }
    assert validation_gaps(jobs.values(), "greedy")[("table", 200)]["dqn"][1] == [(100, 9.0), (200, -41.0)]
    assert validation_gaps(jobs.values(), "central") == {}  # no job validated against it
    out = make_table([root], tmp_path / "out", resamples=200)
    assert VALIDATION_PNG in {p.name for p in out.paths}
    image = matplotlib.image.imread(tmp_path / "out" / VALIDATION_PNG)
    assert image.shape[1] > 400 and image.std() > 0.05
    header = (tmp_path / "out" / CSV_NAME).read_text().splitlines()[0].split(",")
    assert "validation" not in header and "episode_travel" not in header and "eval_days" in header
    # the same gaps over seeds, per training length: 133.5 +- t(0.975, 1) * 3.5 = 44.5 after 100
    assert "| EVs | agent | after 100 | after 200 |" in out.markdown
    assert "| 200 | dqn | +133.5 [+89.0, +178.0] n=2 | +83.5 [+39.0, +128.0] n=2 |" in out.markdown
    assert "| 200 | greedy |" not in out.markdown.split("### Validation by training length")[1]


def test_a_jobs_identity_leaves_out_where_its_days_were_cached_and_whether_it_resumed(tmp_path):
    (tmp_path / ".hydra").mkdir()
    recorded = ["experiment=fleet", "seed=3", "env.cache_dir=/scratch/days", "resume=true", "agent=dqn"]
    (tmp_path / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(recorded))
    assert job_overrides(tmp_path) == ("experiment=fleet", "seed=3", "agent=dqn")
