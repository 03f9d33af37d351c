"""The fleet table (evcd.report.fleet_table, ``scripts/make_table.py --fleet``) on a synthetic sweep of
fleet runs (no SUMO), with every mean, interval and paired difference computed here by hand."""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import statistics
from pathlib import Path

import matplotlib.image
import pytest
import yaml

from evcd.report.fleet_table import (
    BARS_PNG,
    CSV_NAME,
    MD_NAME,
    VALIDATION_PNG,
    fleet_job,
    make_fleet_table,
    paired_fleet,
)
from evcd.report.sweep import ResultsError, WrongTaskError, collect
from evcd.report.table import validation_gaps, validation_points
from tests.conftest import run_script
from tests.report.test_make_table import results_json as single_results_json

T_0975_2 = 4.302652729749464  # Student t, 97.5% quantile, 2 degrees of freedom

AGENTS = ("queue_aware", "reservation", "central", "dqn", "dueling_ddqn")
SEEDS = (0, 1, 2)
SHARES = (0.5, 1.0)
BASE = {
    ("queue_aware", 0.5): 300.0, ("reservation", 0.5): 320.0, ("dqn", 0.5): 310.0,
    ("dueling_ddqn", 0.5): 290.0, ("queue_aware", 1.0): 700.0, ("reservation", 1.0): 650.0,
    ("dqn", 1.0): 640.0, ("dueling_ddqn", 1.0): 600.0, ("central", 0.5): 280.0, ("central", 1.0): 620.0,
}  # fmt: skip
SPREAD = (-5.0, 0.0, 5.0)
#: per-seed noise of the learners, so that their paired differences have a real interval
NOISE = {"dqn": (3.0, -1.0, -2.0), "dueling_ddqn": (-4.0, 0.0, 4.0)}
#: per episode (two a job) around the job's mean
OFFSETS = (-10.0, 10.0)


def guided(agent: str, share: float, seed: int, episode: int) -> float:
    return BASE[agent, share] + SPREAD[seed] + NOISE.get(agent, (0.0,) * 3)[seed] + OFFSETS[episode]


def fleet_results(agent: str, share: float, seed: int) -> dict:
    """A results.json as ``scripts/train.py experiment=fleet`` writes it (the fields the table reads)."""
    episodes = [{"episode": i, "day": 101 + (seed + i) % 2, "transitions": 100, "wall_s": 20.0, "guided": 10,
                 "guided_charged": 10, "truncated": 0, "guided_travel": guided(agent, share, seed, i),
                 "queue_wait": 30.0, "all_evs": 20, "all_unfinished": 0,
                 "all_travel": guided(agent, share, seed, i) + 100.0, "herding": 0.5, "switches": 0.1}
                for i in range(2)]  # fmt: skip
    mean = statistics.mean(e["guided_travel"] for e in episodes)
    learns = agent in ("dqn", "dueling_ddqn")
    return {
        "task": "fleet",
        "agent": agent,
        "seed": seed,
        "summary": {
            "episodes": 2,
            "seed": seed,
            "guided_travel": mean,
            "guided_travel_ci": [mean - 9, mean + 9],
            "all_travel": mean + 100.0,
            "all_travel_ci": [0, 0],
            "queue_wait": 30.0,
            "herding": 0.5,
            "guided": 20,
            "truncated": 1 if agent == "reservation" else 0,
            "guided_travel_censored": mean + (50.0 if agent == "reservation" else 0.0),
            "all_unfinished": 0,
            "transitions": 200,
            "mean_wall_s": 20.0,
        },
        "episodes": episodes,
        "baselines": {},
        "training": {
            "episodes": 60 if learns else 0,
            "transitions": 9000 if learns else 0,
            "wall_s": 1500.0 if learns else 0.0,
        },
        "config": {"regime": "fleet", "evs": 400, "seed": seed, "fleet": {"guided_share": share}},
    }


