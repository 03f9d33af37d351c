"""Render a page from its finished jobs: each render's files, and a summary with every job's wall time.

    folder = render_page(page, found, out / "rendered", manifest)

Per render (``rendered/<render>/``): ``table`` is :func:`evcd.report.table.make_table` (``results.md``,
``results.csv``, the figures), ``fleet_table`` :func:`evcd.report.fleet_table.make_fleet_table`, both
reading a view of each sweep (``rendered/collected/<sweep>``: a ``multirun.yaml`` naming the sweep's
overrides and a link to each job's run directory, wherever it ran: a sweep split in pieces, or resumed,
reads as one); ``seed_rows`` a dispatcher per row with its mean travel time per seed, the mean over
seeds [95% t] and its training (decisions, wall time); ``paired_rows`` the rows of a page's table
whose last cell pairs two (world, dispatcher) rows of :class:`evcd.report.compare.Runs` on the same
episodes (or ``by: seed``, the seeds' means); ``compare`` ``scripts/compare_runs.py``'s table of every
(world, dispatcher) row of the jobs, paired with ``references`` and, with ``against_calm``, with the same
dispatcher calm (and with ``figure: true``, ``<render>.png``: those differences drawn,
:mod:`evcd.report.calm_figure`). ``rendered/reproduce.md`` stamps the whole with the
environment, code and machine of its jobs (:mod:`evcd.report.stamp`) and lists each sweep's launches
and each job's wall time (training, from ``results.json``; the whole job, from its log's first and
last lines).
"""

from __future__ import annotations

import math
import re
import shutil
from collections import defaultdict
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from evcd.loops.run_files import ENVIRONMENTS
from evcd.report.calm_figure import CalmRow, plot_against_calm
from evcd.report.compare import FLEET_MEASURES, Runs, compare_markdown
from evcd.report.fleet_table import make_fleet_table
from evcd.report.markdown import markdown_table, num
from evcd.report.paired import PairedStat
from evcd.report.reproduce.found import Found
from evcd.report.reproduce.launch import launches_span
from evcd.report.reproduce.spec import Page, PageError, PageJob, Render
from evcd.report.seed_stats import SeedStat, seed_interval
from evcd.report.stamp import job_stamp, stamp_markdown
from evcd.report.sweep import MULTIRUN_YAML
from evcd.report.table import make_table
from evcd.utils.atomic import atomic_write_text

COLLECTED = "collected"
SUMMARY = "reproduce.md"
_STAMP = re.compile(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),(\d{3})\]")
#: The first line a session of ``scripts/train.py`` logs (what it runs, ending ``seed <s> -> <run dir>``).
_HEADER = re.compile(r"\]\[train\]\[INFO\] - .*, seed \d+ -> \S")


# ---------------------------------------------------------------------------------------- views
def sweep_views(page: Page, found: Found, folder: Path, extra: Sequence[str] = ()) -> dict[str, Path]:
    """Per sweep, a folder that reads as that whole sweep (:mod:`evcd.report.sweep`): its overrides in
    ``multirun.yaml`` and a link to each finished job's run directory."""
    views = {}
    for sweep in page.sweeps:
        view = Path(folder) / sweep.name
        view.mkdir(parents=True)
        task = {"hydra": {"overrides": {"task": [*sweep.overrides, *extra]}}}
        atomic_write_text(view / MULTIRUN_YAML, yaml.safe_dump(task, sort_keys=False))
        for job_dir in found.of([sweep.name]).values():
            name = f"{job_dir.parent.name}.{job_dir.name}"
            k = 1
            while (view / name).exists():
                name, k = f"{job_dir.parent.name}.{job_dir.name}.{k}", k + 1
            (view / name).symlink_to(job_dir.resolve(), target_is_directory=True)
        views[sweep.name] = view
    return views


# ---------------------------------------------------------------------------------------- tables
def _runs(jobs: Mapping[PageJob, Path]) -> Runs:
    return Runs.read(list(jobs.values()))


def _interval(stat: SeedStat, signed: bool = False) -> str:
    f = "{:+.1f}" if signed else "{:.1f}"
    if stat.n < 2:
        return f.format(stat.mean)
    return f"{f.format(stat.mean)} [{f.format(stat.low)}, {f.format(stat.high)}]"


def _world_rows(runs: Runs, world: str | None) -> dict[str, tuple[str, str]]:
    """Dispatcher -> its row, in one world (``world``, or the only one)."""
    worlds = sorted({w for w, _ in runs.rows()} if world is None else {world})
    if len(worlds) != 1:
        raise PageError(f"seed_rows: the jobs play {len(worlds)} worlds ({', '.join(worlds)}): name one "
                        "(options: world)")  # fmt: skip
    return {a: (w, a) for w, a in runs.rows() if w == worlds[0]}


