"""Collect a multirun sweep of ``scripts/train.py`` into a results table over seeds.

    python scripts/train.py -m experiment=table agent=random,greedy,queue_aware,hindsight,dqn,dueling_ddqn \\
        seed=0,1,2,3,4 evs=200,300,400
    python scripts/make_table.py outputs/train_multirun/<time>
    python scripts/make_table.py outputs/train_multirun/<table sweep> outputs/train_multirun/<paper sweep> \\
        --out results/ --allow-incomplete

Writes ``results.csv`` (one row per job), ``results.md`` (the tables, also printed), ``results_bars.png``
and ``learning_curves.png`` into ``--out`` (default: the first directory); see :mod:`evcd.report.table`.
Exit codes: 0 done; 1 a job of a sweep is missing or failed (each is named; ``--allow-incomplete``
builds the table from the others); 2 anything else (not a run directory, an output file exists, ...).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from evcd.report.fleet_table import make_fleet_table
from evcd.report.sweep import IncompleteSweepError, ResultsError
from evcd.report.table import make_table

log = logging.getLogger("make_table")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dirs", nargs="+", type=Path, help="multirun directories (or single run directories)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: the first DIR)")
    p.add_argument("--overwrite", action="store_true", help="replace output files already there")
    p.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="build the table from the finished jobs and list the missing and failed ones",
    )
    p.add_argument("--resamples", type=int, default=10_000, help="bootstrap resamples (default 10000)")
    p.add_argument("--fleet", action="store_true", help="fleet runs (experiment=fleet): the fleet table")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if args.resamples < 1:
        log.error("--resamples=%d: must be >= 1", args.resamples)
        return 2
    for d in args.dirs:
        if not d.is_dir():
            log.error("%s %s: give the multirun directories (or run directories) of finished runs", d,
                      "is not a directory" if d.exists() else "does not exist")  # fmt: skip
            return 2
    try:
        if args.fleet:
            out = make_fleet_table(args.dirs, args.out, overwrite=args.overwrite,
                                   allow_incomplete=args.allow_incomplete)  # fmt: skip
        else:
            out = make_table(args.dirs, args.out, overwrite=args.overwrite,
                             allow_incomplete=args.allow_incomplete, resamples=args.resamples)  # fmt: skip
    except IncompleteSweepError as exc:
        log.error("%s\npass --allow-incomplete to build the table from the finished jobs", exc)
        return 1
    except (ResultsError, FileExistsError, OSError) as exc:
        log.error("%s", exc)
        return 2
    sys.stdout.write(out.markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
