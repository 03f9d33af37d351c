"""The fleet's results table (docs/FLEET.md): a sweep of ``scripts/train.py experiment=fleet`` over
dispatchers, guided shares and seeds, read into one table.

    python scripts/train.py -m experiment=fleet seed=0,1,2,3,4 fleet.guided_share=0.25,0.5,1.0 \\
        agent=dueling_ddqn,dqn,central,reservation,queue_aware,greedy eval.baselines=[]
    python scripts/make_table.py --fleet outputs/fleet/<time>   (experiment=fleet sweeps there)

Every job of a seed plays the same evaluation fleet episodes (the evaluation stream of the seed: same
days, same guided EVs), so the dispatchers of a cell are paired by seed and episode. Per cell
(EV count, guided share, dispatcher): the mean over seeds of each job's mean over its fleet episodes,
with a Student-t interval across seeds (seeds are the independent draws of days and guided EVs), for
the guided EVs and for ALL EVs charging in the window; and the paired differences of
:data:`FLEET_PAIRS`: per seed the mean over episodes of A - B, then the mean over seeds with its
t interval; where learners validated, their validation minus ``queue_aware``'s per number of training
episodes (:func:`evcd.report.table.validation_markdown`). Files: ``fleet_results.md``,
``fleet_results.csv`` (one row per job), ``fleet_results_bars.png`` and, where learners validated,
``fleet_validation_curves.png`` (the periodic held-out validation per cell, and each seed paired with
``queue_aware`` on its own validation episodes).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from evcd.loops.run_files import ENVIRONMENTS
from evcd.report.figures import agent_colors, plot_results_bars, plot_validation_curves
from evcd.report.fleet_room import BOUND_AGENT, Cell, room_markdown
from evcd.report.markdown import format_stat, markdown_table, num
from evcd.report.paired import PairedStat, paired_cell, paired_stat, per_seed_text
from evcd.report.seed_stats import SeedStat, seed_interval
from evcd.report.stamp import JobStamp, job_stamp, stamp_markdown
from evcd.report.sweep import Collection, ResultsError, WrongTaskError, collect, world_label
from evcd.report.table import (
    GAP_RULE,
    validation_gaps,
    validation_markdown,
    validation_points,
    validation_rule_means,
)
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger(__name__)

MD_NAME = "fleet_results.md"
CSV_NAME = "fleet_results.csv"
BARS_PNG = "fleet_results_bars.png"
VALIDATION_PNG = "fleet_validation_curves.png"
#: Dispatchers in the order of the table's columns (others follow alphabetically).
FLEET_AGENT_ORDER = (
    "random", "greedy", "queue_aware", "reservation", "central", "dqn", "dueling_ddqn", BOUND_AGENT,
)  # fmt: skip
#: The paired comparisons the table reports: (A, B) for A - B.
FLEET_PAIRS: tuple[tuple[str, str], ...] = (
    ("dqn", "queue_aware"),
    ("dueling_ddqn", "queue_aware"),
    ("dqn", "reservation"),
    ("dueling_ddqn", "reservation"),
    ("dqn", "central"),
    ("dueling_ddqn", "central"),
    ("dueling_ddqn", "dqn"),
)
#: The columns of the per-dispatcher table, after the cell's.
DETAIL_COLUMNS = ("dispatcher", "seeds", "truncated", "herding", "queue wait", "with truncated", "training")
#: The travel times of the table: the guided EVs' and everybody's charging in the window.
MEASURES: dict[str, str] = {"guided_travel": "the guided EVs", "all_travel": "all EVs charging in the window"}


@dataclass(frozen=True)
class FleetJob:
    """One finished fleet job, from its ``results.json`` (NaN where it has null)."""

    KEY_NAMES: ClassVar[tuple[str, ...]] = ("regime", "evs", "guided_share", "agent", "seed")
    regime: str
    agent: str
    evs: int
    guided_share: float
    seed: int
    episodes: int
    guided: int
    truncated: int
    guided_travel: float
    all_travel: float
    queue_wait: float
    herding: float
    train_episodes: int
    train_transitions: int
    train_wall_s: float
    eval_days: tuple[int, ...]
    environment: str  # the environment's versioned id; the four provenance columns: evcd.report.stamp
    evcd: str
    commit: str
    machine: str
    job_dir: Path
    #: every guided EV, truncated ones at their truncation (NaN for runs made before the measure)
    guided_travel_censored: float = math.nan
    #: a ``fleet_bound`` job's mean over its episodes of the solver's proven bound (NaN for the others)
    bound: float = math.nan
    #: per evaluation fleet episode: (episode, day, guided EVs' mean, all EVs' mean), for the pairs
    per_episode: tuple[tuple[int, int, float, float], ...] = dataclasses.field(default=(), repr=False)
    #: a ``fleet_bound`` job's proven bound per evaluation fleet episode: (episode, day, bound)
    per_episode_bound: tuple[tuple[int, int, float], ...] = dataclasses.field(default=(), repr=False)
    #: the periodic held-out validation: (training episodes done, guided EVs' mean) per point
    validation: tuple[tuple[int, float], ...] = dataclasses.field(default=(), repr=False)
    #: the rules' means on the same validation episodes, by rule
    validation_rules: tuple[tuple[str, float], ...] = dataclasses.field(default=(), repr=False)

    @property
    def stamp(self) -> JobStamp:
        """Where the job's numbers come from (environment, code, machine)."""
        return JobStamp(self.environment, self.evcd, self.commit, self.machine)

    @property
    def key(self) -> tuple[str, int, float, str, int]:
        """``(regime, evs, guided_share, agent, seed)``: what a job stands for in the table."""
        return self.regime, self.evs, self.guided_share, self.agent, self.seed


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