def seed_rows(jobs: Mapping[PageJob, Path], results: Mapping[PageJob, Mapping[str, Any]],
              options: Mapping[str, Any]) -> list[str]:  # fmt: skip
    """One row per dispatcher of the jobs (their agents and baseline rules, ``options['order']``
    first): its mean travel time per seed, the mean over seeds [95% t], and for learners the mean
    decisions (transitions) and wall seconds of their training."""
    runs = _runs(jobs)
    rows = _world_rows(runs, options.get("world"))
    order = [str(a) for a in options.get("order") or ()]
    unknown = [a for a in order if a not in rows]
    if unknown:
        raise PageError(
            f"seed_rows: no dispatcher {', '.join(unknown)} in the jobs; they have {', '.join(rows)}"
        )
    trained: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for data in results.values():
        t = data.get("training") or {}
        if t.get("transitions"):
            trained[str(data["agent"])].append((float(t["transitions"]), float(t.get("wall_s") or 0.0)))
    seeds = sorted({s for row in rows.values() for s in runs.travel[row]})
    table = []
    for agent in [*order, *sorted(a for a in rows if a not in order)]:
        means = {s: float(np.nanmean(list(t.values()))) for s, t in runs.travel[rows[agent]].items()}
        train = trained.get(agent, [])
        table.append([
            agent, *(num(means.get(s, math.nan)) for s in seeds), _interval(seed_interval(means.values())),
            f"{np.mean([d for d, _ in train]):,.0f}" if train else "",
            f"{np.mean([w for _, w in train]):.0f}" if train else "",
        ])  # fmt: skip
    header = ["dispatcher", *(f"seed {s}" for s in seeds), "mean over seeds [95% t]",
              "decisions in training (mean)", "training wall s (mean)"]  # fmt: skip
    return markdown_table(header, table)


def _row(runs: Runs, text: Any, what: str, kind: str = "paired_rows") -> tuple[str, str]:
    world, _, agent = str(text).rpartition("/")
    if (world, agent) not in runs.travel:
        known = "; ".join(f"{w}/{a}" for w, a in runs.rows())
        raise PageError(f"{kind}: {what}={text!r} is not a row of the jobs; the rows: {known}")
    return world, agent


def by_seed(runs: Runs, a: tuple[str, str], b: tuple[str, str]) -> SeedStat:
    """``a`` minus ``b``: the difference of each seed's mean over its episodes, over the seeds both have."""
    ta, tb = runs.travel[a], runs.travel[b]
    return seed_interval(float(np.nanmean(list(ta[s].values())) - np.nanmean(list(tb[s].values())))
                         for s in sorted(ta.keys() & tb.keys()))  # fmt: skip


def compare_rows(runs: Runs, worlds: Sequence[str], options: Mapping[str, Any]) -> list[str]:
    """``scripts/compare_runs.py``'s table of a ``compare`` render's runs (:func:`compared`): every
    (world, dispatcher) row, its difference with each ``options['references']`` row
    (``world/dispatcher``) paired by episode, and with ``options['against_calm']`` each perturbed row
    minus the same dispatcher calm; only the rows of ``worlds`` where it names some (the references and
    the calm rows may lie outside them)."""
    references = [_row(runs, r, "references", "compare") for r in options.get("references") or ()]
    return compare_markdown(runs, references, bool(options.get("against_calm")), worlds).splitlines()


def compared(jobs: Mapping[PageJob, Path], options: Mapping[str, Any]) -> tuple[Runs, list[str]]:
    """A ``compare`` render's runs, read once for its table and its figure (fleet runs on
    ``options['fleet_measure']``, default the guided EVs' travel time), and the worlds it shows
    (``options['worlds']``; ``[]``: all)."""
    measure = str(options.get("fleet_measure") or "guided_travel")
    if measure not in FLEET_MEASURES:
        raise PageError(f"compare: fleet_measure={measure!r}: choose one of {', '.join(FLEET_MEASURES)}")
    runs = Runs.read(list(jobs.values()), measure)
    worlds = [str(w) for w in options.get("worlds") or ()]
    if worlds:
        known = {w for w, _ in runs.rows()}
        unknown = [w for w in worlds if w not in known]
        if unknown:
            known_text = ", ".join(sorted(known))
            raise PageError(f"compare: worlds {unknown} not among the jobs' worlds: {known_text}")
    return runs, worlds


