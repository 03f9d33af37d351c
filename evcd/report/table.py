"""Make the results table over seeds of a Hydra multirun sweep of ``scripts/train.py``.

    out = make_table([Path("outputs/train_multirun/2026-11-23_10-00-00")])
    print(out.markdown)

1. **Collect** the finished jobs, stopping at a missing or failed one unless ``allow_incomplete``
   (:func:`evcd.report.sweep.collect`).
2. **Tabulate** per regime and EV count: a cell is the mean over seeds of each seed's evaluation mean
   travel time with its 95% interval across seeds, beside the paper's values (:data:`PAPER_TRAVEL_TIME`);
   then the share of the greedy -> hindsight gap each of :data:`GAP_AGENTS` closes, with its paired
   bootstrap interval (:mod:`evcd.report.seed_stats`); the paired differences and evaluation days
   (:mod:`evcd.report.paired`); where learners validated, their validation minus :data:`GAP_RULE`'s
   per number of training episodes (what a training length can be chosen on). Agents in the order
   :data:`AGENT_ORDER`.
3. **Write** into the output directory (nothing existing is overwritten unless ``overwrite``):
   ``results.csv`` (one row per job), ``results.md`` (the tables), ``results_bars.png``,
   ``learning_curves.png`` and, where learners validated, ``validation_curves.png`` (the periodic
   held-out validation, and each seed paired with :data:`GAP_RULE` on its own validation
   episodes) (:mod:`evcd.report.figures`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from evcd.env.runners.base import EpisodeRow
from evcd.loops.run_files import ENVIRONMENTS, TRAIN_CSV, read_episodes_csv
from evcd.report.figures import agent_colors, plot_results_bars, plot_training_curves, plot_validation_curves
from evcd.report.markdown import format_stat, markdown_table, num
from evcd.report.paired import paired_markdown
from evcd.report.seed_stats import MIN_GAP_S, SeedStat, gap_share, seed_interval
from evcd.report.stamp import stamp_markdown
from evcd.report.sweep import Collection, JobResult, ResultsError, collect
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger(__name__)

#: Files written into the output directory.
CSV_NAME = "results.csv"
MD_NAME = "results.md"
BARS_PNG = "results_bars.png"
CURVES_PNG = "learning_curves.png"
VALIDATION_PNG = "validation_curves.png"
#: The rule the validation figure's lower panels pair each learner with, seed by seed.
GAP_RULE = "queue_aware"

#: Column order of agents; other agents follow alphabetically.
AGENT_ORDER = ("random", "greedy", "queue_aware", "dqn", "dueling_ddqn", "hindsight")
#: Agents whose share of the greedy -> hindsight gap is tabulated.
GAP_AGENTS = ("queue_aware", "dqn", "dueling_ddqn")
#: Song et al. (arXiv 2209.02921), mean travel time (s) over its 50 training episodes, whole day.
PAPER_TRAVEL_TIME: dict[str, dict[int, float]] = {
    "random": {200: 942.0, 300: 1377.0, 400: 1955.0},
    "greedy": {200: 750.0, 300: 1158.0, 400: 1648.0},
    "dqn": {200: 545.0, 300: 633.0, 400: 1387.0},
    "dueling_ddqn": {200: 632.0, 300: 587.0, 400: 843.0},
}
PAPER_LABELS = {"random": "random", "greedy": "greedy", "dqn": "DQN", "dueling_ddqn": "Dueling DDQN"}

#: Columns of ``results.csv``: the fields of a job (its per-episode values stay in its results.json).
CSV_COLUMNS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(JobResult) if f.repr)


@dataclass(frozen=True)
class TableOutputs:
    """What :func:`make_table` wrote, and the collection it was made of (jobs in :func:`sort_key` order)."""

    markdown: str
    paths: tuple[Path, ...]
    collection: Collection


# ---------------------------------------------------------------------------------------- grouping
def agent_rank(agent: str) -> tuple[int, str]:
    """Sort key of agents: :data:`AGENT_ORDER`, then the others alphabetically."""
    return (AGENT_ORDER.index(agent) if agent in AGENT_ORDER else len(AGENT_ORDER), agent)


def sort_key(job: JobResult) -> tuple[Any, ...]:
    """Rows are sorted by regime, agent (:func:`agent_rank`), evs, seed."""
    return job.regime, agent_rank(job.agent), job.evs, job.seed


def seed_means(
    jobs: Iterable[JobResult], field: str = "mean_travel_time"
) -> dict[tuple[str, str, int], dict[int, float]]:
    """(regime, agent, evs) -> seed -> the job's ``field``."""
    out: dict[tuple[str, str, int], dict[int, float]] = defaultdict(dict)
    for job in jobs:
        out[job.regime, job.agent, job.evs][job.seed] = float(getattr(job, field))
    return dict(out)


