"""A reproduction's records: what of its output folder a page keeps, small enough to commit.

    copied = keep_records(Path("outputs/reproduce/fleet/<time>"), Path("docs/fleet_table/runs"))

The records of an output folder are its manifest (``reproduce.json``: the page, the overrides, every
launch timed) and, of each finished job (a ``results.json``), the files its numbers and wall time are
read from: ``.hydra/overrides.yaml`` (which job it is), ``.hydra/config.yaml`` (the whole config it ran
with), ``results.json``, the evaluation's episode CSVs and the job's log, at the same relative paths.
Checkpoints, TensorBoard events, figures, a learner's training rows (``train_episodes.csv``: no page
reads them; its 3,000 rows would make a single-target learner's records 0.4 MB instead of tens of kB)
and the jobs that did not finish are left behind (a fleet job's records are tens of kB; its
checkpoints tens of MB).

Two uses. Rendering: the records are run directories, so ``reproduce.py <page> --check <records>/sweeps``
renders the page from them, with no simulation, and compares it with the committed data. Resuming
elsewhere: a copy of the records as a new ``--out`` is an output folder of the page whose finished
jobs are these, so the page's command run into it runs only the jobs left (on another machine, or
after the machine that ran the first jobs is gone); its manifest keeps every earlier launch, so the
page's wall time counts them all.

Records accumulate: keeping the records of a later state of the same reproduction (its manifest's
launches begin with the kept ones) adds the jobs finished since. A record file that is already kept
with other content, or a manifest of another page or of launches the folder does not hold, is refused
before anything is written.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from evcd.loops.run_files import RESULTS_JSON, TRAIN_CSV
from evcd.report.reproduce.launch import MANIFEST, SWEEPS, read_runs
from evcd.report.reproduce.spec import PageError
from evcd.report.sweep import MULTIRUN_YAML, OVERRIDES_YAML
from evcd.utils.atomic import atomic_write_bytes

#: A finished job's record files, as glob patterns relative to its run directory.
RECORD_FILES = (OVERRIDES_YAML.as_posix(), ".hydra/config.yaml", RESULTS_JSON, "*.csv", "*.log")
#: The files of a finished job that match :data:`RECORD_FILES` but no page reads (the training rows).
LEFT_BEHIND = frozenset({TRAIN_CSV})


def _manifest(folder: Path) -> dict[str, Any] | None:
    """The parsed manifest of ``folder`` (``None``: it has none)."""
    path = folder / MANIFEST
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
    except ValueError:
        manifest = None
    if not isinstance(manifest, dict):
        raise PageError(f"{path} is not a reproduction's manifest (not a JSON object)")
    return manifest


def record_files(out: Path) -> Iterator[Path]:
    """The record files of ``out`` (relative to it): each finished job's (:data:`RECORD_FILES`) and its
    sweep's ``multirun.yaml``; the manifest apart."""
    sweeps = set()
    for run in read_runs(out / SWEEPS):
        if run.results is None:  # not finished
            continue
        for pattern in RECORD_FILES:
            for path in sorted(run.path.glob(pattern)):
                if path.is_file() and path.name not in LEFT_BEHIND:
                    yield path.relative_to(out)
        sweeps.add(run.path.parent)
    for sweep in sorted(sweeps):
        if (sweep / MULTIRUN_YAML).is_file():
            yield (sweep / MULTIRUN_YAML).relative_to(out)


def _check_manifests(out: Path, dest: Path, page: str | None) -> bytes:
    """``out``'s manifest (as bytes), after checking that it is a run of ``page`` (any page: ``None``)
    and that ``dest``'s, if any, is an earlier state of it.

    Raises:
        PageError: ``out`` is not a reproduction's folder or not one of ``page``, or ``dest`` holds the
            records of another page, other overrides, or launches ``out`` does not hold.
    """
    new = _manifest(out)
    if new is None:
        raise PageError(
            f"{out} is not a reproduction's folder (no {MANIFEST}): give the --out of a page's run"
        )
    if page is not None and new.get("page") != page:
        raise PageError(f"{out} is a run of page {new.get('page')!r}, not of page {page!r}")
    old = _manifest(dest)
    if old is not None:
        same = all(old.get(k) == new.get(k) for k in ("page", "sweeps", "overrides"))
        kept, launches = old.get("launches") or [], new.get("launches") or []
        if not same or launches[: len(kept)] != kept:
            raise PageError(f"{dest} holds records of another reproduction (page {old.get('page')!r}, "
                            f"{len(kept)} launch(es)) than {out} continues: nothing there is overwritten; "
                            "choose another folder for the records")  # fmt: skip
    return (out / MANIFEST).read_bytes()


def keep_records(out: Path, dest: Path, page: str | None = None) -> list[Path]:
    """Copy the records of the output folder ``out`` (a run of ``page``, where named) into ``dest``
    (made if need be): the files not kept yet, then the manifest. Returns the files copied, relative
    to ``dest`` (the manifest last).

    Raises:
        PageError: :func:`_check_manifests` refuses, or a record is kept in ``dest`` with other content
            (each such file named); nothing is written then.
    """
    out, dest = Path(out), Path(dest)
    manifest = _check_manifests(out, dest, page)
    new, differ = [], []
    for rel in record_files(out):
        kept = dest / rel
        if not kept.exists():
            new.append(rel)
        elif kept.read_bytes() != (out / rel).read_bytes():
            differ.append(rel)
    if differ:
        names = ", ".join(map(str, differ[:5])) + (f" and {len(differ) - 5} more" if len(differ) > 5 else "")
        raise PageError(f"{dest} keeps {len(differ)} record file(s) with other content than {out}: {names}; "
                        "nothing there is overwritten")  # fmt: skip
    for rel in new:
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(dest / rel, (out / rel).read_bytes())
    dest.mkdir(parents=True, exist_ok=True)
    if _manifest(dest) is None or (dest / MANIFEST).read_bytes() != manifest:
        atomic_write_bytes(dest / MANIFEST, manifest)
        new.append(Path(MANIFEST))
    return new
