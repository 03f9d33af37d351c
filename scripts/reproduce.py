"""Every published page from one command: run the jobs a page needs, render its tables, and compare
them with the data the page commits.

    python scripts/reproduce.py results                 # the 90 jobs of docs/RESULTS.md "The table"
    python scripts/reproduce.py fleet hydra/launcher=joblib hydra.launcher.n_jobs=2
    python scripts/reproduce.py results hydra/launcher=evcd_slurm hydra.launcher.partition=cpu
    python scripts/reproduce.py perturbed --dry-run     # the jobs and their exact commands; nothing runs
    python scripts/reproduce.py results --out outputs/reproduce/results/<time>   # resume: the jobs left
    python scripts/reproduce.py results --check outputs/table/evs400 outputs/table/evs300 outputs/table/evs200
    python scripts/reproduce.py fleet --out outputs/reproduce/fleet/<time> --records docs/fleet_table/runs

The pages (``docs/reproduce/<page>.yaml``: readme, results, fleet, perturbed; or a page file ``<path>.yaml``)
name their sweeps, what is rendered from them and the committed files it is compared with
(:mod:`evcd.report.reproduce.spec`). Each sweep runs as ``python scripts/<script> -m <overrides>`` with
the overrides given here after the page (Hydra's, such as a launcher, pass through), into
``--out`` (default ``outputs/reproduce/<page>/<time>``): ``sweeps/``, ``logs/``, ``reproduce.json`` (the
launches, timed) and ``rendered/`` (each render's files and ``reproduce.md``: the stamp, the sweeps' and
the jobs' wall times). ``--check DIR...`` runs nothing: it renders from finished run directories (the
page's jobs matched by their overrides, wherever they ran). Either way the rendering is then compared
with the committed data, cell by cell (:mod:`evcd.report.reproduce.check`). ``--records DEST`` with the
``--out`` of an earlier run runs nothing either: it keeps that folder's records in ``DEST`` (the
manifest and each finished job's overrides, config, results, episode CSVs and log;
:mod:`evcd.report.reproduce.records`), adding to the ones kept there before. ``--check DEST/sweeps``
renders the page from them, and a copy of them as a new ``--out`` resumes the page with the jobs left,
on any machine.

Stopped (Ctrl-C, or SIGTERM), it stops the sweeps running with every process they started, and the
same command with the same ``--out`` resumes it: the jobs left, a training job stopped after a
checkpoint continued from it (in a copy of its run directory).

Exit codes: 0 rendered, and equal to the committed data; 1 rendered, and different (each difference
listed); 2 bad input (an unknown page, a run directory of another task or experiment, a launcher whose
plugin is not installed, an output folder that exists and is not this page's), or jobs that did not
finish (each named, with the command that completes them).
"""

from __future__ import annotations

import argparse
import logging
import shlex
import shutil
import signal
import sys
from datetime import datetime
from pathlib import Path

from evcd.loops.run_files import RESULTS_JSON
from evcd.report.reproduce.check import compare_page
from evcd.report.reproduce.found import completion_commands, find_jobs, run_dirs
from evcd.report.reproduce.launch import SWEEPS, check_launcher, open_output, planned_launches, run_sweeps
from evcd.report.reproduce.records import keep_records
from evcd.report.reproduce.render import render_page
from evcd.report.reproduce.spec import Page, PageError, Sweep, display, load_page, split_overrides
from evcd.report.sweep import ResultsError

log = logging.getLogger("reproduce")
ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "reproduce"
RENDERED = "rendered"


