"""The documentation's generated regions (evcd.report.pages, scripts/render_pages.py): the committed
pages are what their committed data renders, a difference is named cell by cell, and malformed regions
are refused."""

from __future__ import annotations

import csv
import json
import shutil
from collections import Counter
from pathlib import Path

import pytest

from evcd.report.pages import END, PAGES, PageError, differences, regions, render_page
from tests.conftest import ROOT, run_script


@pytest.mark.parametrize("page", PAGES)
def test_every_committed_page_is_what_its_data_renders(page):
    text = (ROOT / page).read_text()
    assert regions(text), f"{page} has no generated region"
    assert differences(text, render_page(text, ROOT), page) == []


def test_the_headline_is_the_mean_over_seeds_of_the_committed_rows():
    """One cell recomputed by hand from docs/results.csv: queue_aware at 400 EVs."""
    with open(ROOT / "docs" / "results.csv", newline="") as f:
        values = [float(r["mean_travel_time"]) for r in csv.DictReader(f)
                  if (r["regime"], r["agent"], r["evs"]) == ("table", "queue_aware", "400")]  # fmt: skip
    assert len(values) == 5
    readme = (ROOT / "README.md").read_text()
    assert f"| {sum(values) / 5:.1f} [" in readme.split("| 400 |")[1].split("\n")[0]


def _share_one(path: Path, *agents: str) -> dict[str, dict[str, float]]:
    """agent -> seed -> the guided EVs' mean travel time at guided share 1, from a fleet csv."""
    by_agent: dict[str, dict[str, float]] = {a: {} for a in agents}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["agent"] in by_agent and float(r["guided_share"]) == 1.0:
                by_agent[r["agent"]][r["seed"]] = float(r["guided_travel"])
    return by_agent


def test_the_fleet_headline_pairs_the_committed_rows_by_seed():
    """One cell recomputed by hand from docs/fleet_table/fleet_results.csv: DQN - central at share 1."""
    by_agent = _share_one(ROOT / "docs" / "fleet_table" / "fleet_results.csv", "dqn", "central")
    diffs = [by_agent["dqn"][s] - by_agent["central"][s] for s in by_agent["central"]]
    assert len(diffs) == 5
    line = next(x for x in (ROOT / "README.md").read_text().splitlines() if x.startswith("- The fleet at "))
    assert f"DQN {sum(diffs) / 5:+.1f} [" in line.split("against queue_aware;")[1]


