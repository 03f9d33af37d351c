"""The fleet table's numbers on the documentation pages, rendered from
``docs/fleet_table/fleet_results.csv`` (and, for the reading per day, the table's job records).

Each function takes the repository root and returns a generated region's Markdown
(:mod:`evcd.report.pages`): the README's fleet headline, the fleet page's tables at the highest
competition and per guided share, and its readings of where each learner stands against the rules (the
verdicts read from the paired intervals). A csv holds one row per job; every dispatcher of a seed plays
the same fleet episodes, so a difference paired by episode within a seed is the difference of the two
jobs' means, and the paired rows here (the mean over seeds of those differences, with the 95% Student-t
interval across seeds) are those of ``fleet_results.md``, which also counts the episodes each side won.
The room the best rule leaves (the clairvoyant bound's tables): :mod:`evcd.report.room_regions`.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from evcd.loops.run_files import FLEET_CSV, RESULTS_JSON
from evcd.report.markdown import interval, markdown_table, signed, verdict
from evcd.report.markdown import marked_interval as _marked
from evcd.report.markdown import signed_interval as _signed
from evcd.report.reproduce.launch import MANIFEST, launches_span
from evcd.report.reproduce.render import log_wall
from evcd.report.seed_stats import SeedStat, seed_interval
from evcd.report.stamp import JobStamp, row_stamp, stamp_sentence

CSV = Path("docs") / "fleet_table" / "fleet_results.csv"
#: The fleet table's job records (``scripts/reproduce.py fleet --records``): ``<sweep>/<job>/`` per job.
RECORDS = Path("docs") / "fleet_table" / "runs" / "sweeps"
#: The table's dispatchers, in the page's order.
DISPATCHERS = ("greedy", "queue_aware", "reservation", "central", "dqn", "dueling_ddqn")
LEARNERS = {"dqn": "DQN", "dueling_ddqn": "Dueling DDQN"}


@dataclass(frozen=True)
class Job:
    """One job's row of the csv (the fields the pages show)."""

    guided: int
    truncated: int
    guided_travel: float
    all_travel: float
    queue_wait: float
    eval_days: tuple[str, ...]
    stamp: JobStamp
    bound: float  # a fleet_bound job's proven bound (NaN for the others, and in tables without the column)
    train_wall_s: float  # the learner's training time (0 for a rule)
    train_transitions: int  # the learner's agent steps in training (0 for a rule)
    job_dir: str  # where the job ran (its record: RECORDS / <sweep> / <job>)


def read_jobs(root: Path, table: Path = CSV) -> dict[float, dict[str, dict[int, Job]]]:
    """guided share -> dispatcher -> seed -> its job, from the committed csv ``table`` under ``root``
    (the fleet table's by default)."""
    out: dict[float, dict[str, dict[int, Job]]] = defaultdict(lambda: defaultdict(dict))
    with open(Path(root) / table, newline="") as f:
        for r in csv.DictReader(f):
            out[float(r["guided_share"])][r["agent"]][int(r["seed"])] = Job(
                int(r["guided"]), int(r["truncated"]), float(r["guided_travel"]), float(r["all_travel"]),
                float(r["queue_wait"]), tuple(r["eval_days"].split()),
                row_stamp(r), float(r.get("bound") or "nan"), float(r["train_wall_s"]),
                int(r["train_transitions"]), r["job_dir"])  # fmt: skip
    return out


def seed_differences(jobs: dict[str, dict[int, Job]], a: str, b: str) -> list[float]:
    """``a`` minus ``b`` on the guided EVs, seed by seed (in seed order), over the seeds both have."""
    return [jobs[a][s].guided_travel - jobs[b][s].guided_travel for s in sorted(set(jobs[a]) & set(jobs[b]))]


def paired(jobs: dict[str, dict[int, Job]], a: str, b: str) -> SeedStat:
    """``a`` minus ``b`` on the guided EVs, paired by seed, over the seeds both have."""
    return seed_interval(seed_differences(jobs, a, b))


