"""Run a page's sweeps into an output folder, each a Hydra multirun of its script in a subprocess, timed.

    manifest = open_output(page, out, extra)          # a new folder, or the resumable one of this page
    run_sweeps(page, out, manifest, extra, hydra, scripts_dir)

The subprocess is the script as a user runs it (``python scripts/train.py -m ...``), so Hydra's
overrides pass through: ``hydra/launcher=joblib hydra.launcher.n_jobs=2`` runs two jobs at once, and
``hydra/launcher=evcd_slurm`` submits the same jobs to a SLURM cluster (:func:`check_launcher` names
the extra a missing plugin needs before anything starts). Each sweep goes to ``<out>/sweeps/<name>``,
its output to ``<out>/logs/<name>.log``; ``<out>/reproduce.json`` records the page, the overrides and
every launch with its command, wall time and exit code; the log names each job as it finishes, with
the time the multirun's other jobs take at its pace so far. Run again with the same ``--out``, a page
runs only the jobs that have not finished (into ``<name>-resume<k>``; nothing already written is
touched); a training job stopped after a checkpoint continues from it (``resume=true``) in a copy of
its run directory, so a page stopped every few hours loses at most a checkpoint interval per job.

Launches overlap where a slot would idle: with ``hydra.launcher.n_jobs=N`` (:func:`parallel_jobs`) the
next multirun starts as soon as the running ones hold fewer unfinished jobs than ``N`` (the last jobs
of a sweep, or a resumed page's small groups, would otherwise leave cores idle until they end). It
starts with its own ``N`` workers, so until the earlier one's last jobs end up to ``2N - 1`` jobs share
the ``N`` cores. Jobs share only the day cache, which takes concurrent builders, and a job's episodes
depend only on its seed: the order changes no job's numbers.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import logging
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from evcd.loops.run_files import CHECKPOINTS, RESULTS_JSON
from evcd.report.reproduce.found import RunDir, job_groups, read_run_dir, run_dirs
from evcd.report.reproduce.spec import Page, PageError, PageJob, Sweep, display, job_key
from evcd.utils.atomic import atomic_write_text
from evcd.utils.checkpoint import POINTER

log = logging.getLogger(__name__)

MANIFEST = "reproduce.json"
SWEEPS = "sweeps"
LOGS = "logs"
#: The scripts whose runs continue from their last checkpoint with ``resume=true``.
RESUMABLE_SCRIPTS = frozenset({"train.py"})
#: Launcher option -> (the Hydra plugin it needs, the evcd extra that installs it; "" = installed with evcd).
LAUNCHER_PLUGINS: dict[str, tuple[str, str]] = {
    "joblib": ("hydra_plugins.hydra_joblib_launcher", ""),
    "evcd_slurm": ("hydra_plugins.hydra_submitit_launcher", "slurm"),
    "submitit_slurm": ("hydra_plugins.hydra_submitit_launcher", "slurm"),
    "submitit_local": ("hydra_plugins.hydra_submitit_launcher", "slurm"),
    "evcd_ray": ("hydra_plugins.hydra_ray_launcher", "ray"),
    "ray": ("hydra_plugins.hydra_ray_launcher", "ray"),
    "ray_aws": ("hydra_plugins.hydra_ray_launcher", "ray"),
}


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:  # a parent package is missing
        return False


def check_launcher(hydra: Sequence[str], installed: Callable[[str], bool] = _installed) -> None:
    """Refuse a ``hydra/launcher=`` whose plugin is not installed, naming the extra that installs it.

    Raises:
        PageError: the plugin of the chosen launcher cannot be imported.
    """
    for override in hydra:
        key, _, name = override.lstrip("+").partition("=")
        if key != "hydra/launcher" or name not in LAUNCHER_PLUGINS:
            continue
        module, extra = LAUNCHER_PLUGINS[name]
        if not installed(module):
            how = f'pip install -e ".[{extra}]"' if extra else "pip install -e ."
            raise PageError(f"hydra/launcher={name} needs the Hydra launcher plugin {module}, which is not "
                            f"installed: {how}")  # fmt: skip


# ---------------------------------------------------------------------------------------- the folder
def _definition(page: Page) -> list[dict[str, Any]]:
    return [{"name": s.name, "script": s.script, "overrides": list(s.overrides)} for s in page.sweeps]


def open_output(page: Page, out: Path, extra: Sequence[str]) -> dict[str, Any]:
    """The manifest of ``out``: a new one (``out`` does not exist: it is made), or the one of an earlier
    run of the same page, sweeps and overrides (to resume).

    Raises:
        PageError: ``out`` exists and is not such a folder (nothing in it is touched).
    """
    path = Path(out) / MANIFEST
    if Path(out).exists():
        try:
            manifest = json.loads(path.read_text())
        except (OSError, ValueError):
            raise PageError(f"{out} exists and is not a reproduction's folder (no readable {MANIFEST}): "
                            "nothing there is overwritten; choose a new --out") from None  # fmt: skip
        same = (manifest.get("page"), manifest.get("sweeps"), manifest.get("overrides")) == (
            page.name,
            _definition(page),
            list(extra),
        )
        if not same:
            before = " ".join(manifest.get("overrides") or []) or "none"
            raise PageError(f"{out} holds a reproduction of page {manifest.get('page')!r} with other "
                            f"sweeps or overrides ({before}): nothing there is overwritten; choose a new "
                            "--out")  # fmt: skip
        log.info("%s: resuming the reproduction of page %s", out, page.name)
        return manifest
    Path(out).mkdir(parents=True)
    manifest = {"page": page.name, "definition": str(page.path), "sweeps": _definition(page),
                "overrides": list(extra), "launches": []}  # fmt: skip
    atomic_write_text(path, json.dumps(manifest, indent=1) + "\n")
    return manifest


def read_runs(folder: Path) -> list[RunDir]:
    """Every run directory under ``folder`` (none if it does not exist), read."""
    return [read_run_dir(d) for d in run_dirs(folder)] if Path(folder).is_dir() else []


def finished_keys(runs: Sequence[RunDir]) -> set[frozenset[tuple[str, str]]]:
    """The job keys of the finished ones of ``runs``."""
    return {job_key(r.overrides) for r in runs if r.results is not None}


def interrupted_runs(runs: Sequence[RunDir]) -> dict[frozenset[tuple[str, str]], Path]:
    """Per job key, the run directory among ``runs`` of a job that was stopped after a checkpoint (no
    ``results.json``, a checkpoint pointer): the latest checkpoint where several were."""
    found: dict[frozenset[tuple[str, str]], Path] = {}
    for run in runs:
        pointer = run.path / CHECKPOINTS / POINTER
        if run.results is not None or not pointer.is_file():
            continue
        key = job_key(run.overrides)
        if key not in found or pointer.stat().st_mtime > (found[key] / CHECKPOINTS / POINTER).stat().st_mtime:
            found[key] = run.path
    return found


def _free_dir(root: Path, name: str) -> Path:
    """``root/name``, or its first free ``-resume<k>``; made here, so that a launch started next finds it
    taken before Hydra writes into it."""
    path, k = root / name, 0
    while path.exists():
        k += 1
        path = root / f"{name}-resume{k}"
    path.mkdir(parents=True)
    return path


@dataclass(frozen=True)
class Planned:
    """A multirun :func:`run_sweeps` launches.

    Attributes:
        sweep: the page's sweep.
        overrides: the script's arguments after ``-m`` but Hydra's and the sweep folder.
        jobs: its jobs.
        resume: the run directory of a job stopped after a checkpoint, which this one-job multirun
            continues (``resume=true``) in a copy of it (``None``: new jobs).
    """

    sweep: Sweep
    overrides: tuple[str, ...]
    jobs: int
    resume: Path | None = None


def planned_launches(page: Page, out: Path, extra: Sequence[str]) -> list[Planned]:
    """What :func:`run_sweeps` would launch now: the whole sweep as the page writes it where none of its
    jobs has started; else first each job of ``train.py`` stopped after a checkpoint, continued from it
    (:func:`interrupted_runs`), then multiruns of the jobs left
    (:func:`evcd.report.reproduce.found.job_groups`)."""
    runs = read_runs(Path(out) / SWEEPS)
    done, stopped = finished_keys(runs), interrupted_runs(runs)
    plan: list[Planned] = []
    for sweep in page.sweeps:
        jobs = [PageJob(sweep, combo) for combo in sweep.jobs(extra)]
        left = [j for j in jobs if j.key not in done]
        resumed = [j for j in left if j.key in stopped and sweep.script in RESUMABLE_SCRIPTS]
        if len(left) == len(jobs) and not resumed:
            plan.append(Planned(sweep, (*sweep.overrides, *extra), len(jobs)))
            continue
        plan += [Planned(sweep, (*j.overrides, "resume=true"), 1, stopped[j.key]) for j in resumed]
        rest = [j for j in left if j not in resumed]
        plan += [Planned(sweep, tuple(overrides), n) for _, overrides, n in job_groups(rest)]
    return plan


def parallel_jobs(hydra: Sequence[str]) -> int:
    """The jobs a launcher runs at once, from Hydra's overrides: ``hydra.launcher.n_jobs`` (``-1``: every
    core of this machine); 1 without it.

    Raises:
        PageError: ``n_jobs`` is neither a whole number >= 1 nor -1.
    """
    value = 1
    for o in hydra:
        key, _, text = o.partition("=")
        if key.lstrip("+~") == "hydra.launcher.n_jobs":
            try:
                value = int(text)
            except ValueError:
                value = 0
            if value == -1:
                value = os.cpu_count() or 1
            if value < 1:
                raise PageError(
                    f"hydra.launcher.n_jobs={text!r}: give a whole number >= 1 (or -1: every core)"
                )
    return value


def launches_span(launches: Sequence[Mapping[str, Any]]) -> float:
    """Seconds during which at least one of ``launches`` ran (from ``reproduce.json``: ``started`` and
    ``wall_s``): their wall time together, overlapping launches counted once."""
    spans = sorted((datetime.fromisoformat(x["started"]).timestamp(), float(x["wall_s"])) for x in launches)
    total, end = 0.0, -math.inf
    for start, wall in spans:
        total += max(0.0, start + wall - max(start, end))
        end = max(end, start + wall)
    return total


class FinishedJobs:
    """Called while a multirun runs: logs each of its jobs as its ``results.json`` appears, with how
    many are left and, at the pace so far, about how long they take (a page runs for hours).

    Args:
        sweep_dir: the multirun's folder.
        label: how the log names the multirun (``sweep 1/3 table``).
        total: its jobs.
    """

    def __init__(self, sweep_dir: Path, label: str, total: int) -> None:
        self.sweep_dir, self.label, self.total = Path(sweep_dir), label, total
        self.started = time.monotonic()
        self.seen: set[str] = set()

    @property
    def unfinished(self) -> int:
        """The multirun's jobs whose ``results.json`` has not appeared yet (as of the last call)."""
        return max(self.total - len(self.seen), 0)

    def __call__(self) -> None:
        """Log the jobs that finished since the last call."""
        for path in sorted(self.sweep_dir.glob(f"*/{RESULTS_JSON}"), key=lambda p: p.stat().st_mtime):
            if path.parent.name in self.seen:
                continue
            self.seen.add(path.parent.name)
            done, elapsed = len(self.seen), time.monotonic() - self.started
            left = max(self.total - done, 0)
            pace = f"; about {_duration(elapsed / done * left)} left at this pace" if left else ""
            log.info("%s: %d of %d jobs finished (%s) after %s%s", self.label, done, self.total,
                     path.parent.name, _duration(elapsed), pace)  # fmt: skip