def _by_regime(jobs: Sequence[JobResult]) -> dict[str, list[JobResult]]:
    out: dict[str, list[JobResult]] = defaultdict(list)
    for job in jobs:
        out[job.regime].append(job)
    return dict(sorted(out.items()))


def _agents(jobs: Iterable[JobResult]) -> list[str]:
    return sorted({j.agent for j in jobs}, key=agent_rank)


# ---------------------------------------------------------------------------------------- CSV
def _csv_value(value: Any) -> Any:
    if isinstance(value, tuple):
        return json.dumps(list(value))
    return str(value) if isinstance(value, Path) else value


def results_csv_text(jobs: Sequence[JobResult]) -> str:
    """One row per job (columns :data:`CSV_COLUMNS`), sorted by :func:`sort_key`; NaN as ``nan``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for job in sorted(jobs, key=sort_key):
        writer.writerow([_csv_value(getattr(job, c)) for c in CSV_COLUMNS])
    return buf.getvalue()


# ---------------------------------------------------------------------------------------- Markdown
def _values(jobs: Sequence[JobResult], field: str) -> str:
    counts: dict[str, int] = defaultdict(int)
    for job in jobs:
        value = getattr(job, field)
        counts[json.dumps(list(value)) if isinstance(value, tuple) else str(value)] += 1
    if len(counts) == 1:
        return next(iter(counts))
    return ", ".join(f"{v} ({n} jobs)" for v, n in sorted(counts.items()))


def _jobs_line(jobs: Sequence[JobResult]) -> str:
    seeds = sorted({j.seed for j in jobs})
    learners = [j for j in jobs if j.train_episodes > 0]
    train = f"; {_values(learners, 'train_episodes')} training episodes per learner" if learners else ""
    evs = ", ".join(map(str, sorted({j.evs for j in jobs})))
    return (
        f"Jobs: {len(jobs)} ({len(_agents(jobs))} agents, EV counts {evs}, "
        f"{len(seeds)} seeds: {', '.join(map(str, seeds))}); {_values(jobs, 'eval_episodes')} evaluation "
        f"episodes per job{train}; training days {_values(jobs, 'train_days')}, evaluation days "
        f"{_values(jobs, 'eval_days')}."
    )


def _main_table(jobs: Sequence[JobResult]) -> list[str]:
    means = seed_means(jobs)
    agents = _agents(jobs)
    regime = jobs[0].regime
    header = ["EVs", *agents, *(f"paper {PAPER_LABELS[a]}" for a in PAPER_TRAVEL_TIME)]
    rows = []
    for evs in sorted({j.evs for j in jobs}):
        cells = [format_stat(seed_interval(means.get((regime, a, evs), {}).values())) for a in agents]
        paper = [num(PAPER_TRAVEL_TIME[a].get(evs, math.nan), 0) for a in PAPER_TRAVEL_TIME]
        rows.append([str(evs), *cells, *paper])
    return [
        "### Mean travel time (s)",
        "",
        "Each cell: the mean over seeds of each seed's evaluation mean travel time, [its 95% interval across "
        "seeds] (Student t, n - 1 degrees of freedom), n = seeds (a seed whose evaluation episodes were all "
        "truncated has no mean and is left out). The *paper* columns are Song et al.'s table: whole day, "
        "mean over its 50 training episodes (exploration included), one run.",
        "",
        *markdown_table(header, rows),
    ]


def _gap_table(jobs: Sequence[JobResult], rng: np.random.Generator, resamples: int) -> list[str]:
    means = seed_means(jobs)
    regime = jobs[0].regime
    agents = [a for a in GAP_AGENTS if any(j.agent == a for j in jobs)]
    title = ["### Share of the greedy -> hindsight gap closed", ""]
    if not {"greedy", "hindsight"} <= {j.agent for j in jobs} or not agents:
        return [*title, "Needs greedy, hindsight and at least one of " + ", ".join(GAP_AGENTS) + "."]
    rows = []
    for evs in sorted({j.evs for j in jobs}):
        g, h = means.get((regime, "greedy", evs), {}), means.get((regime, "hindsight", evs), {})
        gap = seed_interval(g[s] - h[s] for s in sorted(set(g) & set(h)))
        cells = []
        for agent in agents:
            share = gap_share(g, means.get((regime, agent, evs), {}), h, rng, resamples)
            if share.gap.n == 0:
                cells.append("—")
            elif not share.room:
                cells.append("no room")
            elif share.gap.n == 1:
                cells.append(f"{share.share:.2f} n=1")
            else:
                cells.append(f"{share.share:.2f} [{share.low:.2f}, {share.high:.2f}] n={share.gap.n}")
        rows.append([str(evs), format_stat(gap), *cells])
    return [
        *title,
        "share = (G - A) / (G - H) from the seed means (G greedy, A the agent, H hindsight best; 1: the "
        "agent reaches the hindsight bound, 0: no better than greedy, < 0: worse), [95% paired bootstrap "
        f"interval over seeds]. *no room*: G - H below {MIN_GAP_S:g} s or its 95% interval across seeds "
        "includes 0.",
        "",
        *markdown_table(["EVs", "greedy - hindsight (s)", *agents], rows),
    ]


def _agent_evs_groups(jobs: Sequence[JobResult]) -> list[tuple[str, int, list[JobResult]]]:
    """``(agent, evs, the jobs of that cell)`` in table order (agents by :func:`_agents`, EVs ascending)."""
    return [
        (agent, evs, [j for j in jobs if j.agent == agent and j.evs == evs])
        for agent in _agents(jobs)
        for evs in sorted({j.evs for j in jobs if j.agent == agent})
    ]


def _detail_table(jobs: Sequence[JobResult]) -> list[str]:
    rows = []
    for agent, evs, group in _agent_evs_groups(jobs):
        learns = any(j.train_episodes > 0 for j in group)
        rows.append([
            agent, str(evs), str(len(group)),
            f"{sum(j.truncated for j in group)} / {sum(j.eval_episodes for j in group)}",
            num(seed_interval(j.mean_queue_wait for j in group).mean),
            num(seed_interval(j.train_wall_s for j in group).mean, 0) if learns else "—",
        ])  # fmt: skip
    header = ["agent", "EVs", "seeds", "truncated / episodes", "mean queue wait (s)"]
    header.append("training wall time (s)")
    return [
        "### Per agent and EV count",
        "",
        "Truncated evaluation episodes over all seeds; queue wait and training wall time (day builds "
        "excluded): means over seeds.",
        "",
        *markdown_table(header, rows),
    ]


def _paper_table(jobs: Sequence[JobResult]) -> list[str]:
    rows = []
    for agent, evs, group in _agent_evs_groups(jobs):
        rows.append([
            agent, str(evs),
            format_stat(seed_interval(j.train_mean_travel_time for j in group)),
            format_stat(seed_interval(j.mean_travel_time for j in group)),
            num(PAPER_TRAVEL_TIME.get(agent, {}).get(evs, math.nan), 0),
        ])  # fmt: skip
    return [
        "### The paper's way: mean over the training episodes",
        "",
        "Training mean: each seed's mean travel time over its training episodes (exploration included, as "
        "the paper reports; rules do not train), then mean [95% interval] over seeds; evaluation mean as "
        "above.",
        "",
        *markdown_table(["agent", "EVs", "training mean (s)", "evaluation mean (s)", "paper (s)"], rows),
    ]


def results_markdown(
    collection: Collection, resamples: int = 10_000, bootstrap_seed: int = 0, figures: Sequence[str] = ()
) -> str:
    """The Markdown report: per regime the main table, the gap shares, the per-agent details, the paired
    differences, the validation by training length and (regime ``paper``) the training means; then the
    gaps (with ``allow_incomplete``) and links to ``figures``."""
    rng = np.random.default_rng(bootstrap_seed)
    jobs = collection.jobs
    lines = [
        "# Results over seeds",
        "",
        f"{len(jobs)} finished jobs of {collection.expected} expected, from "
        + ", ".join(f"`{s}`" for s in collection.sources)
        + ".",
    ]
    lines += ["", *stamp_markdown([j.stamp for j in jobs], ENVIRONMENTS["single"])]
    for regime, group in _by_regime(jobs).items():
        lines += ["", f"## Regime `{regime}`", "", _jobs_line(group), ""]
        lines += [*_main_table(group), "", *_gap_table(group, rng, resamples), "", *_detail_table(group)]
        lines += ["", *paired_markdown(group)]
        if validation := validation_markdown(group, _regime_evs, ["EVs"], lambda k: [str(k[1])], agent_rank):
            lines += ["", *validation]
        if regime == "paper":
            lines += ["", *_paper_table(group)]
    if collection.gaps:
        missing = sum(g.status == "missing" for g in collection.gaps)
        failed = len(collection.gaps) - missing
        lines += ["", f"## Missing or failed jobs ({missing} missing, {failed} failed)", ""]
        lines += [f"- {g.describe()}" for g in collection.gaps]
    if figures:
        lines += ["", *(f"![{Path(f).stem}]({f})" for f in figures)]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------- figures
def bar_stats(jobs: Sequence[JobResult]) -> dict[str, dict[str, dict[int, SeedStat]]]:
    """regime -> agent -> evs -> :class:`SeedStat` of the evaluation means (what the bar chart shows)."""
    out: dict[str, dict[str, dict[int, SeedStat]]] = {}
    for (regime, agent, evs), seeds in seed_means(jobs).items():
        out.setdefault(regime, {}).setdefault(agent, {})[evs] = seed_interval(seeds.values())
    return {r: dict(sorted(a.items(), key=lambda kv: agent_rank(kv[0]))) for r, a in sorted(out.items())}


def training_rows(jobs: Sequence[JobResult]) -> dict[tuple[str, int], dict[str, list[list[EpisodeRow]]]]:
    """(regime, evs) -> agent -> each seed's training rows, for the jobs that trained and wrote them."""
    out: dict[tuple[str, int], dict[str, list[list[EpisodeRow]]]] = {}
    for job in jobs:
        path = job.job_dir / TRAIN_CSV
        if job.train_episodes <= 0:
            continue
        if not path.is_file():
            log.warning("%s: trained but has no %s; left out of the learning curves", job.job_dir, TRAIN_CSV)
            continue
        out.setdefault((job.regime, job.evs), {}).setdefault(job.agent, []).append(read_episodes_csv(path))
    return dict(sorted(out.items()))


