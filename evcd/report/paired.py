"""Comparisons on the same episodes, and the days behind each cell of the results table.

- :func:`paired_by_seed`: agent A minus agent B, paired by episode within each seed (both jobs of a
  seed play the same evaluation episodes), then averaged over seeds with a Student-t interval across
  seeds. When each seed is evaluated on its own held-out day, the interval carries the day-to-day
  variation: seeds, not episodes, are the independent draws.
- :func:`day_rows`: the evaluation days of every (agent, EV count) and the mean travel time on each.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from evcd.report.markdown import format_stat, markdown_table, num, signed
from evcd.report.seed_stats import SeedStat, seed_interval
from evcd.report.sweep import JobResult

#: The paired comparisons the table reports: (A, B) for A - B.
PAIRS: tuple[tuple[str, str], ...] = (
    ("dqn", "queue_aware"),
    ("dueling_ddqn", "queue_aware"),
    ("dueling_ddqn", "dqn"),
)


@dataclass(frozen=True)
class PairedStat:
    """A - B over seeds: the mean of the seeds' paired mean differences with its t interval.

    Attributes:
        stat: mean, 95% interval across seeds and the number of seeds.
        per_seed: seed -> that seed's mean difference over the episodes both charged in.
        pairs: episodes compared, over all seeds.
        a_faster: pairs in which A was faster; ``b_faster`` likewise.
    """

    stat: SeedStat
    per_seed: dict[int, float]
    pairs: int
    a_faster: int
    b_faster: int


def paired_by_seed(jobs: Sequence[JobResult], regime: str, evs: int, a: str, b: str) -> PairedStat | None:
    """``a`` minus ``b`` at ``evs`` in ``regime``, paired by episode within each seed (``None`` if no
    seed has both)."""
    by = {(j.agent, j.seed): j for j in jobs if j.regime == regime and j.evs == evs}
    diffs: dict[int, list[float]] = {}
    for seed in sorted({s for agent, s in by if agent == a} & {s for agent, s in by if agent == b}):
        times_b = dict(by[b, seed].episode_travel)
        diffs[seed] = [ta - times_b[k] for k, ta in by[a, seed].episode_travel
                       if k in times_b and math.isfinite(ta) and math.isfinite(times_b[k])]  # fmt: skip
    return paired_stat(diffs)


def paired_stat(diffs: Mapping[int, Sequence[float]]) -> PairedStat | None:
    """The :class:`PairedStat` of per-seed episode differences (seed -> A - B per episode; a seed
    without any is left out; ``None`` if no seed has one)."""
    per_seed = {seed: float(np.mean(d)) for seed, d in diffs.items() if len(d)}
    if not per_seed:
        return None
    every = [x for seed in per_seed for x in diffs[seed]]
    return PairedStat(seed_interval(per_seed.values()), per_seed, len(every), sum(x < 0 for x in every),
                      sum(x > 0 for x in every))  # fmt: skip


def day_rows(jobs: Sequence[JobResult]) -> dict[tuple[str, str, int], list[tuple[int, int, float]]]:
    """(regime, agent, evs) -> ``(day, seed, mean travel time)`` of each job's evaluation days."""
    out: dict[tuple[str, str, int], list[tuple[int, int, float]]] = defaultdict(list)
    for job in jobs:
        for day, mean in job.day_means:
            out[job.regime, job.agent, job.evs].append((day, job.seed, mean))
    return {key: sorted(rows) for key, rows in out.items()}


def per_seed_text(p: PairedStat) -> str:
    """Each seed's mean difference, ``seed: difference`` joined by `` / `` (e.g. ``0: -4.0 / 1: +9.1``)."""
    return " / ".join(f"{seed}: {signed(d)}" for seed, d in p.per_seed.items())


def paired_cell(p: PairedStat) -> str:
    """A table cell: the mean difference [interval across seeds] n=seeds; A lower / B lower of pairs."""
    return f"{format_stat(p.stat, sign=True)}; {p.a_faster} / {p.b_faster} of {p.pairs}"


def paired_markdown(jobs: Sequence[JobResult]) -> list[str]:
    """The paired differences (:data:`PAIRS` present in ``jobs``, one regime) and the days table."""
    regime = jobs[0].regime
    agents = {j.agent for j in jobs}
    pairs = [(a, b) for a, b in PAIRS if a in agents and b in agents]
    lines: list[str] = []
    if pairs:
        rows, per_seed = [], []
        for evs in sorted({j.evs for j in jobs}):
            cells = []
            for a, b in pairs:
                p = paired_by_seed(jobs, regime, evs, a, b)
                if p is None:
                    cells.append("—")
                    continue
                cells.append(paired_cell(p))
                per_seed.append([f"{a} - {b}", str(evs), per_seed_text(p)])
            rows.append([str(evs), *cells])
        lines += [
            "### Paired differences (s)",
            "",
            "A - B on the same evaluation episodes: per seed the mean difference over the episodes both "
            "charged in, then the mean over seeds [95% Student-t interval across seeds] (each seed's "
            "episodes are one draw of days and departures, so the interval carries the day-to-day "
            "variation when seeds run on their own days); then in how many episode pairs A was faster / "
            "B was faster. Negative: A is faster.",
            "",
            *markdown_table(["EVs", *(f"{a} - {b}" for a, b in pairs)], rows),
            "",
            *markdown_table(["pair", "EVs", "per seed (seed: mean difference, s)"], per_seed),
            "",
        ]
    days = day_rows(jobs)
    rows = []
    for (_, agent, evs), entries in sorted(days.items(), key=lambda kv: (kv[0][1], kv[0][2])):
        spread = ", ".join(f"{day} (seed {seed}): {num(mean)}" for day, seed, mean in entries)
        rows.append([agent, str(evs), str(len({d for d, _, _ in entries})), spread])
    lines += [
        "### Evaluation days",
        "",
        "The background days each cell was evaluated on (demand seeds) and the mean travel time (s) on each.",
        "",
        *markdown_table(["agent", "EVs", "days", "per day: mean travel time (s)"], rows),
    ]
    return lines