def seed_mean(jobs: dict[int, Job], field: str) -> float:
    """The mean over seeds of a job field (``guided_travel``, ``queue_wait``, ...)."""
    return seed_interval(getattr(j, field) for j in jobs.values()).mean


def _total(jobs: dict[int, Job], field: str) -> int:
    """The sum over seeds of a job count."""
    return sum(int(getattr(j, field)) for j in jobs.values())


def _made(shares: Iterable[dict[str, dict[int, Job]]]) -> str:
    """The provenance sentence of the jobs of these shares (every dispatcher's, every seed's)."""
    return stamp_sentence([j.stamp for jobs in shares for by_seed in jobs.values() for j in by_seed.values()])


def share_label(share: float) -> str:
    """A guided share as the pages write it: ``1``, ``0.5``, ``0.25``."""
    return f"{share:g}"


def headline(root: Path) -> str:
    """The README's fleet line: at share 1, each learner minus ``queue_aware`` and minus ``central``."""
    jobs = read_jobs(root)[1.0]
    pairs = []
    for rule in ("queue_aware", "central"):
        cells = [f"{name} {_signed(paired(jobs, learner, rule))}" for learner, name in LEARNERS.items()]
        pairs.append(f"{' and '.join(cells)} s against {rule}")
    days = {d for job in jobs["central"].values() for d in job.eval_days}
    return (f"- The fleet at 600 EVs, every charging EV guided ({len(jobs['central'])} seeds, {len(days)} "
            "held-out days), each learner minus a rule on the same episodes (mean over seeds [95% t]): "
            f"{'; '.join(pairs)}, the rule that assigns a tick's EVs jointly "
            "([`docs/FLEET.md`](docs/FLEET.md)).")  # fmt: skip


def _per_seed(jobs: dict[str, dict[int, Job]]) -> str:
    """Dueling DDQN minus DQN, and each learner minus ``queue_aware`` seed by seed with the seeds it is
    faster on."""
    seeds = sorted(set(jobs["queue_aware"]))
    parts = []
    for a, name in LEARNERS.items():
        diffs = seed_differences(jobs, a, "queue_aware")
        faster = sum(d < 0 for d in diffs)
        parts.append(f"{name} {' / '.join(signed(d) for d in diffs)} (faster on {faster} of {len(diffs)})")
    return (f"Dueling DDQN - DQN: {_signed(paired(jobs, 'dueling_ddqn', 'dqn'))}. Per seed "
            f"({', '.join(map(str, seeds))}), learner - queue_aware (s): {'; '.join(parts)}.")


def share_one(root: Path) -> str:
    """The fleet page's table at the highest competition (share 1): per dispatcher the guided EVs' mean
    travel time over seeds, everybody's, the truncated guided EVs and the mean queue wait; then each
    learner minus each rule."""
    jobs = read_jobs(root)[1.0]
    guided = _total(jobs["central"], "guided")
    travel = {a: seed_interval(j.guided_travel for j in jobs[a].values()) for a in DISPATCHERS}
    rows = [
        [
            "mean over seeds [95 % t interval]",
            *map(interval, travel.values()),
        ],
        ["all EVs charging in the window", *(f"{seed_mean(jobs[a], 'all_travel'):.1f}" for a in DISPATCHERS)],
        [f"guided EVs truncated (of {guided:,})", *(f"{_total(jobs[a], 'truncated')}" for a in DISPATCHERS)],
        ["mean queue wait (s)", *(f"{seed_mean(jobs[a], 'queue_wait'):.1f}" for a in DISPATCHERS)],
    ]
    pairs = [[a, *(_marked(paired(jobs, a, rule)) for rule in ("queue_aware", "reservation", "central"))]
             for a in LEARNERS]  # fmt: skip
    caption = (
        "Paired on the same episodes, guided EVs (s, mean over seeds [95% t]; bold: the interval "
        "leaves out 0; the episodes each side won: `fleet_results.md`):"
    )
    means = markdown_table(["guided EVs' mean travel time (s)", *DISPATCHERS], rows)
    differences = markdown_table(["", "- queue_aware", "- reservation", "- central"], pairs)
    return "\n".join([*means, "", caption, "", *differences, "", _per_seed(jobs), "", _made([jobs])])