Points = list[tuple[int, float]]  # (training episodes done, validation mean travel time)
#: What a validation panel groups jobs by: a tuple of their fields (``(regime, evs)`` by default).
PanelKey = Callable[[Any], tuple[Any, ...]]


def _regime_evs(job: Any) -> tuple[str, int]:
    return job.regime, job.evs


def validation_points(jobs: Sequence[Any], key: PanelKey = _regime_evs) -> dict[Any, dict[str, list[Points]]]:
    """Panel key (``(regime, evs)``) -> agent -> each seed's periodic validation points, for the jobs
    that validated (any job with ``agent``, ``validation`` and ``validation_rules``: the fleet's too)."""
    out: dict[Any, dict[str, list[Points]]] = {}
    for job in jobs:
        if job.validation:
            out.setdefault(key(job), {}).setdefault(job.agent, []).append(list(job.validation))
    return dict(sorted(out.items()))


def validation_gaps(
    jobs: Sequence[Any], rule: str = GAP_RULE, key: PanelKey = _regime_evs
) -> dict[Any, dict[str, list[Points]]]:
    """Panel key -> agent -> each seed's validation points minus ``rule``'s validation mean in the
    same job (the same episodes: a paired difference per point; negative: the learner is faster).
    Jobs whose validation did not run ``rule`` are left out."""
    out: dict[Any, dict[str, list[Points]]] = {}
    for job in jobs:
        base = dict(job.validation_rules).get(rule)
        if job.validation and base is not None:
            gaps = [(episodes, mean - base) for episodes, mean in job.validation]
            out.setdefault(key(job), {}).setdefault(job.agent, []).append(gaps)
    return dict(sorted(out.items()))


