"""The results table's numbers on the README, rendered from ``docs/results.csv``.

Each function takes the repository root and returns a generated region's Markdown
(:mod:`evcd.report.pages`): the headline table (each dispatcher's mean over seeds per EV count), the
line that pairs the learners with the rules, and the line on the first command's regime (read from the
results page's tables of that regime, which ``scripts/reproduce.py readme --check`` holds to its runs).
The csv holds one row per job (regime, agent, EV count, seed); every dispatcher of a seed and EV count
is evaluated on the same episodes, so a difference paired by episode within a seed is the difference of
the two jobs' means, and the paired numbers here (the mean over seeds of those differences, with the 95%
Student-t interval across seeds) are those of the results page.
"""

from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path

from evcd.report.markdown import interval, read_interval, section_lines, signed_interval, tables, verdict
from evcd.report.markdown import marked_interval as _marked
from evcd.report.seed_stats import SeedStat, seed_interval
from evcd.report.stamp import JobStamp, row_stamp, stamp_sentence

CSV = Path("docs") / "results.csv"
#: The results page, whose README-regime tables (``scripts/reproduce.py readme --check`` compares them with
#: their runs) give the README's line on the first command's regime.
RESULTS = Path("docs") / "RESULTS.md"
REGIME = "### The README regime"
#: The headline table's columns, in the results page's order.
HEADLINE_AGENTS = ("random", "greedy", "queue_aware", "dqn", "dueling_ddqn", "hindsight")
LEARNERS = {"dqn": "DQN", "dueling_ddqn": "Dueling DDQN"}


def read_table(root: Path) -> tuple[dict[tuple[int, str], dict[int, float]], list[JobStamp]]:
    """``(EV count, agent) -> seed -> mean travel time`` of the table's regime (the headline's
    dispatchers), and those jobs' provenance."""
    cells: dict[tuple[int, str], dict[int, float]] = defaultdict(dict)
    stamps = []
    with open(Path(root) / CSV, newline="") as f:
        for row in csv.DictReader(f):
            if row["regime"] == "table" and row["agent"] in HEADLINE_AGENTS:
                cells[int(row["evs"]), row["agent"]][int(row["seed"])] = float(row["mean_travel_time"])
                stamps.append(row_stamp(row))
    return cells, stamps


def headline(root: Path) -> str:
    """The headline table: mean travel time per EV count and dispatcher over the seeds, with the 95%
    Student-t interval across seeds, and what made its jobs."""
    cells, stamps = read_table(root)
    seeds = max(len(v) for v in cells.values())
    lines = [
        f"Mean travel time from departure to the start of charging (s), mean over {seeds} seeds "
        "[95% Student-t interval across seeds], in the paper's world:",
        "",
        "| EVs | " + " | ".join(HEADLINE_AGENTS) + " |",
        "|---|" + "---:|" * len(HEADLINE_AGENTS),
    ]
    for evs in sorted({e for e, _ in cells}):
        row = [interval(seed_interval(cells[evs, a].values())) for a in HEADLINE_AGENTS]
        lines.append(f"| {evs} | " + " | ".join(row) + " |")
    several = len({s.commit for s in stamps}) > 1
    between = " The results page says what changed between them." if several else ""
    lines += ["", stamp_sentence(stamps) + between]
    return "\n".join(lines)


def difference(cells: dict[tuple[int, str], dict[int, float]], evs: int, a: str, b: str) -> SeedStat:
    """``a`` minus ``b`` at ``evs`` EVs, paired by seed, over the seeds both have."""
    seeds = sorted(set(cells[evs, a]) & set(cells[evs, b]))
    return seed_interval(cells[evs, a][s] - cells[evs, b][s] for s in seeds)


def _reading(by_count: dict[int, SeedStat], rule: str) -> str:
    """``level with <rule> at 200 and 300 EVs and behind it at 400``: the EV counts grouped by verdict."""
    groups: dict[str, list[int]] = {}
    for evs, stat in by_count.items():
        groups.setdefault(verdict(stat), []).append(evs)
    parts = []
    for i, (said, counts) in enumerate(groups.items()):
        at = ", ".join(map(str, counts[:-1])) + " and " if len(counts) > 1 else ""
        parts.append(f"{said} {rule if i == 0 else 'it'} at {at}{counts[-1]}")
    return " and ".join(parts) + " EVs"