def test_the_fleet_tables_recount_the_committed_rows():
    """The fleet page's share-1 table from docs/fleet_table/fleet_results.csv, two cells by hand: the
    truncated guided EVs of reservation, and the mean queue wait of greedy."""
    with open(ROOT / "docs" / "fleet_table" / "fleet_results.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if float(r["guided_share"]) == 1.0]
    truncated = sum(int(r["truncated"]) for r in rows if r["agent"] == "reservation")
    waits = [float(r["queue_wait"]) for r in rows if r["agent"] == "greedy"]
    lines = (ROOT / "docs" / "FLEET.md").read_text().splitlines()
    truncated_row = next(x for x in lines if x.startswith("| guided EVs truncated")).split(" | ")
    wait_row = next(x for x in lines if x.startswith("| mean queue wait (s)")).split(" | ")
    assert truncated_row[3] == str(truncated)  # greedy, queue_aware, reservation
    assert wait_row[1] == f"{sum(waits) / len(waits):.1f}"
    by_seed = {(r["agent"], r["seed"]): float(r["guided_travel"]) for r in rows}
    seed_line = next(x for x in lines if x.startswith("Dueling DDQN - DQN: "))
    first = by_seed["dqn", "0"] - by_seed["queue_aware", "0"]
    assert f"learner - queue_aware (s): DQN {first:+.1f} / " in seed_line


def test_the_room_line_pairs_central_with_the_played_plan_by_seed():
    """One number recomputed by hand from docs/fleet_room/perturbed/fleet_results.csv: central minus
    the played plan (agent fleet_bound) at guided share 1."""
    perturbed = ROOT / "docs" / "fleet_room" / "perturbed" / "fleet_results.csv"
    by_agent = _share_one(perturbed, "central", "fleet_bound")
    diffs = [by_agent["central"][s] - by_agent["fleet_bound"][s] for s in by_agent["central"]]
    assert len(diffs) == 5
    line = next(x for x in (ROOT / "README.md").read_text().splitlines() if x.startswith("- How much room "))
    assert f"and {sum(diffs) / 5:+.1f} [" in line and "] perturbed (" in line


def _copy_root(tmp_path: Path) -> Path:
    root = tmp_path / "repo"
    (root / "docs").mkdir(parents=True)
    for page in PAGES:
        shutil.copy(ROOT / page, root / page)
    shutil.copy(ROOT / "docs" / "results.csv", root / "docs" / "results.csv")
    for page in ("RESULTS.md", "PERTURBED.md"):
        shutil.copy(ROOT / "docs" / page, root / "docs" / page)
    (root / "docs" / "fleet_table").mkdir()
    shutil.copy(ROOT / "docs" / "fleet_table" / "fleet_results.csv", root / "docs" / "fleet_table")
    (root / "docs" / "fleet_table" / "runs").symlink_to(ROOT / "docs" / "fleet_table" / "runs")
    for world in ("calm", "perturbed"):
        room = Path("docs") / "fleet_room" / world
        (root / room).mkdir(parents=True)
        shutil.copy(ROOT / room / "fleet_results.csv", root / room)
    return root


def test_check_names_the_changed_cell_and_rendering_restores_it(tmp_path):
    root = _copy_root(tmp_path)
    csv_path = root / "docs" / "results.csv"
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:  # greedy at 200 EVs becomes 100 s slower in every seed
        if (r["agent"], r["evs"]) == ("greedy", "200"):
            r["mean_travel_time"] = str(float(r["mean_travel_time"]) + 100.0)
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    check = run_script("render_pages.py", "--check", "--root", str(root))
    assert check.returncode == 1, check.stderr[-2000:]
    cell, paired_line = check.stdout.splitlines()  # the headline's cell; the learners' lead on greedy
    assert "README.md:" in cell and "column 'greedy' of row '200': '475.7 [341.7, 609.7]' -> '575.7 [" in cell
    assert "ahead of greedy at every EV count, by 309 to" in paired_line
    assert "ahead of greedy at every EV count, by 409 to" in paired_line
    assert run_script("render_pages.py", "--root", str(root)).returncode == 0
    assert "575.7 [441.7, 709.7]" in (root / "README.md").read_text()
    assert run_script("render_pages.py", "--check", "--root", str(root)).returncode == 0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("<!-- generated: results-headline -->\nx\n", "never closed"),
        (f"x\n{END}\n", "without a region"),
        ("<!-- generated: nothing-such -->\n" + END, "no generator named 'nothing-such'"),
        ("<!-- generated: results-headline -->\n" * 2 + END, "opens inside"),
    ],
)
def test_malformed_regions_are_refused_with_their_line(text, message):
    with pytest.raises(PageError, match=message):
        regions(text)


def test_a_malformed_page_exits_2_and_writes_nothing(tmp_path):
    root = _copy_root(tmp_path)
    before, _, after = (root / "README.md").read_text().rpartition(END)  # the last region left open
    broken = before + after
    (root / "README.md").write_text(broken)
    proc = run_script("render_pages.py", "--root", str(root))
    assert proc.returncode == 2 and "never closed" in proc.stderr
    assert (root / "README.md").read_text() == broken