def _duration(seconds: float) -> str:
    """``42 s``, ``17 min`` or ``3.2 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 5400 else f"{seconds / 3600:.1f} h"


def continue_in(run_dir: Path, sweep_dir: Path) -> str:
    """Copy the stopped run directory ``run_dir`` into ``sweep_dir`` (under a hidden name, then renamed:
    a copy cut short is never taken for a run) and return the copy's name, the ``hydra.sweep.subdir``
    of the multirun that continues it: the stopped run stays as it was."""
    partial = sweep_dir / f".{run_dir.name}.partial"
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(run_dir, partial, symlinks=True)
    partial.rename(sweep_dir / run_dir.name)
    return run_dir.name


class Launch:
    """One multirun of a page, running in a process group of its own, its output to ``<out>/logs``.

    Args:
        label: how the log names it (``sweep 1/3 table``).
        sweep: the page's sweep.
        argv: the script's arguments (``-m``, the overrides, Hydra's, the sweep folder).
        sweep_dir: the multirun's folder.
        jobs: its jobs.
        logfile: where its output goes.
        scripts_dir: the folder of the script; the multirun runs in the folder above it.
        python: the interpreter.
    """

    def __init__(
        self,
        label: str,
        sweep: Sweep,
        argv: Sequence[str],
        sweep_dir: Path,
        jobs: int,
        logfile: Path,
        scripts_dir: Path,
        python: str,
    ) -> None:
        self.label, self.sweep, self.argv = label, sweep, list(argv)
        self.sweep_dir, self.jobs = sweep_dir, jobs
        self.started = datetime.now().isoformat(timespec="seconds")
        self.t0 = time.perf_counter()
        self.watch = FinishedJobs(sweep_dir, label, jobs)
        self._output = open(logfile, "a")  # noqa: SIM115 (closed when the launch ends)
        cmd = [python, str(Path(scripts_dir) / sweep.script), *self.argv]
        self.process = subprocess.Popen(
            cmd,
            stdout=self._output,
            stderr=subprocess.STDOUT,
            cwd=Path(scripts_dir).parent,
            start_new_session=True,
        )

    def poll(self) -> int | None:
        """Log its newly finished jobs; its exit code once it has ended (``None`` while it runs)."""
        code = self.process.poll()
        self.watch()  # after the poll: a multirun that ended has written every job it finished
        if code is not None:
            self._output.close()
        return code

    def record(self, code: int) -> dict[str, Any]:
        """What ``reproduce.json`` keeps of it, once it has ended with ``code``."""
        return {"sweep": self.sweep.name, "dir": str(self.sweep_dir),
                "command": display(self.sweep.script, self.argv), "jobs": self.jobs, "started": self.started,
                "wall_s": round(time.perf_counter() - self.t0, 1), "returncode": code}  # fmt: skip

    def stop(self, grace_s: float) -> None:
        """End it with every process it started (:func:`stop_group`)."""
        log.warning("stopped: ending the sweep running (process group %d) and every process it started; "
                    "the same command resumes it", self.process.pid)  # fmt: skip
        stop_group(self.process, grace_s)
        self._output.close()


def stop_group(process: subprocess.Popen[Any], grace_s: float) -> None:
    """Send SIGTERM to the process group ``process`` leads, SIGKILL to what is left of it after
    ``grace_s`` (``process`` itself reaped)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline:
            process.poll()
            os.killpg(process.pid, 0)  # ProcessLookupError once the whole group has gone
            time.sleep(0.1)
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