def paired(root: Path) -> str:
    """The README's line of paired differences: each learner minus ``queue_aware`` per EV count, how far
    ahead of ``greedy`` the learners are, and the room the hindsight bound leaves ``queue_aware``."""
    cells, _ = read_table(root)
    counts = sorted({e for e, _ in cells})
    per = " / ".join(map(str, counts))
    against = {a: {e: difference(cells, e, a, "queue_aware") for e in counts} for a in LEARNERS}
    rule = [f"{name} " + " / ".join(map(_marked, against[a].values())) for a, name in LEARNERS.items()]
    readings = {a: _reading(against[a], "queue_aware") for a in LEARNERS}
    if len(set(readings.values())) == 1:
        reading = f"both learners are {next(iter(readings.values()))}"
    else:
        reading = "; ".join(f"{LEARNERS[a]} is {r}" for a, r in readings.items())
    greedy = [difference(cells, e, a, "greedy") for a in LEARNERS for e in counts]
    if all(s.high < 0 for s in greedy):
        means = sorted(-s.mean for s in greedy)
        against_greedy = (f"both are ahead of greedy at every EV count, by {means[0]:,.0f} to "
                          f"{means[-1]:,.0f} s (every interval below 0)")  # fmt: skip
    else:
        against_greedy = "against greedy: " + ", ".join(
            f"{LEARNERS[a]} " + " / ".join(_marked(difference(cells, e, a, "greedy")) for e in counts)
            for a in LEARNERS
        )
    room = " / ".join(_marked(difference(cells, e, "hindsight", "queue_aware")) for e in counts)
    return (f"- Paired on the same episodes, {reading}; {against_greedy}. Each learner minus "
            f"queue_aware at {per} EVs (s, mean over seeds [95% t]; bold: the interval leaves out 0): "
            f"{'; '.join(rule)}. The hindsight bound minus queue_aware, the room the rule leaves: {room}.")


def regime(root: Path) -> str:
    """The README's line on the first command's regime, from the results page's section on it: Dueling
    DDQN, queue_aware and greedy over seeds, Dueling DDQN minus queue_aware paired, and where the other
    learners stand against queue_aware."""
    text = (Path(root) / RESULTS).read_text()
    heading = next((line for line in text.splitlines() if line.startswith(REGIME + " ")), None)
    if heading is None:
        raise ValueError(f"{RESULTS}: no section {REGIME!r}")
    found = tables(section_lines(text, heading))
    if len(found) < 2:
        raise ValueError(f"{RESULTS}: the section {heading!r} has {len(found)} table(s), not the two "
                         "(means per seed, paired differences) the README's line reads")  # fmt: skip
    (_, header, rows), (_, pair_header, pair_rows) = found[:2]
    means = {cells[0]: cells[header.index("mean over seeds [95% t]")] for _, cells in rows}
    column = pair_header.index("- queue_aware: mean over seeds [95% t]")
    against = {cells[0]: read_interval(cells[column]) for _, cells in pair_rows}
    seeds = sum(h.startswith("seed ") for h in header)
    own = against.pop("dueling_ddqn")
    said = {verdict(s) for s in against.values()}
    if said == {"behind"}:
        means_behind = sorted(s.mean for s in against.values())
        others = f"which trail the rule by {means_behind[0]:.0f}-{means_behind[-1]:.0f} s"
    else:
        others = "; ".join(f"{a} {verdict(s)} the rule" for a, s in against.items())
    return (f"- The first command's regime (morning peak, 400 EVs, {seeds} seeds on days 101 and 102; "
            f"regenerated on today's code by `scripts/reproduce.py readme`): Dueling DDQN "
            f"{_with_unit(means['dueling_ddqn'])}, queue_aware {_with_unit(means['queue_aware'])}, greedy "
            f"{_with_unit(means['greedy'])}; paired, {verdict(own)} queue_aware ({signed_interval(own)}) "
            f"([`docs/RESULTS.md`](docs/RESULTS.md), \"Outside algorithms\", beside evcd's PPO and "
            f"stable-baselines3's PPO and DQN, {others}).")  # fmt: skip


def _with_unit(cell: str) -> str:
    """``167.2 [135.7, 198.7]`` as ``167.2 s [135.7, 198.7]``."""
    mean, _, rest = cell.partition(" ")
    return f"{mean} s {rest}"