def write_fleet_sweep(root: Path, agents: tuple[str, ...] = AGENTS) -> Path:
    root.mkdir(parents=True)
    task = ["experiment=fleet", f"agent={','.join(agents)}", f"seed={','.join(map(str, SEEDS))}",
            f"fleet.guided_share={','.join(map(str, SHARES))}"]  # fmt: skip
    (root / "multirun.yaml").write_text(yaml.safe_dump({"hydra": {"overrides": {"task": task}}}))
    for num, (agent, seed, share) in enumerate(itertools.product(agents, SEEDS, SHARES)):
        job = root / f"{num}_{agent}_share{share}_seed{seed}"
        (job / ".hydra").mkdir(parents=True)
        overrides = ["experiment=fleet", f"agent={agent}", f"seed={seed}", f"fleet.guided_share={share}"]
        (job / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
        (job / "results.json").write_text(json.dumps(fleet_results(agent, share, seed)))
    return root


def row(markdown: str, title: str, first: list[str]) -> dict[str, str]:
    """The row starting with ``first`` of the table that follows the heading ``title``."""
    lines = markdown.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(title))
    header_at = next(i for i in range(start, len(lines)) if lines[i].startswith("| "))
    header = [c.strip() for c in lines[header_at].strip("|").split("|")]
    for line in lines[header_at + 2 :]:
        if not line.startswith("| "):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[: len(first)] == first:
            return dict(zip(header, cells, strict=True))
    raise AssertionError(f"no row {first} under {title}")


def test_the_fleet_table_by_hand(tmp_path) -> None:
    sweep = write_fleet_sweep(tmp_path / "sweep")
    out = make_fleet_table([sweep], tmp_path / "out")
    md = out.markdown
    assert len(out.collection.jobs) == len(AGENTS) * len(SEEDS) * len(SHARES) and not out.collection.gaps
    # jobs written without the environment's and the code's records: the page says so before anything
    assert "**Made with another environment than today's `evcd_fleet_v1`**" in md.split("## ")[0]
    assert "World: `fleet`." in md.split("## ")[0]  # one world: named in the header, no column
    assert row(md, "## Paired differences on the guided EVs", ["400", "1"])[
        "dueling_ddqn - central"
    ].startswith("-20.0 [")
    # the cell: mean over seeds of the jobs' means, t interval across seeds
    half = T_0975_2 * 5.0 / math.sqrt(3)  # SPREAD's sd is 5
    cell = row(md, "## Mean travel time of the guided EVs", ["400", "0.5"])
    assert cell["queue_aware"] == f"300.0 [{300 - half:.1f}, {300 + half:.1f}] n=3"
    everybody = row(md, "## Mean travel time of all EVs", ["400", "1"])
    assert everybody["reservation"].startswith("750.0 [")
    # paired by seed and episode: dqn - queue_aware = base difference + the learner's noise per seed
    noise = NOISE["dqn"]
    sd = statistics.stdev(noise)
    pair = row(md, "## Paired differences on the guided EVs", ["400", "1"])
    low, high = -60.0 - T_0975_2 * sd / math.sqrt(3), -60.0 + T_0975_2 * sd / math.sqrt(3)
    assert pair["dqn - queue_aware"] == f"-60.0 [{low:+.1f}, {high:+.1f}] n=3; 6 / 0 of 6"
    p = paired_fleet(list(out.collection.jobs), ("fleet", 400, 1.0), "dueling_ddqn", "dqn", "guided_travel")
    expected = {s: -40.0 + NOISE["dueling_ddqn"][s] - NOISE["dqn"][s] for s in SEEDS}
    assert p is not None and p.per_seed == pytest.approx(expected) and p.pairs == 6
    # all EVs: the same differences (all_travel = guided + 100 here)
    assert (
        row(md, "## Paired differences on all EVs", ["400", "1"])["dqn - queue_aware"]
        == pair["dqn - queue_aware"]
    )
    detail = row(md, "## Per dispatcher", ["400", "0.5", "reservation"])
    assert detail["truncated"] == "3 of 60" and detail["training"] == "—"
    assert detail["with truncated"] == f"{BASE['reservation', 0.5] + 50.0:.1f}"  # SPREAD and OFFSETS: mean 0
    assert row(md, "## Per dispatcher", ["400", "0.5", "dqn"])["training"] == "180 / 27000 / 75.0"
    # the csv: one row per job; the figure is a real PNG
    rows = list(csv.DictReader(io.StringIO((tmp_path / "out" / CSV_NAME).read_text())))
    assert len(rows) == len(AGENTS) * 6 and {r["eval_days"] for r in rows} == {"101 102"}
    assert (tmp_path / "out" / MD_NAME).read_text() == md
    assert matplotlib.image.imread(tmp_path / "out" / BARS_PNG).shape[0] > 300
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        make_fleet_table([sweep], tmp_path / "out")