def _standing(jobs: dict[str, dict[int, Job]], a: str, rule: str) -> str:
    """``ahead of it, -45.2 [-78.6, -11.8] (13% of its time; faster on 5 of 5 seeds)``: where learner
    ``a`` stands against ``rule`` (read from the paired interval) and by how much."""
    diffs = seed_differences(jobs, a, rule)
    stat = seed_interval(diffs)
    part = abs(stat.mean) / seed_mean(jobs[rule], "guided_travel")
    return (f"{verdict(stat)} it, {_signed(stat)} ({part:.0%} of its time; faster on "
            f"{sum(d < 0 for d in diffs)} of {len(diffs)} seeds)")


def against_rules(root: Path) -> str:
    """The fleet page's reading at the highest competition (share 1): where each learner stands against
    each rule, the verdict read from the paired interval, with its size and the seeds it is faster on;
    and where a learner is ahead of ``queue_aware``, whether the dispatchers' own intervals tell them
    apart too."""
    jobs = read_jobs(root)[1.0]
    named = {"queue_aware": "queue_aware", "reservation": "reservation",
             "central": "central, the rule that assigns the EVs of a tick jointly"}  # fmt: skip
    lines = ["**Against the rules** (guided share 1; each learner minus the rule on the same episodes, s, "
             "mean over seeds [95% t]):", ""]  # fmt: skip
    for rule, name in named.items():
        lines.append(f"- {name}: " + "; ".join(f"{learner} {_standing(jobs, a, rule)}"
                                             for a, learner in LEARNERS.items()) + ".")  # fmt: skip
    ahead = [a for a in LEARNERS if paired(jobs, a, "queue_aware").high < 0]
    if ahead:
        own = {a: seed_interval(j.guided_travel for j in jobs[a].values()) for a in (*ahead, "queue_aware")}
        apart = all(own[a].high < own["queue_aware"].low for a in ahead)
        cells = ", ".join(f"{LEARNERS.get(a, a)} {interval(own[a])}" for a in own)
        lines += ["", f"Read as the dispatchers' own intervals not overlapping, the lead on queue_aware is "
                      f"{'shown too' if apart else 'not shown'} ({cells}): those intervals hold the spread "
                      "of the days between seeds (one seed's days are heavier than another's), which the "
                      "pairing removes; the paired interval is the test of the question asked."]  # fmt: skip
    return "\n".join(lines)


def _verdicts(jobs: dict[str, dict[int, Job]]) -> dict[str, str]:
    """Learner -> ``ahead of queue_aware and level with central``."""
    return {a: " and ".join(f"{verdict(paired(jobs, a, rule))} {rule}" for rule in ("queue_aware", "central"))
            for a in LEARNERS}  # fmt: skip


def share_verdicts(root: Path) -> str:
    """The fleet page's line per guided share: where each learner stands against ``queue_aware`` and
    ``central`` (the verdicts read from the paired intervals of the table above), and by how much where
    both learners are behind both rules."""
    shares = read_jobs(root)
    parts = []
    for share in sorted(shares, reverse=True):
        jobs, said = shares[share], _verdicts(shares[share])
        if len(set(said.values())) == 1:
            text = f"both learners {next(iter(said.values()))}"
        else:
            text = ", ".join(f"{LEARNERS[a]} {v}" for a, v in said.items())
        stats = [paired(jobs, a, rule) for a in LEARNERS for rule in ("queue_aware", "central")]
        if all(s.low > 0 for s in stats):
            means = sorted(s.mean for s in stats)
            text += f" (by {means[0]:.1f} to {means[-1]:.1f} s)"
        parts.append(f"at {share_label(share)}, {text}")
    return ("Each learner against the two rules that read the queues, per guided share (the verdict "
            "read from the paired interval): " + "; ".join(parts) + ".")