def calm_rows(runs: Runs, worlds: Sequence[str]) -> list[CalmRow]:
    """What a ``compare`` render's figure (``options['figure']``) draws: each row it shows minus the
    same dispatcher calm (:func:`evcd.report.calm_figure.plot_against_calm`), in the order of ``worlds``
    where it names them.

    Raises:
        PageError: no row it shows has a calm run of its dispatcher.
    """
    order = {w: i for i, w in enumerate(worlds)}
    rows = [(w, a, p) for w, a in runs.rows() if not worlds or w in order
            for p in [runs.against_calm((w, a))] if p is not None]  # fmt: skip
    rows.sort(key=lambda r: (order.get(r[0], 0), r[0]))
    if not rows:
        raise PageError("compare: figure: no row it shows is perturbed with a calm run of its dispatcher to "
                        "draw against")  # fmt: skip
    return rows


def paired_rows(jobs: Mapping[PageJob, Path], options: Mapping[str, Any]) -> list[str]:
    """The table ``options['header']``: one row per ``options['rows']`` entry, its ``cells`` then
    ``a`` minus ``b`` (``world/dispatcher`` rows), paired by episode within each seed (``by: episode``)
    or by the seeds' means (``by: seed``): mean over seeds [95% t] n=seeds."""
    runs = _runs(jobs)
    table = []
    for entry in options.get("rows") or ():
        a, b = _row(runs, entry.get("a"), "a"), _row(runs, entry.get("b"), "b")
        by = entry.get("by", "episode")
        if by == "seed":
            stat = by_seed(runs, a, b)
            cell = f"{_interval(stat, signed=True)} n={stat.n}, by seed"
        elif by == "episode":
            p: PairedStat | None = runs.paired(a, b)
            cell = "—" if p is None else f"{_interval(p.stat, signed=True)} n={p.stat.n}"
        else:
            raise PageError(f"paired_rows: by={by!r}: choose episode or seed")
        table.append([*map(str, entry.get("cells") or ()), cell])
    return markdown_table([str(h) for h in options.get("header") or ()], table)


# ---------------------------------------------------------------------------------------- timing
def _sessions(job_dir: Path) -> list[list[datetime]]:
    """The stamps of a job's log lines (Hydra's, ``[%Y-%m-%d %H:%M:%S,ms]``), per session: a job
    continued from its checkpoint holds each session's lines, each session begun by the script's
    header (``... seed <s> -> <run directory>``)."""
    sessions: list[list[datetime]] = []
    for path in sorted(Path(job_dir).glob("*.log")):
        for line in path.read_text(errors="replace").splitlines():
            m = _STAMP.match(line)
            if not m:
                continue
            if not sessions or (_HEADER.search(line) and sessions[-1]):
                sessions.append([])
            sessions[-1].append(datetime.strptime(f"{m.group(1)}.{m.group(2)}", "%Y-%m-%d %H:%M:%S.%f"))
    return [s for s in sessions if s]


def log_span(job_dir: Path) -> tuple[datetime, datetime] | None:
    """When a job's logs begin and end, or ``None``."""
    stamps = [t for session in _sessions(job_dir) for t in session]
    return (min(stamps), max(stamps)) if stamps else None


def log_wall(job_dir: Path) -> float | None:
    """A job's wall time from its log: each session's first to last line, summed (the time between
    the sessions of a job continued from its checkpoint left out), or ``None``."""
    sessions = _sessions(job_dir)
    return sum((max(s) - min(s)).total_seconds() for s in sessions) if sessions else None


def _varying(jobs: Sequence[PageJob]) -> dict[PageJob, str]:
    """Each job by the overrides that vary within its sweep."""
    common = set.intersection(*(set(j.overrides) for j in jobs)) if jobs else set()
    return {j: " ".join(o for o in j.overrides if o not in common) or "(the only job)" for j in jobs}


