"""Every dispatcher of a set of ``scripts/train.py`` runs, across worlds, paired on the same episodes
(``scripts/compare_runs.py``).

A run's *world* is its regime, the perturbations it played and what its agents observed
(:func:`world_label`, e.g. ``peak +incidents/outages/rain/roadworks sees PTF``); its *rows* are its
agent's evaluation episodes and each baseline rule's on the same episodes. Runs of the same seed
play the same evaluation episodes whatever the agent and whatever it observes (the days, the
departures and the origins are drawn from the seed), so a learner that sees the forecasts can be
paired with the plain queue-aware rule of another run of its seed, episode by episode.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evcd.loops.run_files import RESULTS_JSON, read_episodes_csv
from evcd.report.markdown import markdown_table
from evcd.report.paired import PairedStat, paired_cell, paired_stat
from evcd.report.seed_stats import seed_interval
from evcd.report.sweep import world_label

#: (world, dispatcher)
Row = tuple[str, str]


@dataclass
class Runs:
    """Per (world, dispatcher) and seed, the travel time of each evaluation episode by reset seed."""

    travel: dict[Row, dict[int, dict[int, float]]]

    @classmethod
    def read(cls, dirs: Sequence[Path]) -> Runs:
        """The runs under ``dirs`` (run directories, or folders holding them at any depth)."""
        travel: dict[Row, dict[int, dict[int, float]]] = {}
        found = [p for d in map(Path, dirs) for p in ([d / RESULTS_JSON] if (d / RESULTS_JSON).is_file()
                                                      else d.rglob(RESULTS_JSON))]  # fmt: skip
        for results in sorted(found):
            data = json.loads(results.read_text())
            world, seed = world_label(data["config"]), int(data["seed"])
            files = {str(data["agent"]): results.parent / "episodes.csv"}
            for rule in data.get("baselines", {}):
                files[rule] = results.parent / f"baseline_{rule}_episodes.csv"
            for agent, path in files.items():
                travel.setdefault((world, agent), {}).setdefault(seed, _episodes(path))
        return cls(travel)

    def rows(self) -> list[Row]:
        """Every (world, dispatcher), sorted."""
        return sorted(self.travel)

    def mean(self, row: Row) -> tuple[str, int]:
        """The mean over seeds of each seed's mean travel time, with its 95% t interval, and the
        seeds."""
        per_seed = [np.nanmean(list(t.values())) for t in self.travel[row].values()]
        stat = seed_interval(per_seed)
        text = f"{stat.mean:.1f} [{stat.low:.1f}, {stat.high:.1f}]" if stat.n > 1 else f"{stat.mean:.1f}"
        return text, stat.n

    def paired(self, a: Row, b: Row) -> PairedStat | None:
        """``a`` minus ``b``, paired by episode within each seed both have."""
        diffs = {}
        for seed in sorted(self.travel.get(a, {}).keys() & self.travel.get(b, {}).keys()):
            ta, tb = self.travel[a][seed], self.travel[b][seed]
            diffs[seed] = [ta[k] - tb[k] for k in ta.keys() & tb.keys()
                           if math.isfinite(ta[k]) and math.isfinite(tb[k])]  # fmt: skip
        return paired_stat(diffs)


def _episodes(path: Path) -> dict[int, float]:
    """An episodes CSV as reset seed -> travel time (NaN where truncated)."""
    return {int(r.seed): math.nan if r.truncated else float(r.travel_time) for r in read_episodes_csv(path)}


def compare_markdown(runs: Runs, references: Sequence[Row]) -> str:
    """A table: per (world, dispatcher), the mean over seeds and its paired difference with each
    reference row (mean over seeds of the per-seed mean differences [95% t])."""
    header = [
        "world",
        "dispatcher",
        "seeds",
        "mean travel time (s)",
        *(f"- {w} / {a}" for w, a in references),
    ]
    lines = []
    for row in runs.rows():
        mean, n = runs.mean(row)
        cells = []
        for ref in references:
            p = runs.paired(row, ref) if ref != row else None
            cells.append(paired_cell(p) if p is not None else "")
        lines.append([row[0], row[1], str(n), mean, *cells])
    return "\n".join(markdown_table(header, lines))