def _record(root: Path, job: Job) -> Path:
    """A job's run directory where it still is (its ``job_dir``, relative to ``root`` if relative), else
    its record (``RECORDS/<sweep>/<job>``, kept by ``scripts/reproduce.py fleet --records``).

    Raises:
        ValueError: neither holds it.
    """
    own = Path(root) / job.job_dir
    if (own / RESULTS_JSON).is_file():
        return own
    record = Path(root) / RECORDS / own.parent.name / own.name
    if not (record / RESULTS_JSON).is_file():
        raise ValueError(f"no record of the job {job.job_dir} ({record}): this needs the table's records "
                         "(scripts/reproduce.py fleet --records docs/fleet_table/runs)")  # fmt: skip
    return record


def _days(root: Path, jobs: dict[int, Job]) -> dict[int, tuple[int, float]]:
    """Day -> (guided EVs, their mean travel time) of a dispatcher's jobs, from their records'
    ``fleet_episodes.csv`` (one fleet episode per day)."""
    out = {}
    for job in jobs.values():
        with open(_record(root, job) / FLEET_CSV, newline="") as f:
            for e in csv.DictReader(f):
                out[int(e["day"])] = (int(e["guided"]), float(e["guided_travel"]))
    return out


def cost(root: Path) -> str:
    """The fleet page's line on what the table cost on the machine that made it: per guided share, a
    learner job's wall time (its log, sessions summed), the learners' training time and agent steps on
    average, a rule job's wall time; and the page's launches together (the records' manifest)."""
    shares = read_jobs(root)
    parts = []
    for share in sorted(shares, reverse=True):
        jobs = shares[share]
        walls = {a: [log_wall(_record(root, j)) or math.nan for j in jobs[a].values()] for a in jobs}
        learners = [w / 60 for a in LEARNERS for w in walls[a]]
        rules = [w / 60 for a in walls if a not in LEARNERS for w in walls[a]]
        training = " / ".join(f"{seed_mean(jobs[a], 'train_wall_s') / 60:.1f}" for a in LEARNERS)
        steps = " / ".join(f"{seed_mean(jobs[a], 'train_transitions'):,.0f}" for a in LEARNERS)
        parts.append(f"at share {share_label(share)}, a learner job {_span(learners)} minutes "
                     f"({' / '.join(LEARNERS.values())}: {training} minutes of training on average, {steps} "
                     f"agent steps), a rule job {_span(rules)} minutes")  # fmt: skip
    manifest = json.loads((Path(root) / RECORDS.parent / MANIFEST).read_text())
    launches = manifest["launches"]
    at_once = re.search(r"hydra\.launcher\.n_jobs=(\d+)", launches[0]["command"])
    together = f"{at_once.group(1)} jobs at once" if at_once else "one job at a time"
    return (f"What it cost on the machine that made it ({together}; the jobs' logs and `results.json`): "
            f"{'; '.join(parts)}. The page's {len(launches)} launches: "
            f"{launches_span(launches) / 3600:.1f} h in all (`reproduce.json`; pauses for other work on the "
            "machine included).")  # fmt: skip


def _span(values: Iterable[float]) -> str:
    """``291-616``: the range of values, each rounded to a whole unit."""
    v = sorted(values)
    return f"{v[0]:.0f}-{v[-1]:.0f}"


