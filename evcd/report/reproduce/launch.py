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
touched).
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import IO, Any

from evcd.loops.run_files import RESULTS_JSON
from evcd.report.reproduce.found import job_groups, read_run_dir, run_dirs
from evcd.report.reproduce.spec import Page, PageError, PageJob, Sweep, display, job_key
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger(__name__)

MANIFEST = "reproduce.json"
SWEEPS = "sweeps"
LOGS = "logs"
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


def finished_keys(folder: Path) -> set[frozenset[tuple[str, str]]]:
    """The job keys of the finished run directories under ``folder``."""
    if not Path(folder).is_dir():
        return set()
    return {job_key(r.overrides) for r in map(read_run_dir, run_dirs(folder)) if r.results is not None}


def _free_dir(root: Path, name: str) -> Path:
    if not (root / name).exists():
        return root / name
    k = 1
    while (root / f"{name}-resume{k}").exists():
        k += 1
    return root / f"{name}-resume{k}"


def planned_launches(page: Page, out: Path, extra: Sequence[str]) -> list[tuple[Sweep, list[str], int]]:
    """What :func:`run_sweeps` would launch now: (sweep, arguments after the script without Hydra's
    overrides and sweep folder, jobs), the whole sweep as the page writes it where none of its jobs
    finished, else a multirun of the jobs left (:func:`evcd.report.reproduce.found.job_groups`)."""
    done = finished_keys(Path(out) / SWEEPS)
    plan: list[tuple[Sweep, list[str], int]] = []
    for sweep in page.sweeps:
        jobs = [PageJob(sweep, combo) for combo in sweep.jobs(extra)]
        left = [j for j in jobs if j.key not in done]
        if len(left) == len(jobs):
            plan.append((sweep, [*sweep.overrides, *extra], len(jobs)))
        elif left:
            plan += [(sweep, list(overrides), n) for _, overrides, n in job_groups(left)]
    return plan


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


def run_group(
    cmd: Sequence[str],
    output: IO[str],
    cwd: Path,
    grace_s: float = 10.0,
    watch: Callable[[], None] | None = None,
    every_s: float = 10.0,
) -> int:
    """Run ``cmd`` in a process group of its own, its output to ``output``; its exit code. ``watch`` is
    called every ``every_s`` while it runs and once after. If this process is stopped while it runs
    (an exception here, such as ``KeyboardInterrupt`` or the ``SystemExit`` of a SIGTERM handler), the
    whole group goes with it: the multirun, its launcher's workers, the jobs' day builds and second
    processes, none left playing on into the run's folder (SIGTERM, then SIGKILL after ``grace_s``)."""
    process = subprocess.Popen(cmd, stdout=output, stderr=subprocess.STDOUT, cwd=cwd, start_new_session=True)
    try:
        while True:
            try:
                code = process.wait(timeout=every_s if watch else None)
                break
            except subprocess.TimeoutExpired:
                if watch:
                    watch()
        if watch:
            watch()
        return code
    except BaseException:
        log.warning(
            "stopped: ending the sweep running (process group %d) and every process it started; "
            "the same command resumes it",
            process.pid,
        )
        stop_group(process, grace_s)
        raise


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
) -> list[Mapping[str, Any]]:
    """Launch every sweep of ``page`` that has jobs left, one after another, into ``out/sweeps``; record
    each launch (command, wall time, exit code) in ``out/reproduce.json``; return this call's launches.
    A sweep whose multirun fails (a job failed) does not stop the others."""
    out = Path(out)
    plan = planned_launches(page, out, extra)
    if not plan:
        log.info("page %s: every job has finished in %s", page.name, out / SWEEPS)
    launches = []
    for i, (sweep, overrides, jobs) in enumerate(plan, 1):
        sweep_dir = _free_dir(out / SWEEPS, sweep.name)
        argv = ["-m", *overrides, *hydra, f"hydra.sweep.dir={sweep_dir}"]
        (out / LOGS).mkdir(parents=True, exist_ok=True)
        logfile = out / LOGS / f"{sweep_dir.name}.log"
        log.info(
            "sweep %d/%d %s: %d job(s) -> %s (output: %s)", i, len(plan), sweep.name, jobs, sweep_dir, logfile
        )
        started, t0 = datetime.now().isoformat(timespec="seconds"), time.perf_counter()
        watch = FinishedJobs(sweep_dir, f"sweep {i}/{len(plan)} {sweep.name}", jobs)
        with open(logfile, "a") as f:
            cmd = [python, str(Path(scripts_dir) / sweep.script), *argv]
            code = run_group(cmd, f, Path(scripts_dir).parent, watch=watch)
        wall = time.perf_counter() - t0
        launch = {"sweep": sweep.name, "dir": str(sweep_dir), "command": display(sweep.script, argv),
                  "jobs": jobs, "started": started, "wall_s": round(wall, 1), "returncode": code}  # fmt: skip
        manifest["launches"].append(launch)
        atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")
        launches.append(launch)
        if code == 0:
            log.info("sweep %d/%d %s: done in %.0f s", i, len(plan), sweep.name, wall)
        else:
            log.warning("sweep %d/%d %s: exit code %d after %.0f s (a job failed?): see %s", i, len(plan),
                        sweep.name, code, wall, logfile)  # fmt: skip
    return launches