def dry_run(page: Page, out: Path, extra: list[str], hydra: list[str]) -> str:
    """The jobs :func:`main` would run into ``out`` now, with each multirun's exact command."""
    plan = planned_launches(page, out, extra)
    total = sum(x.jobs for x in plan)
    lines = [f"page {page.name} ({page.title}): {total} jobs to run in {len(plan)} multirun(s), into {out}"]
    for i, x in enumerate(plan, 1):
        sweep = x.sweep
        argv = ["-m", *x.overrides, *hydra, f"hydra.sweep.dir={out / SWEEPS / sweep.name}"]
        what = f"{x.jobs} jobs" if x.resume is None else f"continues {x.resume} from its last checkpoint"
        lines += [f"sweep {sweep.name} ({sweep.script}, {what}):", f"  {display(sweep.script, argv)}"]
        jobs = Sweep(sweep.name, sweep.script, sweep.task, sweep.regime, x.overrides).jobs()
        lines += [f"    {i}.{k} {' '.join(job)}" for k, job in enumerate(jobs, 1)]
    for render in page.renders:
        against = ", ".join(c.committed for c in render.compare) or "nothing"
        lines.append(
            f"render {render.name} ({render.kind}, from {', '.join(render.sweeps)}): compared with {against}"
        )
    lines += [f"not covered: {note}" for note in page.not_covered]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("page", help="a page (docs/reproduce/<page>.yaml) or a page file <path>.yaml")
    p.add_argument(
        "overrides", nargs="*", help="Hydra overrides every job takes (a launcher: hydra/launcher=...)"
    )
    p.add_argument("--dry-run", action="store_true", help="list the jobs and their commands; run nothing")
    p.add_argument("--check", nargs="+", type=Path, metavar="DIR", help="render from these finished run "
                   "directories (run nothing) and compare with the committed data")  # fmt: skip
    p.add_argument("--out", type=Path, help="output folder (default outputs/reproduce/<page>/<time>); an "
                   "earlier run's folder resumes it")  # fmt: skip
    p.add_argument("--records", type=Path, metavar="DEST", help="keep the records of the finished jobs of "
                   "--out (an earlier run of the page) in DEST; run nothing")  # fmt: skip
    p.add_argument(
        "--root", type=Path, default=ROOT, help="where the committed data lies (default: this checkout)"
    )
    args = p.parse_intermixed_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    made: Path | None = None
    try:
        page = load_page(args.page, PAGES)
        extra, hydra = map(list, split_overrides(args.overrides))
        page.jobs(extra)  # every override parses
        stamp = datetime.now().strftime("%Y-%m-%d_%H-%M-%S") + ("-check" if args.check else "")
        out = (args.out or Path("outputs") / "reproduce" / page.name / stamp).resolve()
        root = ["--root", str(args.root)] if args.root.resolve() != ROOT else []  # in the commands it prints
        if args.records:
            return _records(page, args.out, args.records, bool(args.check or args.dry_run))
        if args.dry_run:
            print(dry_run(page, out, extra, hydra))
            try:
                check_launcher(hydra)
            except PageError as exc:
                log.warning("%s", exc)
            return 0
        if args.check:
            if out.exists():
                raise FileExistsError(f"{out} exists: nothing there is overwritten (give a new --out)")
            made = out  # the folder this call makes, with the parents it makes
            while not made.parent.exists():
                made = made.parent
            found = find_jobs(page, args.check, extra)
            more = out.parent / f"{out.name}-completion"
            again = shlex.join(["python", "scripts/reproduce.py", args.page, *args.overrides, "--check",
                                *map(str, args.check), str(more), *root])  # fmt: skip
            found.require_complete(
                [*completion_commands([j for j, _ in found.gaps], hydra, more), f"then: {again}"]
            )
            rendered = render_page(page, found, out / RENDERED, None, extra)
        else:
            check_launcher(hydra)
            manifest = open_output(page, out, extra)
            rendered = out / RENDERED
            if rendered.exists():
                log.info(
                    "%s: already rendered; comparing it again (a new --out runs the page again)", rendered
                )
            else:
                run_sweeps(page, out, manifest, extra, hydra, ROOT / "scripts")
                found = find_jobs(page, [out / SWEEPS] if run_dirs(out / SWEEPS) else [], extra)
                again = shlex.join(["python", "scripts/reproduce.py", args.page, *args.overrides, "--out",
                                    str(out), *root])  # fmt: skip
                found.require_complete([again])
                render_page(page, found, rendered, manifest, extra)
        log.info("rendered page %s into %s", page.name, rendered)
        differences, notes = compare_page(page, rendered, args.root)
    except (PageError, ResultsError, FileExistsError) as exc:
        if made is not None:  # a --check that could not render leaves no folder behind
            shutil.rmtree(made, ignore_errors=True)
        log.error("%s", exc)
        return 2
    for note in notes:
        log.info("%s", note)
    for line in differences:
        print(line)
    log.info("%s", f"{len(differences)} difference(s) from the committed data" if differences
             else "equal to the committed data")  # fmt: skip
    return 1 if differences else 0


def _records(page: Page, out: Path | None, dest: Path, other_mode: bool) -> int:
    """``--records``: keep the records of ``out`` (a run of ``page``) in ``dest``."""
    if other_mode or out is None:
        raise PageError("--records keeps the records of an earlier run: give its --out, without --check "
                        "or --dry-run")  # fmt: skip
    copied = keep_records(out, dest, page.name)
    jobs = {p.parent for p in copied if p.name == RESULTS_JSON}
    log.info("%s: kept %d file(s) of %d newly finished job(s) from %s", dest, len(copied), len(jobs), out)
    return 0


def _terminated(signum: int, _frame: object) -> None:
    """SIGTERM (``kill``, a cluster's time limit) ends the run as Ctrl-C does: each sweep running is
    stopped with every process it started (:func:`evcd.report.reproduce.launch.run_sweeps`)."""
    raise SystemExit(128 + signum)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _terminated)
    sys.exit(main())