def test_runs_made_before_the_censored_measure_leave_its_cell_empty(tmp_path) -> None:
    sweep = write_fleet_sweep(tmp_path / "sweep")
    job = next(sweep.glob("*_reservation_share0.5_seed1")) / "results.json"
    data = json.loads(job.read_text())
    del data["summary"]["guided_travel_censored"]
    job.write_text(json.dumps(data))
    md = make_fleet_table([sweep], tmp_path / "out").markdown
    assert row(md, "## Per dispatcher", ["400", "0.5", "reservation"])["with truncated"] == "—"
    assert row(md, "## Per dispatcher", ["400", "1", "reservation"])["with truncated"] != "—"


def test_a_nan_episode_is_left_out_of_its_pairs(tmp_path) -> None:
    sweep = write_fleet_sweep(tmp_path / "sweep", agents=("queue_aware", "dqn"))
    (job,) = sweep.glob("*_dqn_share1.0_seed0")
    data = json.loads((job / "results.json").read_text())
    data["episodes"][1]["guided_travel"] = None  # nobody charged in it
    (job / "results.json").write_text(json.dumps(data))
    parsed = fleet_job(data, job)
    assert math.isnan(parsed.per_episode[1][2])
    jobs = list(collect([sweep], parse=fleet_job).jobs)
    p = paired_fleet(jobs, ("fleet", 400, 1.0), "dqn", "queue_aware", "guided_travel")
    assert p is not None and p.pairs == 5
    assert p.per_seed[0] == pytest.approx(guided("dqn", 1.0, 0, 0) - guided("queue_aware", 1.0, 0, 0))


def write_bound_sweep(
    root: Path, monkeypatch, raise_bound: dict[tuple[int, int], float] | None = None
) -> Path:
    """greedy 500 s, central 300 s, the played plan 200 s, the bound 100 s (each with SPREAD by seed and
    OFFSETS by episode, so the gaps are the same on every seed and episode); ``raise_bound``: (seed,
    episode) -> a bound put in place of that episode's."""
    for agent, mean in {"greedy": 500.0, "central": 300.0, "fleet_bound": 200.0}.items():
        for share in SHARES:
            monkeypatch.setitem(BASE, (agent, share), mean)
    sweep = write_fleet_sweep(root, agents=("greedy", "central", "fleet_bound"))
    for job in sweep.glob("*_fleet_bound_*"):
        data = json.loads((job / "results.json").read_text())
        data["fleet_bound"] = {
            "episodes": [
                {"index": e["episode"], "day": e["day"],
                 "bound": (raise_bound or {}).get((data["seed"], e["episode"]), e["guided_travel"] - 100.0)}
                for e in data["episodes"]
            ]
        }  # fmt: skip
        (job / "results.json").write_text(json.dumps(data))
    return sweep


