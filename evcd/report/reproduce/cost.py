"""What a page's reproduce command costs on this machine, measured on a small version of the page.

    report = reproduce_cost(load_page("readme", PAGES), work, scripts_dir, hydra=["hydra/launcher=joblib",
                            "hydra.launcher.n_jobs=2"], full=Path("outputs/reproduce/readme/<time>"))

The small version keeps the page's sweeps and cuts each to its first job (the first value of every
swept key: for the README page, Dueling DDQN and stable-baselines3's PPO on seed 0), renders nothing,
and runs through ``scripts/reproduce.py`` itself (the command a user runs, Hydra's launcher
included) twice: **cold**, from an empty day cache (every day the jobs need is built), then **warm**,
from the cache the cold run filled. Both are measured wall times, back to back. From them:

- ``day_builds_s``: cold minus warm, what building the days cost;
- ``full_minutes_extrapolated``: the whole page were its jobs alike within a sweep: the day builds
  once, plus per sweep its warm job's wall time times the sweep's jobs over the jobs run at once
  (``hydra.launcher.n_jobs``, 1 without a parallel launcher). Two jobs on two cores do not run at twice
  one's speed, so on a busy machine this is low; it is an extrapolation, and the report says so;
- ``full_minutes_measured`` and ``full_over_small``, where ``full`` names a finished run of the whole
  page (its ``reproduce.json``: the launches' wall times): the measured wall time and its ratio to the
  small version's cold run, the figure that carries to the next measurement of the small version.

Every job of the small version is a job of the page (its overrides are one of the page's jobs', with
``extra`` and the bench's cache folder added), so its day builds and its training are the page's.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from evcd.report.reproduce.launch import MANIFEST, launches_span, parallel_jobs
from evcd.report.reproduce.spec import Page, PageError

log = logging.getLogger(__name__)

#: The override that sends every job of the small version to the bench's own day cache.
CACHE_KEY = "env.cache_dir"


def small_page(page: Page, cache_dir: Path, extra: Sequence[str] = ()) -> dict[str, Any]:
    """The definition of ``page``'s small version (module docstring): each sweep its first job with
    ``extra`` and ``env.cache_dir=cache_dir`` (replacing the job's own), no render."""
    sweeps = []
    for sweep in page.sweeps:
        first = [o for o in sweep.jobs(extra)[0] if o.split("=", 1)[0].lstrip("+~") != CACHE_KEY]
        sweeps.append({"name": sweep.name, "script": sweep.script, "task": sweep.task, "regime": sweep.regime,
                       "overrides": [*first, f"{CACHE_KEY}={cache_dir}"]})  # fmt: skip
    return {"title": f"{page.title}: the first job of each sweep", "sweeps": sweeps, "renders": []}


def measured_wall(out: Path) -> dict[str, Any]:
    """A finished reproduction's measured cost, from its ``reproduce.json``: the page, the wall time of
    its launches (:func:`~evcd.report.reproduce.launch.launches_span`: overlapping launches counted
    once), their jobs, and per sweep the wall time of its launches.

    Raises:
        PageError: ``out`` holds no reproduce.json, or a launch that failed.
    """
    path = Path(out) / MANIFEST
    if not path.is_file():
        raise PageError(f"{out}: no {MANIFEST} (give the --out folder of a finished reproduce.py run)")
    manifest = json.loads(path.read_text())
    launches = manifest.get("launches") or []
    failed = [launch["sweep"] for launch in launches if launch.get("returncode") != 0]
    if not launches or failed:
        why = f"sweeps {failed} failed" if failed else "nothing was launched"
        raise PageError(f"{out}: {why}; the bench compares with a finished page")
    per_sweep = {name: launches_span([x for x in launches if x["sweep"] == name])
                 for name in dict.fromkeys(x["sweep"] for x in launches)}  # fmt: skip
    return {"page": manifest.get("page"), "wall_s": launches_span(launches),
            "jobs": sum(int(launch["jobs"]) for launch in launches), "sweeps_s": per_sweep}  # fmt: skip


def reproduce_cost(
    page: Page,
    work: Path,
    scripts_dir: Path,
    extra: Sequence[str] = (),
    hydra: Sequence[str] = (),
    full: Path | None = None,
    python: str = sys.executable,
) -> dict[str, Any]:
    """Run ``page``'s small version cold, then warm, in ``work`` (a new folder) and report what it cost
    (module docstring).

    Raises:
        PageError: ``work`` exists, a bad ``n_jobs``, ``full`` is not a finished run of this page, or
            a run of the small version failed (its log named).
    """
    work = Path(work)
    if work.exists():
        raise PageError(f"{work} exists: the bench runs in a new folder (nothing there is overwritten)")
    workers = parallel_jobs(hydra)
    done = measured_wall(full) if full is not None else None
    if done is not None and done["page"] != page.name:
        raise PageError(f"{full} reproduced page {done['page']!r}, not {page.name!r}")
    work.mkdir(parents=True)
    definition = work / f"{page.name}_small.yaml"
    definition.write_text(yaml.safe_dump(small_page(page, work / "cache", extra), sort_keys=False))
    runs = {}
    for name in ("cold", "warm"):
        out, logfile = work / name, work / f"{name}.log"
        t0 = time.perf_counter()
        with open(logfile, "w") as f:
            code = subprocess.run([python, str(Path(scripts_dir) / "reproduce.py"), str(definition), *hydra,
                                   "--out", str(out)], stdout=f, stderr=subprocess.STDOUT,
                                  cwd=Path(scripts_dir).parent).returncode  # fmt: skip
        wall = time.perf_counter() - t0
        if code != 0:
            raise PageError(f"the small version of page {page.name} ({name}) failed (exit {code}): "
                            f"see {logfile}")  # fmt: skip
        runs[name] = {**measured_wall(out), "wall_s": wall}  # the whole command's, rendering included
        log.info("page %s, small version, %s: %.1f s", page.name, name, wall)
    cold, warm = runs["cold"], runs["warm"]
    jobs = {s.name: len(s.jobs(extra)) for s in page.sweeps}
    jobs_s = sum(warm["sweeps_s"][s] * n / min(workers, n) for s, n in jobs.items())
    builds = max(0.0, cold["wall_s"] - warm["wall_s"])
    report: dict[str, Any] = {
        "page": page.name,
        "small_jobs": len(page.sweeps),
        "full_jobs": sum(jobs.values()),
        "jobs_per_sweep": jobs,
        "parallel_jobs": workers,
        "small_cold_s": cold["wall_s"],
        "small_warm_s": warm["wall_s"],
        "small_warm_sweeps_s": warm["sweeps_s"],
        "day_builds_s": builds,
        "full_minutes_extrapolated": (builds + jobs_s) / 60.0,
        "extrapolation": "the day builds once, plus per sweep its warm job's wall time x its jobs / the jobs "
        "run at once (jobs alike within a sweep, perfect parallel speed-up: low on a busy machine)",
        "work": str(work),
    }
    if done is not None:
        report["full_minutes_measured"] = done["wall_s"] / 60.0
        report["full_over_small"] = done["wall_s"] / cold["wall_s"]
        report["full"] = str(full)
    return report