def test_the_fleet_tables_say_which_code_and_machine_made_their_rows(tmp_path):
    """The committed table names the code and machine of its rows, each commit with its job count
    (counted here from the csv); a table made before results recorded their provenance says so; a table
    of other commits names them."""
    from evcd.report.fleet_regions import per_share, share_one

    root = _copy_root(tmp_path)
    path = root / "docs" / "fleet_table" / "fleet_results.csv"
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    commits = Counter(r["commit"][:7] for r in rows if float(r["guided_share"]) == 1.0)
    (top, n), *_ = commits.most_common()
    assert f"`{top}` ({n} of 30 jobs)" in share_one(root).splitlines()[-1]
    for r in rows:
        r.update(environment="", evcd="", machine="", commit="")
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert share_one(root).splitlines()[-1] == ("Its jobs recorded no environment version, code or machine "
                                                "(made before results did).")
    for i, r in enumerate(rows):
        r.update(environment="evcd_fleet_v1", evcd="0.1.0", machine="AMD EPYC (AVX512), torch 2.13.0+cpu",
                 commit=("a" if float(r["guided_share"]) == 1.0 else "b" if i % 2 else "c") * 40)  # fmt: skip
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert share_one(root).endswith("on `AMD EPYC (AVX512), torch 2.13.0+cpu`, by commit `aaaaaaa`.")
    last = per_share(root).splitlines()[-1]
    assert last.startswith("Made with `evcd_fleet_v1`, evcd `0.1.0`, on ")
    assert "by commits `aaaaaaa` (30 of 90 jobs), " in last


def test_the_paired_line_reads_the_verdicts_from_the_intervals(tmp_path):
    """The README's paired line from docs/results.csv; DQN made 100 s slower at 300 EVs in every seed
    turns its verdict there from level to behind, and the line then reads each learner apart."""
    from evcd.report.results_regions import paired

    root = _copy_root(tmp_path)
    line = paired(root)
    assert "both learners are level with queue_aware at 200 and 300 and behind it at 400 EVs;" in line
    assert "both are ahead of greedy at every EV count" in line
    csv_path = root / "docs" / "results.csv"
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        if (r["regime"], r["agent"], r["evs"]) == ("table", "dqn", "300"):
            r["mean_travel_time"] = str(float(r["mean_travel_time"]) + 100.0)
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    line = paired(root)
    assert "DQN is level with queue_aware at 200 and behind it at 300 and 400 EVs; Dueling DDQN" in line
    assert "DQN +3.3 [-0.1, +6.7] / **+111.2 [+91.3, +131.1]** / **+34.9" in line


def test_the_gap_shares_are_those_of_the_seed_means():
    """One share recomputed by hand: DQN (fleet table) at guided share 1, against greedy and the proven
    bound of the room's calm table."""
    means: dict[str, list[float]] = {"greedy": [], "bound": [], "dqn": []}
    with open(ROOT / "docs" / "fleet_room" / "calm" / "fleet_results.csv", newline="") as f:
        for r in csv.DictReader(f):
            if float(r["guided_share"]) == 1.0 and r["agent"] in ("greedy", "fleet_bound"):
                means["greedy" if r["agent"] == "greedy" else "bound"].append(
                    float(r["guided_travel" if r["agent"] == "greedy" else "bound"]))
    with open(ROOT / "docs" / "fleet_table" / "fleet_results.csv", newline="") as f:
        means["dqn"] = [float(r["guided_travel"]) for r in csv.DictReader(f)
                        if float(r["guided_share"]) == 1.0 and r["agent"] == "dqn"]  # fmt: skip
    g, b, a = (sum(v) / len(v) for v in (means["greedy"], means["bound"], means["dqn"]))
    assert all(len(v) == 5 for v in means.values())
    row = next(x for x in (ROOT / "docs" / "FLEET.md").read_text().splitlines() if x.startswith("| dqn | 0."))
    assert row.split(" | ")[1].startswith(f"{(g - a) / (g - b):.2f} [")


def test_the_line_per_world_subtracts_the_proven_bound_seed_by_seed():
    """central minus the proven bound at guided share 1, calm, recomputed by hand from the room's csv."""
    central, bound = {}, {}
    with open(ROOT / "docs" / "fleet_room" / "calm" / "fleet_results.csv", newline="") as f:
        for r in csv.DictReader(f):
            if float(r["guided_share"]) == 1.0 and r["agent"] == "central":
                central[r["seed"]] = float(r["guided_travel"])
            elif float(r["guided_share"]) == 1.0 and r["agent"] == "fleet_bound":
                bound[r["seed"]] = float(r["bound"])
    diff = sum(central[s] - bound[s] for s in central) / len(central)
    line = next(x for x in (ROOT / "docs" / "FLEET.md").read_text().splitlines() if x.startswith("- calm: "))
    assert f"to the played plan; {diff:+.1f} / " in line