def per_day(root: Path, days: int = 4, close: float = 10.0) -> str:
    """The fleet page's reading per day at share 1 (every dispatcher plays one fleet episode a day): on
    the ``days`` days where counting the centre's own EVs pays most (the largest ``queue_aware`` -
    ``central`` gaps), each dispatcher's range of guided EVs' mean travel time; and on the days where the
    two rules are within ``close`` seconds, how far the learners are from ``central``."""
    jobs = read_jobs(root)[1.0]
    agents = ("queue_aware", "central", *LEARNERS)
    by = {a: _days(root, jobs[a]) for a in agents}
    common = sorted(set.intersection(*(set(d) for d in by.values())))
    gap = {d: by["queue_aware"][d][1] - by["central"][d][1] for d in common}
    worst = sorted(common, key=lambda d: -gap[d])[:days]
    guided = [by["central"][d][0] for d in worst]
    ranges = ", ".join(f"{LEARNERS.get(a, a)} {_span(by[a][d][1] for d in worst)}" for a in agents)
    level = [d for d in common if abs(gap[d]) <= close]
    text = (f"- Per day at share 1 ({len(common)} days, one fleet episode each; the jobs' "
            f"`fleet_episodes.csv`): on the {len(worst)} days where counting the centre's own EVs pays "
            f"most (the largest queue_aware - central gaps: days {', '.join(map(str, worst))}, with "
            f"{min(guided)}-{max(guided)} guided EVs), the guided EVs' mean travel time (s) ranges over "
            f"{ranges}.")  # fmt: skip
    if level:
        off = max(abs(by[a][d][1] - by["central"][d][1]) for a in LEARNERS for d in level)
        text += (f" On the {len(level)} days where the two rules are within {close:.0f} s of each other, "
                 f"the learners are within {off:.0f} s of central.")  # fmt: skip
    return text


def _against_reservation(shares: dict[float, dict[str, dict[int, Job]]]) -> str:
    """Each learner minus ``reservation`` per guided share."""
    cells = []
    for s in sorted(shares, reverse=True):
        both = " / ".join(_marked(paired(shares[s], a, "reservation")) for a in LEARNERS)
        cells.append(f"{both} at {share_label(s)}")
    names = " / ".join(LEARNERS.values())
    return f"{names} minus reservation (s, mean over seeds [95% t]; bold as above): {'; '.join(cells)}."


def per_share(root: Path) -> str:
    """The fleet page's table per guided share: each dispatcher's guided EVs' mean travel time over seeds
    (with its truncated guided EVs), then the learners and ``central`` paired with the rules."""
    shares = read_jobs(root)
    rows, pairs = [], []
    for share in sorted(shares, reverse=True):
        jobs = shares[share]
        cells = []
        for a in DISPATCHERS:
            cut = _total(jobs[a], "truncated")
            cells.append(f"{seed_mean(jobs[a], 'guided_travel'):.1f}" + (f" ({cut} trunc.)" if cut else ""))
        rows.append([share_label(share), f"{_total(jobs['central'], 'guided'):,}", *cells])
        learners = [paired(jobs, a, rule) for rule in ("queue_aware", "central") for a in LEARNERS]
        pairs.append([share_label(share), *map(_marked, [*learners, paired(jobs, "central", "queue_aware")])])
    header = ["share", "guided EVs", *DISPATCHERS]
    pair_header = ["share", "dqn - queue_aware", "dueling_ddqn - queue_aware", "dqn - central",
                   "dueling_ddqn - central", "central - queue_aware"]  # fmt: skip
    return "\n".join([*markdown_table(header, rows), "",
                      "(Guided EVs' mean travel time, s, mean over seeds; intervals in `fleet_results.md`.) "
                      "Paired on the same episodes (per seed the mean over its episodes, t interval across "
                      "seeds; bold: the interval leaves out 0; the episodes each side won: "
                      "`fleet_results.md`):", "", *markdown_table(pair_header, pairs), "",
                      _against_reservation(shares), "", _made(shares.values())])  # fmt: skip