def validation_rule_means(jobs: Sequence[Any], key: PanelKey = _regime_evs) -> dict[Any, dict[str, float]]:
    """Panel key -> rule -> its validation mean over the seeds of the jobs that validated."""
    values: dict[Any, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for job in jobs:
        for rule, mean in job.validation_rules:
            values[key(job)][rule].append(mean)
    return {k: {rule: float(np.mean(v)) for rule, v in rules.items()} for k, rules in values.items()}


def validation_markdown(
    jobs: Sequence[Any],
    key: PanelKey,
    head: Sequence[str],
    label: Callable[[Any], list[str]],
    rank: Callable[[str], Any],
    what: str = "mean travel time",
    heading: str = "###",
) -> list[str]:
    """The table of each learner's validation minus :data:`GAP_RULE`'s per number of training
    episodes, mean over seeds with its interval: one row per panel (``key`` of a job, shown as
    ``label(key)`` under the columns ``head``) and learner (ordered by ``rank``); nothing where no job
    validated with the rule. What a training length can be chosen on, on tuning days only."""
    gaps = validation_gaps(jobs, GAP_RULE, key)
    if not gaps:
        return []
    after = sorted({e for panel in gaps.values() for runs in panel.values() for run in runs for e, _ in run})
    rows = []
    for panel, by_agent in gaps.items():
        for agent in sorted(by_agent, key=rank):
            stats = [seed_interval(g for run in by_agent[agent] for e, g in run if e == n) for n in after]
            rows.append([*label(panel), agent, *(format_stat(x, sign=True) for x in stats)])
    return [
        f"{heading} Validation by training length (s)",
        "",
        f"The periodic validation, on tuning days (never the evaluation days): each learner's {what} minus "
        f"{GAP_RULE}'s on the same validation episodes after each number of training episodes, mean over "
        "seeds [95% Student-t interval across seeds]; negative: the learner is faster. What a training "
        "length can be chosen on without looking at the evaluation.",
        "",
        *markdown_table([*head, "agent", *(f"after {n:,}" for n in after)], rows),
    ]


def make_table(
    dirs: Sequence[str | Path],
    out_dir: str | Path | None = None,
    overwrite: bool = False,
    allow_incomplete: bool = False,
    resamples: int = 10_000,
    bootstrap_seed: int = 0,
) -> TableOutputs:
    """Collect ``dirs`` and write ``results.csv``, ``results.md`` and the figures into ``out_dir``.

    Args:
        dirs: multirun directories (and/or single run directories).
        out_dir: where the files go (default: the first of ``dirs``).
        overwrite: replace files already there.
        allow_incomplete: build the table from the finished jobs, listing the missing and failed ones.
        resamples: bootstrap resamples of the gap-share intervals.
        bootstrap_seed: seed of their generator.

    Raises:
        IncompleteSweepError, ResultsError: see :func:`evcd.report.sweep.collect`.
        FileExistsError: an output file exists and ``overwrite`` is false (checked before anything is read).
    """
    if not dirs:
        raise ResultsError("no directory given")
    out = Path(out_dir) if out_dir is not None else Path(dirs[0])
    names = (CSV_NAME, MD_NAME, BARS_PNG, CURVES_PNG, VALIDATION_PNG)
    existing = [str(out / n) for n in names if (out / n).exists()]
    if existing and not overwrite:
        raise FileExistsError(f"refusing to overwrite {', '.join(existing)} (pass overwrite / --overwrite)")
    collection = collect(dirs, allow_incomplete)
    collection = dataclasses.replace(collection, jobs=tuple(sorted(collection.jobs, key=sort_key)))
    out.mkdir(parents=True, exist_ok=True)
    paths = [atomic_write_text(out / CSV_NAME, results_csv_text(collection.jobs))]
    colors = agent_colors(_agents(collection.jobs))
    paths.append(plot_results_bars(bar_stats(collection.jobs), out / BARS_PNG, PAPER_TRAVEL_TIME, colors))
    curves = training_rows(collection.jobs)
    if curves:
        means = seed_means(collection.jobs)
        references = {
            key: {f"{a} (evaluation mean)": seed_interval(means.get((key[0], a, key[1]), {}).values()).mean
                  for a in ("greedy", "hindsight") if (key[0], a, key[1]) in means}
            for key in curves
        }  # fmt: skip
        paths.append(plot_training_curves(curves, out / CURVES_PNG, references, colors))
    else:
        log.info("no job trained (no learner): %s not drawn", CURVES_PNG)
    validation = validation_points(collection.jobs)
    if validation:
        rules = validation_rule_means(collection.jobs)
        gaps = validation_gaps(collection.jobs, GAP_RULE)
        paths.append(plot_validation_curves(validation, rules, out / VALIDATION_PNG, colors, gaps, GAP_RULE))
    figures = [p.name for p in paths if p.suffix == ".png"]
    markdown = results_markdown(collection, resamples, bootstrap_seed, figures)
    paths.insert(1, atomic_write_text(out / MD_NAME, markdown))
    for path in paths:
        log.info("wrote %s", path)
    return TableOutputs(markdown, tuple(paths), collection)