def summary_markdown(page: Page, found: Found, manifest: Mapping[str, Any] | None) -> str:
    """The rendering's summary: what made it (stamp), each sweep's launches and wall time, each job's."""
    lines = [f"# Reproduction of page `{page.name}`: {page.title}", "",
             f"{len(found.finished)} jobs in {len(page.sweeps)} sweeps (definition `{page.path}`), rendered "
             f"{datetime.now().isoformat(timespec='seconds')}.", ""]  # fmt: skip
    for task in sorted({j.sweep.task for j in found.finished}):
        stamps = [job_stamp(found.results[j]) for j in found.finished if j.sweep.task == task]
        lines += [f"{task} task:", "", *stamp_markdown(stamps, ENVIRONMENTS[task]), ""]
    launches = (manifest or {}).get("launches") or []
    rows = []
    spans = {j: log_span(d) for j, d in found.finished.items()}
    for sweep in page.sweeps:
        mine = [launch for launch in launches if launch.get("sweep") == sweep.name]
        jobs = [s for j, s in spans.items() if j.sweep == sweep and s is not None]
        span = (max(e for _, e in jobs) - min(b for b, _ in jobs)).total_seconds() if jobs else math.nan
        wall = num(launches_span(mine), 0) if mine else "—"
        count = sum(j.sweep == sweep for j in found.finished)
        rows.append([sweep.name, sweep.script, str(count), str(len(mine)), wall, num(span, 0)])
    header = ["sweep", "script", "jobs", "launches", "launches' wall s", "jobs' span s"]
    page_wall = f" The page: {num(launches_span(launches), 0)} s." if launches else ""
    lines += ["## Sweeps", "", "Wall time of this command's launches (`reproduce.json`; launches that "
              "overlapped counted once), and from the first job's first log line to the last job's last."
              + page_wall, "", *markdown_table(header, rows), "",
              *(f"- `{launch['command']}`: {launch['wall_s']} s, exit code {launch['returncode']}"
                for launch in launches), ""]  # fmt: skip
    rows = []
    for sweep in page.sweeps:
        jobs = [j for j in found.finished if j.sweep == sweep]
        for job, label in _varying(jobs).items():
            training = found.results[job].get("training") or {}
            wall = log_wall(found.finished[job])
            rows.append([sweep.name, label, num(float(training.get("wall_s") or 0.0), 0),
                         num(wall, 0) if wall is not None else "—", str(found.finished[job])])  # fmt: skip
    header = ["sweep", "job", "training wall s", "job wall s", "run directory"]
    lines += ["## Jobs", "", "Training wall time (`results.json`: day builds and validation apart) and the "
              "job's wall time (its log's first to last line; a job continued from its checkpoint: each "
              "session's, summed).", "",
              *markdown_table(header, rows)]  # fmt: skip
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------- the page
def render_one(render: Render, views: Mapping[str, Path], found: Found, folder: Path) -> list[Path]:
    """Write one render's files into ``folder`` (which must not exist); return them."""
    dirs = [views[s] for s in render.sweeps]
    if render.kind == "table":
        resamples = int(render.options.get("resamples", 10_000))
        return list(make_table(dirs, folder, resamples=resamples).paths)
    if render.kind == "fleet_table":
        return list(make_fleet_table(dirs, folder).paths)
    jobs = found.of(render.sweeps)
    figure: list[CalmRow] = []
    if render.kind == "seed_rows":
        results = {j: found.results[j] for j in jobs}
        table = seed_rows(jobs, results, render.options)
    elif render.kind == "compare":
        runs, worlds = compared(jobs, render.options)
        table = compare_rows(runs, worlds, render.options)
        if render.options.get("figure"):  # before anything is written
            figure = calm_rows(runs, worlds)
    else:
        table = paired_rows(jobs, render.options)
    title = str(render.options.get("title") or render.name)
    lines = [f"# {title}", "", *table]
    for task in sorted({j.sweep.task for j in jobs}):
        stamps = [job_stamp(found.results[j]) for j in jobs if j.sweep.task == task]
        lines += ["", *stamp_markdown(stamps, ENVIRONMENTS[task])]
    text = "\n".join(lines) + "\n"
    folder.mkdir(parents=True)
    written = [atomic_write_text(folder / str(render.options.get("file") or f"{render.name}.md"), text)]
    if figure:
        written.append(plot_against_calm(figure, folder / f"{render.name}.png"))
    return written


def render_page(
    page: Page,
    found: Found,
    folder: Path,
    manifest: Mapping[str, Any] | None = None,
    extra: Sequence[str] = (),
) -> Path:
    """Render every render of ``page`` from ``found`` (complete) into ``folder`` (which must not exist:
    nothing is overwritten), with the summary :data:`SUMMARY`; return ``folder``.

    Raises:
        FileExistsError: ``folder`` exists.
        PageError, ResultsError: a render's definition does not fit the jobs (``folder`` is removed).
    """
    folder = Path(folder)
    if folder.exists():
        raise FileExistsError(f"{folder} exists: nothing there is overwritten (give a new --out)")
    try:
        views = sweep_views(page, found, folder / COLLECTED, extra)
        for render in page.renders:
            render_one(render, views, found, folder / render.name)
        atomic_write_text(folder / SUMMARY, summary_markdown(page, found, manifest))
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)  # a rendering is whole or absent
        raise
    return folder