def test_the_room_table_gives_the_bound_and_the_share_of_the_greedy_to_bound_gap(
    tmp_path, monkeypatch
) -> None:
    # central closes (500 - 300) / (500 - 100) = 0.5 of the greedy -> bound gap, the played plan 0.75
    sweep = write_bound_sweep(tmp_path / "sweep", monkeypatch)
    md = make_fleet_table([sweep], tmp_path / "out").markdown
    room = row(md, "## Room: the clairvoyant bound", ["400", "0.5"])
    half = T_0975_2 * 5.0 / math.sqrt(3)
    assert room["bound (s)"] == f"100.0 [{100 - half:.1f}, {100 + half:.1f}] n=3"
    assert room["central"] == "0.50 [0.50, 0.50] n=3" and room["fleet_bound"] == "0.75 [0.75, 0.75] n=3"
    assert row(md, "## Mean travel time of the guided EVs", ["400", "1"])["fleet_bound"].startswith("200.0 [")
    # the strongest rule (central, not greedy; the bound's played plan is no rule) 100 s above the played
    # plan and 200 s above the bound on every episode, leaving half of the gap
    rule = row(md, "## From the strongest rule to the bound", ["400", "1"])
    assert rule["rule"] == "central" and rule["rule (s)"] == f"300.0 [{300 - half:.1f}, {300 + half:.1f}] n=3"
    assert rule["rule - played plan"] == "+100.0 [+100.0, +100.0] n=3; 0 / 6 of 6"
    assert rule["rule - bound"] == "+200.0 [+200.0, +200.0] n=3; 0 / 6 of 6"
    assert rule["left"] == "0.50"
    below = row(md, "## Below the bound", ["400", "0.5"])
    assert below == {"EVs": "400", "guided share": "0.5", "greedy": "0 of 6", "central": "0 of 6",
                     "fleet_bound (played plan)": "0 of 6"}  # fmt: skip
    rows = list(csv.DictReader(io.StringIO((tmp_path / "out" / CSV_NAME).read_text())))
    assert (
        sorted(float(r["bound"]) for r in rows if r["agent"] == "fleet_bound")
        == [95.0] * 2 + [100.0] * 2 + [105.0] * 2
    )
    assert all(r["bound"] == "nan" for r in rows if r["agent"] != "fleet_bound")
    # without a bound job there is no room table
    plain = make_fleet_table([write_fleet_sweep(tmp_path / "plain")], tmp_path / "o2").markdown
    assert "## Room" not in plain and "## Below the bound" not in plain


def test_episodes_below_the_bound_are_counted_with_their_margin(tmp_path, monkeypatch) -> None:
    # seed 0's first episode: central 300 - 5 - 10 = 285 s, greedy 485 s, the played plan 185 s; a bound
    # of 292 s puts central 7 s and the played plan 107 s below it, greedy above
    sweep = write_bound_sweep(tmp_path / "sweep", monkeypatch, raise_bound={(0, 0): 292.0})
    md = make_fleet_table([sweep], tmp_path / "out").markdown
    for share in ("0.5", "1"):
        below = row(md, "## Below the bound", ["400", share])
        assert below["greedy"] == "0 of 6"
        assert below["central"] == "1 of 6 (up to 7.0 s)"
        assert below["fleet_bound (played plan)"] == "1 of 6 (up to 107.0 s)"
    rule = row(md, "## From the strongest rule to the bound", ["400", "1"])
    assert rule["rule - bound"].endswith("; 1 / 5 of 6")


def test_a_single_target_job_is_not_a_fleet_job_and_the_reverse(tmp_path) -> None:
    """A job of the other task is not a job that did not finish: the table is refused, naming the job
    and the flag (not the incomplete-sweep message and its --allow-incomplete)."""
    sweep = write_fleet_sweep(tmp_path / "sweep", agents=("queue_aware",))
    (job,) = sweep.glob("*_share0.5_seed1")
    (job / "results.json").write_text(json.dumps(single_results_json("greedy", 300, 1)))
    for allow in (False, True):
        with pytest.raises(WrongTaskError, match=f"{job.name} is a single-target run.*without --fleet"):
            make_fleet_table([sweep], tmp_path / "out", allow_incomplete=allow)
    with pytest.raises(WrongTaskError, match=r"is a fleet run.*make_table\.py --fleet"):
        collect([sweep])  # the single-target table refuses the fleet jobs, naming the flag


