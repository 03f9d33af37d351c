"""Every dispatcher of a set of ``scripts/train.py`` runs, across worlds, paired on the same episodes
(``scripts/compare_runs.py``).

A run's *world* is its regime, the perturbations it played and what its agents observed
(:func:`world_label`, e.g. ``peak +incidents/outages/rain/roadworks sees PTF``); its *rows* are its
agent's evaluation episodes and each baseline rule's on the same episodes. Runs of the same seed
play the same evaluation episodes whatever the agent and whatever it observes (the days, the
departures and the origins are drawn from the seed), so a learner that sees the forecasts can be
paired with the plain queue-aware rule of another run of its seed, episode by episode.

Fleet runs (``task=fleet``) are read the same way, episode by episode of the seed's evaluation fleet
episodes, on the guided EVs' mean travel time (``fleet_measure``: or ``guided_travel_censored``, or
``all_travel``); a fleet row is never paired with a single target's.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from evcd.loops.run_files import EVAL_CSV, FLEET_CSV, RESULTS_JSON, baseline_csv, read_episodes_csv
from evcd.report.markdown import interval, markdown_table
from evcd.report.paired import PairedStat, paired_cell, paired_stat, per_seed_text
from evcd.report.seed_stats import seed_interval
from evcd.report.sweep import world_label

log = logging.getLogger(__name__)

#: (world, dispatcher)
Row = tuple[str, str]
#: What a fleet run's rows compare (columns of its episodes CSV).
FLEET_MEASURES = ("guided_travel", "guided_travel_censored", "all_travel")


@dataclass
class Runs:
    """Per (world, dispatcher) and seed, the travel time of each evaluation episode by reset seed."""

    travel: dict[Row, dict[int, dict[int, float]]]
    #: the task of each row's runs ("single" or "fleet")
    task: dict[Row, str] = field(default_factory=dict)
    #: each world's calm counterpart: the same regime and observation without perturbations
    calm_world: dict[str, str] = field(default_factory=dict)

    @classmethod
    def read(cls, dirs: Sequence[Path], fleet_measure: str = "guided_travel") -> Runs:
        """The runs under ``dirs`` (run directories, or folders holding them at any depth); fleet runs
        on ``fleet_measure`` (``guided_travel``, ``guided_travel_censored`` or ``all_travel``).

        Raises:
            ValueError: another ``fleet_measure``.
        """
        if fleet_measure not in FLEET_MEASURES:
            raise ValueError(f"fleet_measure={fleet_measure!r}: choose among {', '.join(FLEET_MEASURES)}")
        runs = cls({})
        found = [p for d in map(Path, dirs) for p in ([d / RESULTS_JSON] if (d / RESULTS_JSON).is_file()
                                                      else d.rglob(RESULTS_JSON))]  # fmt: skip
        for results in sorted(found):
            data = json.loads(results.read_text())
            world, seed = world_label(data["config"]), int(data["seed"])
            runs.calm_world[world] = world_label({**data["config"], "perturbations": None})
            task = str(data.get("task", "single"))
            fleet = task == "fleet"
            files = {str(data["agent"]): results.parent / (FLEET_CSV if fleet else EVAL_CSV)}
            for rule in data.get("baselines", {}):
                files[rule] = results.parent / baseline_csv(rule, fleet=fleet)
            for agent, path in files.items():
                episodes = _fleet_episodes(path, fleet_measure) if fleet else _episodes(path)
                seeds = runs.travel.setdefault((world, agent), {})
                if seed in seeds and not _same(seeds[seed], episodes):
                    log.warning("%s / %s seed %d again in %s, with other numbers: the first run read is kept",
                                world, agent, seed, path)  # fmt: skip
                seeds.setdefault(seed, episodes)
                runs.task[(world, agent)] = task
        return runs

    def rows(self) -> list[Row]:
        """Every (world, dispatcher), sorted."""
        return sorted(self.travel)

    def mean(self, row: Row) -> tuple[str, int]:
        """The mean over seeds of each seed's mean travel time, with its 95% t interval, and the
        seeds."""
        per_seed = [np.nanmean(list(t.values())) for t in self.travel[row].values()]
        stat = seed_interval(per_seed)
        text = interval(stat) if stat.n > 1 else f"{stat.mean:.1f}"
        return text, stat.n

    def paired(self, a: Row, b: Row) -> PairedStat | None:
        """``a`` minus ``b``, paired by episode within each seed both have (``None``: rows of different
        tasks, or no seed in common)."""
        if self.task.get(a, "single") != self.task.get(b, "single"):
            return None
        diffs = {}
        for seed in sorted(self.travel.get(a, {}).keys() & self.travel.get(b, {}).keys()):
            ta, tb = self.travel[a][seed], self.travel[b][seed]
            diffs[seed] = [ta[k] - tb[k] for k in ta.keys() & tb.keys()
                           if math.isfinite(ta[k]) and math.isfinite(tb[k])]  # fmt: skip
        return paired_stat(diffs)

    def against_calm(self, row: Row) -> PairedStat | None:
        """``row`` minus the same dispatcher in the calm counterpart of its world (the same regime
        and observation, no perturbation), paired by episode (``None``: a calm world, or no calm
        run of that dispatcher)."""
        world, agent = row
        calm = (self.calm_world.get(world, world), agent)
        if calm[0] == world or calm not in self.travel:
            return None
        return self.paired(row, calm)


def _same(a: dict[int, float], b: dict[int, float]) -> bool:
    """Whether two runs' episodes hold the same numbers (NaN equal to NaN)."""
    if a.keys() != b.keys():
        return False
    return all(x == b[k] or (math.isnan(x) and math.isnan(b[k])) for k, x in a.items())


def _fleet_episodes(path: Path, measure: str) -> dict[int, float]:
    """A fleet episodes CSV as episode index -> ``measure`` (NaN where empty: the writer's None)."""
    with path.open(newline="", encoding="utf-8") as f:
        return {int(r["episode"]): float(r[measure] or "nan") for r in csv.DictReader(f)}


def _episodes(path: Path) -> dict[int, float]:
    """An episodes CSV as reset seed -> travel time (NaN where truncated)."""
    return {int(r.seed): math.nan if r.truncated else float(r.travel_time) for r in read_episodes_csv(path)}


def compare_markdown(
    runs: Runs, references: Sequence[Row], against_calm: bool = False, worlds: Sequence[str] = ()
) -> str:
    """A table: per (world, dispatcher), the mean over seeds and its paired difference with each
    reference row (mean over seeds of the per-seed mean differences [95% t]); with ``against_calm``,
    a last column: each perturbed row minus the same dispatcher calm (:meth:`Runs.against_calm`),
    what the world's perturbations do to each dispatcher, with its seeds' differences. ``worlds``:
    only the rows of these worlds (the references and calm rows they pair with may lie outside)."""
    header = [
        "world",
        "dispatcher",
        "seeds",
        "mean travel time (s)",
        *(f"- {w} / {a}" for w, a in references),
        *(["- the same dispatcher calm (per seed)"] if against_calm else []),
    ]
    lines = []
    for row in runs.rows():
        if worlds and row[0] not in worlds:
            continue
        mean, n = runs.mean(row)
        cells = []
        for ref in references:
            p = runs.paired(row, ref) if ref != row else None
            cells.append(paired_cell(p) if p is not None else "")
        if against_calm:
            p = runs.against_calm(row)
            cells.append("" if p is None else f"{paired_cell(p)} ({per_seed_text(p)})")
        lines.append([row[0], row[1], str(n), mean, *cells])
    return "\n".join(markdown_table(header, lines))