def _shift_fleet(root: Path, agent: str, share: float, by: float) -> None:
    """Make ``agent``'s guided EVs ``by`` seconds slower at ``share`` in every seed of a copied fleet csv."""
    path = root / "docs" / "fleet_table" / "fleet_results.csv"
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        if r["agent"] == agent and float(r["guided_share"]) == share:
            r["guided_travel"] = str(float(r["guided_travel"]) + by)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_the_fleet_readings_follow_the_paired_intervals(tmp_path):
    """The fleet page's readings from the committed csv: DQN's lead on queue_aware at share 1 as a share
    of the rule's time, recomputed by hand; DQN made 100 s slower at share 1 turns it from ahead of
    queue_aware to behind, drops the unpaired reading, and splits the learners' line at that share."""
    from evcd.report.fleet_regions import against_rules, share_verdicts

    by_agent = _share_one(ROOT / "docs" / "fleet_table" / "fleet_results.csv", "dqn", "queue_aware")
    rule = by_agent["queue_aware"]
    diff = sum(by_agent["dqn"][s] - rule[s] for s in rule) / len(rule)
    root = _copy_root(tmp_path)
    text = against_rules(root)
    assert f"- queue_aware: DQN ahead of it, {diff:+.1f} [" in text
    part = abs(diff) / (sum(rule.values()) / len(rule))
    assert f"] ({part:.0%} of its time; faster on 5 of 5 seeds); Dueling DDQN ahead of it" in text
    assert "the lead on queue_aware is not shown (DQN " in text
    line = share_verdicts(root)
    assert "at 0.5, both learners level with queue_aware and level with central;" in line
    _shift_fleet(root, "dqn", 1.0, 100.0)
    text = against_rules(root)
    assert "- queue_aware: DQN behind it, +54.8 [" in text
    assert "the lead on queue_aware is not shown (Dueling DDQN " in text
    line = share_verdicts(root)
    assert "at 1, DQN behind queue_aware and behind central, Dueling DDQN ahead of queue_aware" in line
    _shift_fleet(root, "dueling_ddqn", 1.0, 100.0)
    assert "lead on queue_aware" not in against_rules(root)


def test_the_regime_line_reads_the_results_pages_tables_of_that_regime(tmp_path):
    """The README's line on the first command's regime: Dueling DDQN's mean recomputed by hand from its
    seeds on the results page; a learner's paired interval moved below 0 on the page changes where the
    line says it stands; a page without the section is refused by name."""
    from evcd.report.results_regions import RESULTS, regime

    text = (ROOT / RESULTS).read_text()
    section = text[text.index("### The README regime "):]
    row = next(x for x in section.splitlines() if x.startswith("| dueling_ddqn | "))
    seeds = [float(c) for c in row.split(" | ")[1:6]]
    root = _copy_root(tmp_path)
    line = regime(root)
    assert f"Dueling DDQN {sum(seeds) / 5:.1f} s [" in line
    assert "paired, level with queue_aware (+2.7 [" in line and "which trail the rule by 54-96 s" in line
    (root / RESULTS).write_text(text.replace("| -221.8 [-360.8, -82.8] | +95.5 [+6.0, +185.1] |",
                                             "| -221.8 [-360.8, -82.8] | -5.0 [-9.0, -1.0] |"))  # fmt: skip
    assert "sb3_dqn ahead of the rule; sb3_ppo behind the rule" in regime(root)
    (root / RESULTS).write_text(text.replace("### The README regime ", "### The first regime "))
    with pytest.raises(ValueError, match="no section '### The README regime'"):
        regime(root)