def run_sweeps(
    page: Page,
    out: Path,
    manifest: dict[str, Any],
    extra: Sequence[str],
    hydra: Sequence[str],
    scripts_dir: Path,
    python: str = sys.executable,
    every_s: float = 2.0,
    grace_s: float = 10.0,
) -> list[Mapping[str, Any]]:
    """Launch every sweep of ``page`` that has jobs left into ``out/sweeps``, the next as soon as the
    running ones leave a slot of :func:`parallel_jobs` idle (one after another without ``n_jobs``);
    record each launch (command, wall time, exit code) in ``out/reproduce.json`` as it ends; return
    this call's launches. A sweep whose multirun fails (a job failed) does not stop the others.

    If this process is stopped meanwhile (an exception here, such as ``KeyboardInterrupt`` or the
    ``SystemExit`` of a SIGTERM handler), every running multirun goes with it: its launcher's workers,
    the jobs' day builds and second processes, none left playing on into the run's folder (SIGTERM,
    then SIGKILL after ``grace_s``); each is recorded as ``stopped``, with its wall time. ``every_s``:
    how often the running multiruns are looked at."""
    out = Path(out)
    plan = planned_launches(page, out, extra)
    if not plan:
        log.info("page %s: every job has finished in %s", page.name, out / SWEEPS)
    slots = parallel_jobs(hydra)
    (out / LOGS).mkdir(parents=True, exist_ok=True)
    waiting = list(enumerate(plan, 1))
    running: list[Launch] = []
    launches: list[Mapping[str, Any]] = []
    try:
        while waiting or running:
            while waiting and (not running or sum(x.watch.unfinished for x in running) < slots):
                i, planned = waiting.pop(0)
                sweep = planned.sweep
                sweep_dir = _free_dir(out / SWEEPS, sweep.name)
                logfile = out / LOGS / f"{sweep_dir.name}.log"
                argv = ["-m", *planned.overrides, *hydra, f"hydra.sweep.dir={sweep_dir}"]
                what = f"{planned.jobs} job(s)"
                if planned.resume is not None:
                    argv.append(f"hydra.sweep.subdir='{continue_in(planned.resume, sweep_dir)}'")
                    what = f"continues {planned.resume} from its last checkpoint, in a copy"
                beside = f", beside {', '.join(x.label for x in running)}" if running else ""
                log.info("sweep %d/%d %s: %s -> %s (output: %s)%s", i, len(plan), sweep.name, what, sweep_dir,
                         logfile, beside)  # fmt: skip
                label = f"sweep {i}/{len(plan)} {sweep.name}"
                running.append(
                    Launch(label, sweep, argv, sweep_dir, planned.jobs, logfile, scripts_dir, python)
                )
            deadline = time.monotonic() + every_s
            while time.monotonic() < deadline and all(x.process.poll() is None for x in running):
                time.sleep(0.2)
            for launch in list(running):
                code = launch.poll()
                if code is None:
                    continue
                running.remove(launch)
                record = launch.record(code)
                manifest["launches"].append(record)
                atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")
                launches.append(record)
                if code == 0:
                    log.info("%s: done in %.0f s", launch.label, record["wall_s"])
                else:
                    log.warning("%s: exit code %d after %.0f s (a job failed?): see %s", launch.label, code,
                                record["wall_s"], out / LOGS / f"{launch.sweep_dir.name}.log")  # fmt: skip
    except BaseException:
        for launch in running:
            launch.stop(grace_s)
            # a stopped launch counts in the page's wall time too (records carried to another machine)
            record = {**launch.record(launch.process.returncode), "stopped": True}
            manifest["launches"].append(record)
            launches.append(record)
        if running:
            atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")
        raise
    return launches