def fleet_job(data: Mapping[str, Any], job_dir: Path) -> FleetJob:
    """The :class:`FleetJob` of a fleet run's parsed ``results.json``.

    Raises:
        WrongTaskError: not a fleet run; KeyError, TypeError: a field is missing or malformed.
    """
    if data.get("task") != "fleet":
        raise WrongTaskError(f"{job_dir} is a single-target run, not a fleet run (its results.json has no "
                             "task: fleet): make its table without --fleet")  # fmt: skip
    summary, config, training = data["summary"], data["config"], data.get("training") or {}
    if not isinstance(config, Mapping):
        raise KeyError("config")
    episodes = data.get("episodes") or []
    validation = data.get("validation") or {}
    per_episode = tuple(
        (int(e["episode"]), int(e["day"]), _float(e["guided_travel"]), _float(e["all_travel"]))
        for e in episodes
    )
    bounds = tuple((int(e["index"]), int(e["day"]), _float(e.get("bound")))
                   for e in (data.get("fleet_bound") or {}).get("episodes", ()))  # fmt: skip
    return FleetJob(
        regime=world_label(config),  # a perturbed or better-informed world is a table of its own
        agent=str(data["agent"]),
        evs=int(config["evs"]),
        guided_share=float(config["fleet"]["guided_share"]),
        seed=int(data["seed"]),
        episodes=int(summary["episodes"]),
        guided=int(summary["guided"]),
        truncated=int(summary["truncated"]),
        guided_travel=_float(summary["guided_travel"]),
        all_travel=_float(summary["all_travel"]),
        queue_wait=_float(summary.get("queue_wait")),
        herding=_float(summary.get("herding")),
        train_episodes=int(training.get("episodes", 0)),
        train_transitions=int(training.get("transitions", 0)),
        train_wall_s=_float(training.get("wall_s", 0.0)),
        eval_days=tuple(sorted({d for _, d, _, _ in per_episode})),
        **dataclasses.asdict(job_stamp(data)),
        job_dir=job_dir,
        guided_travel_censored=_float(summary.get("guided_travel_censored")),
        bound=_nanmean([b for _, _, b in bounds]),
        per_episode_bound=bounds,
        per_episode=per_episode,
        validation=tuple(
            (int(p["episodes_done"]), _float(p.get("mean"))) for p in validation.get("points", ())
        ),
        validation_rules=tuple((str(k), _float(v)) for k, v in (validation.get("rule_means") or {}).items()),
    )


def _rank(agent: str) -> tuple[int, str]:
    return (FLEET_AGENT_ORDER.index(agent) if agent in FLEET_AGENT_ORDER else len(FLEET_AGENT_ORDER), agent)


def sort_key(job: FleetJob) -> tuple[Any, ...]:
    """Rows are sorted by regime, EV count, guided share, dispatcher, seed."""
    return job.regime, job.evs, job.guided_share, _rank(job.agent), job.seed


def _cells(jobs: Sequence[FleetJob]) -> list[Cell]:
    return sorted({(j.regime, j.evs, j.guided_share) for j in jobs})


def cell_stat(jobs: Sequence[FleetJob], cell: Cell, agent: str, measure: str) -> SeedStat:
    """Mean over seeds of ``agent``'s ``measure`` in ``cell`` with its t interval across seeds."""
    return seed_interval(getattr(j, measure) for j in jobs if (j.regime, j.evs, j.guided_share) == cell
                         and j.agent == agent)  # fmt: skip


