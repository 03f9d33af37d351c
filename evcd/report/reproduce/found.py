"""A page's jobs in run directories: which finished, which are missing or failed, and which run
directories belong to another task or experiment.

    found = find_jobs(page, [Path("outputs/table/evs400"), Path("outputs/table/evs300")])
    found.require_complete(["python scripts/reproduce.py results --out ..."])   # IncompleteJobsError

Every run directory under the given folders (a multirun, a run, or a folder holding them at any
depth: a directory with ``.hydra/overrides.yaml``) is matched to a job of the page by its recorded
overrides (:func:`evcd.report.reproduce.spec.job_key`), so a page's jobs may come from several sweeps
(a sweep split by EV count, a resumed one). A finished run of another task than the page's, or of
another regime (experiment), is refused (:class:`ForeignRunError`), as make_table refuses a fleet
run in the single target's table; other run directories are left out with a warning.
"""

from __future__ import annotations

import json
import logging
import os
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from evcd.loops.run_files import RESULTS_JSON
from evcd.report.reproduce.spec import Page, PageError, PageJob, Sweep, display, job_key
from evcd.report.sweep import OVERRIDES_YAML, JobGap, job_overrides, read_job

log = logging.getLogger(__name__)

TASK_WORDS = {"single": "single-target", "fleet": "fleet"}


def task_text(task: str) -> str:
    """A task as a reader names it, with its setting: ``single-target (task=single)``."""
    return f"{TASK_WORDS.get(task, task)} (task={task})"


class ForeignRunError(PageError):
    """A run directory of another task or experiment than the page's."""


class IncompleteJobsError(PageError):
    """Jobs of the page did not finish; :attr:`gaps` names them (the message also says how to complete
    them)."""

    def __init__(self, page: Page, gaps: Sequence[tuple[PageJob, JobGap]], total: int, how: Sequence[str]):
        self.gaps = tuple(gaps)
        lines = [f"  {g.status}: {job.sweep.name}: {g.describe().split(': ', 1)[1]}" for job, g in self.gaps]
        super().__init__("\n".join([
            f"page {page.name}: {len(self.gaps)} of {total} jobs did not finish (missing or failed):",
            *lines, "complete them with:", *(f"  {c}" for c in how),
        ]))  # fmt: skip


@dataclass(frozen=True)
class RunDir:
    """A run directory: its recorded overrides and its parsed ``results.json`` (``None``: none, or
    unreadable)."""

    path: Path
    overrides: tuple[str, ...]
    results: Mapping[str, Any] | None

    @property
    def task(self) -> str:
        """The task its results record."""
        return str((self.results or {}).get("task", "single"))

    @property
    def regime(self) -> str:
        """The regime (experiment) its config records."""
        config = (self.results or {}).get("config") or {}
        return str(config.get("regime", "unknown")) if isinstance(config, Mapping) else "unknown"


@dataclass(frozen=True)
class Found:
    """The jobs of a page found in some folders.

    Attributes:
        finished: each finished job's run directory (results.json readable), in the page's order.
        gaps: each job that did not finish: ``missing`` (no run directory) or ``failed`` (its run
            directory has no readable results.json; the last error of its log named).
        total: the page's jobs.
        results: each finished job's parsed results.json.
    """

    page: Page
    finished: Mapping[PageJob, Path]
    gaps: tuple[tuple[PageJob, JobGap], ...]
    total: int
    results: Mapping[PageJob, Mapping[str, Any]]

    def require_complete(self, how: Sequence[str]) -> None:
        """Raise :class:`IncompleteJobsError` (with the commands ``how``) unless every job finished."""
        if self.gaps:
            raise IncompleteJobsError(self.page, self.gaps, self.total, how)

    def of(self, sweeps: Sequence[str]) -> dict[PageJob, Path]:
        """The finished jobs of the named sweeps."""
        return {job: d for job, d in self.finished.items() if job.sweep.name in sweeps}


def run_dirs(folder: Path) -> list[Path]:
    """Every run directory at or under ``folder`` (holding ``.hydra/overrides.yaml``; links followed,
    so a rendering's ``collected/`` views count), sorted, each once."""
    found: dict[str, Path] = {}
    for here, subdirs, _ in os.walk(folder, followlinks=True):
        if (Path(here) / OVERRIDES_YAML).is_file():
            found.setdefault(os.path.realpath(here), Path(here))
            subdirs[:] = []  # a run directory holds no other
        else:
            subdirs[:] = [d for d in subdirs if not d.startswith(".")]
    return sorted(found.values())


def read_run_dir(path: Path) -> RunDir:
    """The overrides and results of the run directory ``path``."""
    results = None
    if (path / RESULTS_JSON).is_file():
        try:
            results = json.loads((path / RESULTS_JSON).read_text())
        except (OSError, ValueError):
            results = None
    return RunDir(path, job_overrides(path), results if isinstance(results, Mapping) else None)


def _foreign(run: RunDir, page: Page, sweeps: Sequence[Sweep]) -> str | None:
    """Why a finished run directory is not of ``sweeps`` (another task or regime), or ``None``."""
    tasks, regimes = {s.task for s in sweeps}, {s.regime for s in sweeps}
    if run.task not in tasks:
        words = " or ".join(sorted(task_text(t) for t in tasks))
        what = TASK_WORDS.get(run.task, run.task)
        return (f"{run.path} is a {what} run (task={run.task}); the jobs of page {page.name} here are "
                f"{words}: give the run directories of the page's own jobs")  # fmt: skip
    if run.regime not in regimes:
        return (f"{run.path} is a run of regime {run.regime!r} (experiment={run.regime}); the jobs of page "
                f"{page.name} here are of regime {' or '.join(map(repr, sorted(regimes)))}")  # fmt: skip
    return None