def test_the_perturbed_line_reads_the_goal_table(tmp_path):
    """The README's perturbed line from the perturbed page's goal table: the single target's plain
    learner as the table says it; the fleet's learner seeing P, T, F moved below 0 on the page is named
    as ahead of its rule; a page without the goal table is refused by name."""
    from evcd.report.perturbed_regions import PAGE, goal

    text = (ROOT / PAGE).read_text()
    row = next(x for x in text.splitlines() if x.startswith("| single target | Dueling DDQN, plain |"))
    cell = row.split(" | ")[3].split(" n=")[0]
    root = _copy_root(tmp_path)
    line = goal(root)
    assert f"({cell} s); no learner beats every rule there" in line
    fleet = next(x for x in text.splitlines() if x.startswith("| fleet | Dueling DDQN seeing"))
    moved = fleet.replace(fleet.split(" | ")[3].removesuffix(" |"), "**-20.0 [-30.0, -10.0]** n=5, by seed")
    (root / PAGE).write_text(text.replace(fleet, moved))
    said = "ahead of its world's strongest rule: fleet: Dueling DDQN seeing `P`, `T`, `F` ahead of central"
    assert said in goal(root)
    (root / PAGE).write_text(text.replace("## The goal, in one table", "## The goal"))
    with pytest.raises(ValueError, match="no heading '## The goal, in one table'"):
        goal(root)


def _recorded_root(tmp_path: Path, ran_here: bool = False) -> tuple[Path, list[dict]]:
    """A root whose fleet csv holds the fleet table's recorded jobs (made from their records' results.json)
    beside a link to the records; and those jobs' results. The csv's job directories are where the jobs
    ran, gone since (``ran_here``: the records themselves, as where the jobs still are)."""
    from evcd.report.fleet_regions import CSV, RECORDS
    from evcd.report.fleet_table import fleet_csv_text, fleet_job

    jobs, results = [], []
    for path in sorted((ROOT / RECORDS).glob("*/*/results.json")):
        results.append(json.loads(path.read_text()))
        ran = path.parent if ran_here else tmp_path / "gone" / path.parent.parent.name / path.parent.name
        jobs.append(fleet_job(results[-1], ran))
    root = tmp_path / "repo"
    (root / CSV).parent.mkdir(parents=True, exist_ok=True)
    (root / CSV).write_text(fleet_csv_text(jobs))
    if not (root / RECORDS.parent).exists():
        (root / RECORDS.parent).symlink_to(ROOT / RECORDS.parent)
    return root, results


def test_the_per_day_reading_reads_the_jobs_records(tmp_path):
    """The fleet page's reading per day, from a csv of the recorded jobs of the fleet table and their
    records: the day listed first is the one with the largest queue_aware - central gap at share 1,
    recomputed by hand from the jobs' results.json; without the records it names the job and the
    command."""
    from evcd.report.fleet_regions import RECORDS, per_day

    root, results = _recorded_root(tmp_path)
    travel = {(r["agent"], e["day"]): e["guided_travel"] for r in results
              if r["config"]["fleet"]["guided_share"] == 1.0 for e in r["episodes"]}  # fmt: skip
    days = {d for a, d in travel if a == "central" and ("queue_aware", d) in travel}
    assert len(days) >= 5, "the fleet table's records hold at least one seed at share 1"
    first = max(days, key=lambda d: travel["queue_aware", d] - travel["central", d])
    reading = per_day(root)
    assert f"(the largest queue_aware - central gaps: days {first}, " in reading
    (root / RECORDS.parent).unlink()
    with pytest.raises(ValueError, match="needs the table's records"):
        per_day(root)
    # jobs whose run directories are still where they ran are read there, records or not
    root, _ = _recorded_root(tmp_path, ran_here=True)
    (root / RECORDS.parent).unlink()
    assert per_day(root) == reading


def test_the_cost_line_reads_the_jobs_and_the_manifest(tmp_path):
    """The fleet page's cost line from the recorded jobs: DQN's mean training minutes at share 1
    recomputed by hand from results.json, and the launches counted from the records' manifest."""
    from evcd.report.fleet_regions import RECORDS, cost

    root, results = _recorded_root(tmp_path)
    minutes = [r["training"]["wall_s"] / 60 for r in results
               if r["agent"] == "dqn" and r["config"]["fleet"]["guided_share"] == 1.0]  # fmt: skip
    launches = json.loads((ROOT / RECORDS.parent / "reproduce.json").read_text())["launches"]
    line = cost(root)
    assert line.startswith("What it cost on the machine that made it (2 jobs at once;")
    assert f"(DQN / Dueling DDQN: {sum(minutes) / len(minutes):.1f} / " in line.split("at share 0.5")[0]
    assert f"The page's {len(launches)} launches: " in line