def paired_fleet(jobs: Sequence[FleetJob], cell: Cell, a: str, b: str, measure: str) -> PairedStat | None:
    """``a`` minus ``b`` in ``cell`` on ``measure``, paired by episode within each seed (the same
    evaluation fleet episodes: same index and day), then over seeds (``None`` if no seed has both)."""
    column = {"guided_travel": 2, "all_travel": 3}[measure]
    by = {(j.agent, j.seed): j for j in jobs if (j.regime, j.evs, j.guided_share) == cell}
    diffs: dict[int, list[float]] = {}
    for seed in sorted({s for x, s in by if x == a} & {s for x, s in by if x == b}):
        values_b = {(e[0], e[1]): e[column] for e in by[b, seed].per_episode}
        both = [
            (e[column], values_b[e[0], e[1]]) for e in by[a, seed].per_episode if (e[0], e[1]) in values_b
        ]
        diffs[seed] = [x - y for x, y in both if math.isfinite(x) and math.isfinite(y)]
    return paired_stat(diffs)


def _nanmean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def _censored(values: Sequence[float]) -> str:
    """The mean over seeds of the censored travel time, ``—`` unless every job measured it."""
    return num(float(np.mean(values))) if values and all(math.isfinite(v) for v in values) else "—"


def _cell_label(cell: Cell, regimes: int) -> list[str]:
    return [*([cell[0]] if regimes > 1 else []), str(cell[1]), f"{cell[2]:g}"]


def fleet_markdown(collection: Collection) -> str:
    """The table's Markdown: settings, the two travel times per cell, the pairs, per-job details."""
    jobs: list[FleetJob] = list(collection.jobs)
    cells = _cells(jobs)
    agents = sorted({j.agent for j in jobs}, key=_rank)
    regimes = len({c[0] for c in cells})
    head = [*(["regime"] if regimes > 1 else []), "EVs", "guided share"]
    seeds = sorted({j.seed for j in jobs})
    days = sorted({d for j in jobs for d in j.eval_days})
    lines = [
        "# The fleet table",
        "",
        f"{len(jobs)} jobs from {', '.join(map(str, collection.sources))}; seeds {seeds}; "
        f"{sorted({j.episodes for j in jobs})} evaluation fleet episodes per job on days {days}.",
        "",
    ]
    if regimes == 1:  # the world is no column: say which it is
        lines += [f"World: `{cells[0][0]}`.", ""]
    lines += [*stamp_markdown([j.stamp for j in jobs], ENVIRONMENTS["fleet"]), ""]
    if collection.gaps:
        lines += [
            "Jobs that did not finish (left out):",
            "",
            *(f"- {g.describe()}" for g in collection.gaps),
            "",
        ]
    for measure, label in MEASURES.items():
        rows = [[*_cell_label(c, regimes), *(format_stat(cell_stat(jobs, c, a, measure)) for a in agents)]
                for c in cells]  # fmt: skip
        lines += [
            f"## Mean travel time of {label} (s)",
            "",
            "Per job the mean over its fleet episodes of the episode's mean; mean over seeds [95% Student-t "
            "interval across seeds].",
            "",
            *markdown_table([*head, *agents], rows),
            "",
        ]
    lines += room_markdown(jobs, cells, {c: _cell_label(c, regimes) for c in cells}, head, agents)
    if validation := validation_markdown(jobs, _panel, head, lambda c: _cell_label(c, regimes), _rank,
                                         "guided EVs' mean travel time", "##"):  # fmt: skip
        lines += [*validation, ""]
    pairs = [(a, b) for a, b in FLEET_PAIRS if a in agents and b in agents]
    if pairs:
        for measure, label in MEASURES.items():
            rows, per_seed = [], []
            for c in cells:
                cells_out = []
                for a, b in pairs:
                    p = paired_fleet(jobs, c, a, b, measure)
                    if p is None:
                        cells_out.append("—")
                        continue
                    cells_out.append(paired_cell(p))
                    per_seed.append([f"{a} - {b}", *_cell_label(c, regimes), per_seed_text(p)])
                rows.append([*_cell_label(c, regimes), *cells_out])
            lines += [
                f"## Paired differences on {label} (s)",
                "",
                "A - B on the same fleet episodes: per seed the mean over episodes of the difference of the "
                "episode means, then the mean over seeds [95% Student-t interval across seeds]; then in how "
                "many episode pairs A was lower / B was lower. Negative: A is faster.",
                "",
                *markdown_table([*head, *(f"{a} - {b}" for a, b in pairs)], rows),
                "",
                *markdown_table(["pair", *head, "per seed (seed: mean difference, s)"], per_seed),
                "",
            ]
    rows = []
    for c in cells:
        for a in agents:
            group = [j for j in jobs if (j.regime, j.evs, j.guided_share) == c and j.agent == a]
            if not group:
                continue
            trained = sum(j.train_episodes for j in group)
            steps, minutes = sum(j.train_transitions for j in group), sum(j.train_wall_s for j in group) / 60
            rows.append([
                *_cell_label(c, regimes), a, str(len(group)),
                f"{sum(j.truncated for j in group)} of {sum(j.guided for j in group)}",
                num(_nanmean([j.herding for j in group]), 2), num(_nanmean([j.queue_wait for j in group])),
                _censored([j.guided_travel_censored for j in group]),
                f"{trained} / {steps} / {num(minutes)}" if trained else "—",
            ])  # fmt: skip
    lines += [
        "## Per dispatcher",
        "",
        "Over the seeds of each cell: guided EVs truncated, the mean herding (largest share of the guided "
        "EVs of a 10-minute bin sent to one station) and queue wait (s), the guided EVs' mean travel time "
        "with the truncated ones counted at their truncation (s, a lower bound; mean over seeds, — for "
        "runs made before this measure), and for learners the training episodes / agent steps / "
        "minutes, summed over seeds.",
        "",
        *markdown_table([*head, *DETAIL_COLUMNS], rows),
        "",
    ]
    return "\n".join(lines)