def test_two_jobs_of_one_cell_are_refused(tmp_path) -> None:
    a = write_fleet_sweep(tmp_path / "a", agents=("queue_aware",))
    b = write_fleet_sweep(tmp_path / "b", agents=("queue_aware",))
    with pytest.raises(ResultsError, match=r"guided_share=0\.5"):
        make_fleet_table([a, b], tmp_path / "out")


@pytest.mark.slow
def test_make_table_fleet_on_the_command_line(tmp_path) -> None:
    sweep = write_fleet_sweep(tmp_path / "sweep", agents=("queue_aware", "dueling_ddqn"))
    proc = run_script("make_table.py", "--fleet", str(sweep), "--out", str(tmp_path / "out"), timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "## Paired differences on the guided EVs" in proc.stdout
    assert (tmp_path / "out" / BARS_PNG).exists()
    proc = run_script("make_table.py", str(sweep), "--out", str(tmp_path / "single"), timeout=300)
    assert proc.returncode == 2 and "make_table.py --fleet" in proc.stderr  # another kind: bad input
    assert "allow-incomplete" not in proc.stderr


@pytest.mark.slow
def test_validation_curves_per_cell_pair_each_seed_with_queue_aware(tmp_path) -> None:
    sweep = write_fleet_sweep(tmp_path / "sweep", agents=("queue_aware", "dqn"))
    for job in sweep.glob("*_dqn_*"):
        data = json.loads((job / "results.json").read_text())
        seed, share = data["seed"], data["config"]["fleet"]["guided_share"]
        data["validation"] = {
            "points": [{"episodes_done": 20, "transitions": 900, "mean": 500.0 + seed},
                       {"episodes_done": 40, "transitions": 1800, "mean": 400.0 * share + seed}],
            "rules": {"queue_aware": [450.0], "central": [380.0]},
            "rule_means": {"queue_aware": 450.0 + 10 * seed, "central": 380.0},
        }  # fmt: skip
        (job / "results.json").write_text(json.dumps(data))
    out = make_fleet_table([sweep], tmp_path / "out")
    jobs = [j for j in out.collection.jobs if j.agent == "dqn"]
    panel = ("fleet", 400, 0.5)
    points = validation_points(jobs, lambda j: (j.regime, j.evs, j.guided_share))
    assert sorted(points) == [panel, ("fleet", 400, 1.0)]
    assert sorted(points[panel]["dqn"]) == [[(20, 500.0 + s), (40, 200.0 + s)] for s in SEEDS]
    gaps = validation_gaps(jobs, "queue_aware", lambda j: (j.regime, j.evs, j.guided_share))
    # paired per seed with queue_aware on its own validation episodes
    assert sorted(gaps[panel]["dqn"]) == sorted([(20, 50.0 - 9 * s), (40, -250.0 - 9 * s)] for s in SEEDS)
    assert matplotlib.image.imread(tmp_path / "out" / VALIDATION_PNG).shape[0] > 600  # two rows of panels
    # the same gaps per training length, over seeds, in the table
    assert "| EVs | guided share | agent | after 20 | after 40 |" in out.markdown
    # 50, 41, 32 s after 20 episodes: 41.0 +- t(0.975, 2) * 9 / sqrt(3) = 22.4
    assert "| 400 | 0.5 | dqn | +41.0 [+18.6, +63.4] n=3 | " in out.markdown
    section = out.markdown.split("## Validation by training length")[1].split("\n## ")[0]
    assert "| 400 | 1 | dqn | " in section and "queue_aware |" not in section
    # no learner validated: no figure
    plain = write_fleet_sweep(tmp_path / "plain", agents=("queue_aware",))
    assert VALIDATION_PNG not in {p.name for p in make_fleet_table([plain], tmp_path / "o2").paths}