def find_jobs(page: Page, folders: Sequence[Path], extra: Sequence[str] = ()) -> Found:
    """Match the run directories under ``folders`` to the jobs of ``page`` (``extra``: the overrides
    every job took).

    Raises:
        ForeignRunError: a finished run directory of another task or regime than its job's or the page's.
        PageError: a folder holds no run directory, or none of the page's jobs; two finished run
            directories stand for the same job.
    """
    jobs = page.jobs(extra)
    by_key = {job.key: job for job in jobs}
    candidates: dict[PageJob, list[RunDir]] = defaultdict(list)
    seen: set[Path] = set()
    for folder in map(Path, folders):  # every folder first: a mistyped one is named before any match
        if not folder.exists():
            override = " (an override? overrides go before --check)" if "=" in folder.name else ""
            raise PageError(f"{folder} does not exist{override}: give the multirun or run directories of "
                            "the page's jobs")  # fmt: skip
    for folder in map(Path, folders):
        every = run_dirs(folder)
        runs = [r for r in every if r.resolve() not in seen]
        if not every:
            raise PageError(f"{folder} holds no run directory (no .hydra/overrides.yaml): give the multirun "
                            "or run directories of the page's jobs")  # fmt: skip
        matched = 0
        for path in runs:
            seen.add(path.resolve())
            run = read_run_dir(path)
            job = by_key.get(job_key(run.overrides))
            if run.results is not None:
                why = _foreign(run, page, [job.sweep] if job is not None else page.sweeps)
                if why:
                    raise ForeignRunError(why)
            if job is None:
                log.warning("%s: not a job of page %s (its overrides: %s); left out", path, page.name,
                            " ".join(run.overrides))  # fmt: skip
                continue
            candidates[job].append(run)
            matched += 1
        if runs and not matched:
            raise PageError(f"{folder} holds no job of page {page.name} (its {len(runs)} run directories "
                            "have other overrides; the page's jobs: python scripts/reproduce.py "
                            f"{page.name} --dry-run)")  # fmt: skip
    finished: dict[PageJob, Path] = {}
    results: dict[PageJob, Mapping[str, Any]] = {}
    gaps: list[tuple[PageJob, JobGap]] = []
    for job in jobs:
        runs = candidates.get(job, [])
        done = [r for r in runs if r.results is not None]
        if len(done) > 1:
            raise PageError(f"job {job.describe()} finished in {len(done)} run directories ("
                            f"{', '.join(str(r.path) for r in done)}): pass one of them")  # fmt: skip
        if done:
            finished[job], results[job] = done[0].path, done[0].results  # type: ignore[assignment]
        elif runs:
            gap = read_job(runs[-1].path, job.overrides, parse=lambda data, _: data)
            gaps.append(
                (job, gap if isinstance(gap, JobGap) else JobGap("failed", job.overrides, runs[-1].path))
            )
        else:
            gaps.append((job, JobGap("missing", job.overrides, None)))
    return Found(page, finished, tuple(gaps), len(jobs), results)


def _products(combos: Sequence[tuple[str, ...]]) -> list[list[list[str]]]:
    """Split ``combos`` (each a tuple of values, one per axis, all the same length) into products of
    values, each given as the values of every axis: along the first axis, the values whose jobs on the
    other axes are the same share one product, and those jobs split the same way in turn."""
    if not combos or not combos[0]:
        return [[]] if combos else []
    rests: dict[str, list[tuple[str, ...]]] = {}
    for combo in combos:
        rests.setdefault(combo[0], []).append(combo[1:])
    shared: dict[frozenset[tuple[str, ...]], list[str]] = {}
    for value, rest in rests.items():
        shared.setdefault(frozenset(rest), []).append(value)
    out: list[list[list[str]]] = []
    for values in shared.values():
        out += [[values, *part] for part in _products(rests[values[0]])]
    return out


def job_groups(jobs: Sequence[PageJob]) -> list[tuple[Sweep, tuple[str, ...], int]]:
    """Multiruns that run exactly ``jobs``, as (sweep, overrides, jobs): per sweep, products of values
    found axis by axis (``agent=dqn,greedy seed=3``: the jobs left of a sweep stopped after its first
    few make a few multiruns, not one per job), each job in exactly one, in the sweep's order; a job
    whose overrides name other axes runs alone."""
    by_sweep: dict[str, list[PageJob]] = defaultdict(list)
    for job in jobs:
        by_sweep[job.sweep.name].append(job)
    out: list[tuple[Sweep, tuple[str, ...], int]] = []
    for group in by_sweep.values():
        sweep = group[0].sweep
        keys = [o.partition("=")[0] for o in group[0].overrides]
        alike = [j for j in group if [o.partition("=")[0] for o in j.overrides] == keys]
        combos = [tuple(o.partition("=")[2] for o in j.overrides) for j in alike]
        for values in _products(combos):
            n = 1
            for axis in values:
                n *= len(axis)
            out.append((sweep, tuple(f"{k}={','.join(v)}" for k, v in zip(keys, values, strict=True)), n))
        out += [(sweep, job.overrides, 1) for job in group if job not in alike]
    return out


def completion_commands(jobs: Sequence[PageJob], hydra: Sequence[str], new_dir: Path) -> list[str]:
    """The multiruns that run ``jobs`` (:func:`job_groups`) into new sweep folders under ``new_dir``."""
    commands = []
    for i, (sweep, overrides, _) in enumerate(job_groups(jobs)):
        argv = ["-m", *overrides, *hydra, f"hydra.sweep.dir={Path(new_dir) / f'{sweep.name}-{i}'}"]
        commands.append(display(sweep.script, argv))
    return commands