CSV_COLUMNS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(FleetJob) if f.repr)


def fleet_csv_text(jobs: Sequence[FleetJob]) -> str:
    """One row per job (columns :data:`CSV_COLUMNS`); NaN as ``nan``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for job in jobs:
        row = []
        for name in CSV_COLUMNS:
            value = getattr(job, name)
            row.append(" ".join(map(str, value)) if isinstance(value, tuple) else value)
        writer.writerow(row)
    return buf.getvalue()


@dataclass(frozen=True)
class FleetTableOutputs:
    """What :func:`make_fleet_table` wrote, and the collection it was made of."""

    markdown: str
    paths: tuple[Path, ...]
    collection: Collection


def make_fleet_table(
    dirs: Sequence[str | Path],
    out_dir: str | Path | None = None,
    overwrite: bool = False,
    allow_incomplete: bool = False,
) -> FleetTableOutputs:
    """Collect the fleet jobs of ``dirs``; write ``fleet_results.md``, ``fleet_results.csv`` and
    ``fleet_results_bars.png`` into ``out_dir`` (default: the first of ``dirs``).

    Raises:
        IncompleteSweepError, ResultsError: see :func:`evcd.report.sweep.collect` (a single-target job
            is a failed job here).
        FileExistsError: an output exists and ``overwrite`` is false (checked before anything is read).
    """
    if not dirs:
        raise ResultsError("no directory given")
    out = Path(out_dir) if out_dir is not None else Path(dirs[0])
    existing = [str(out / n) for n in (MD_NAME, CSV_NAME, BARS_PNG) if (out / n).exists()]
    if existing and not overwrite:
        raise FileExistsError(f"refusing to overwrite {', '.join(existing)} (pass overwrite / --overwrite)")
    collection = collect(dirs, allow_incomplete, parse=fleet_job)
    collection = dataclasses.replace(collection, jobs=tuple(sorted(collection.jobs, key=sort_key)))
    jobs: list[FleetJob] = list(collection.jobs)
    out.mkdir(parents=True, exist_ok=True)
    markdown = fleet_markdown(collection)
    paths = [
        atomic_write_text(out / MD_NAME, markdown),
        atomic_write_text(out / CSV_NAME, fleet_csv_text(jobs)),
    ]
    agents = sorted({j.agent for j in jobs}, key=_rank)
    stats: dict[str, dict[str, dict[float, SeedStat]]] = {}
    for regime, evs, share in _cells(jobs):
        panel = stats.setdefault(f"{regime}, {evs} EVs", {})
        for a in agents:
            stat = cell_stat(jobs, (regime, evs, share), a, "guided_travel")
            if stat.n:
                panel.setdefault(a, {})[share] = stat
    title = "Fleet: guided EVs' mean travel time, mean over seeds, 95% interval across seeds (Student t)"
    paths.append(plot_results_bars(stats, out / BARS_PNG, colors=agent_colors(agents), title=title,
                                   xlabel="guided share"))  # fmt: skip
    validation = validation_points(jobs, _panel)
    if validation:
        titles = {key: f"guided share {key[2]:g}, {key[1]} EVs" for key in validation}
        gaps = validation_gaps(jobs, GAP_RULE, _panel)
        rules = validation_rule_means(jobs, _panel)
        png = out / VALIDATION_PNG
        paths.append(
            plot_validation_curves(validation, rules, png, agent_colors(agents), gaps, GAP_RULE, titles)
        )
    for path in paths:
        log.info("wrote %s", path)
    return FleetTableOutputs(markdown, tuple(paths), collection)


def _panel(job: FleetJob) -> Cell:
    """The validation figure's panel of a job: its cell (regime, EV count, guided share)."""
    return job.regime, job.evs, job.guided_share
