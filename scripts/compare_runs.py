"""Compare the dispatchers of ``scripts/train.py`` runs across worlds, paired on the same episodes.

    python scripts/compare_runs.py outputs/train_multirun/<sweep A> outputs/train_multirun/<sweep B> \\
        --reference "peak +incidents/outages/rain/roadworks/queue_aware" --out compare.md

Every run's agent and its baseline rules become rows (world, dispatcher), a world being the run's
regime, the perturbations it played and the observation blocks its agents saw
(:func:`evcd.report.compare.world_label`). Each row: the mean over seeds of the seeds' mean travel
times [95% t], and its difference with each ``--reference`` row, paired by episode within each seed
(runs of a seed play the same episodes), mean over seeds [95% t] n=seeds; A lower / B lower of pairs.
Fleet runs (``experiment=fleet``) pair by fleet episode on the guided EVs' mean travel time
(``--fleet-measure``: or ``guided_travel_censored``, ``all_travel``). ``--against-calm`` adds what
each perturbed world does to each dispatcher: its row minus the same dispatcher in the calm runs of
the same regime and observation, paired the same way, with each seed's difference (the by-kind
tables of docs/PERTURBED.md). Prints the table and writes it to ``--out`` (refusing to overwrite).

    python scripts/compare_runs.py <sweep with perturbations=none,incidents_peak,outages_peak> --against-calm
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from evcd.report.compare import FLEET_MEASURES, Runs, compare_markdown
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger("compare_runs")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dirs", nargs="+", type=Path, help="run directories or folders holding them")
    p.add_argument("--reference", action="append", default=[], help="a row 'WORLD/DISPATCHER' to pair with")
    p.add_argument("--out", type=Path, default=None, help="write the table here (Markdown)")
    p.add_argument("--fleet-measure", choices=FLEET_MEASURES, default="guided_travel",
                   help="what fleet runs compare (default: the guided EVs' mean travel time)")  # fmt: skip
    p.add_argument("--against-calm", action="store_true",
                   help="each perturbed row minus the same dispatcher in its regime's calm runs")  # fmt: skip
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    runs = Runs.read(args.dirs, args.fleet_measure)
    if not runs.travel:
        log.error("no run (results.json) under %s", [str(d) for d in args.dirs])
        return 2
    refs = [tuple(r.rsplit("/", 1)) for r in args.reference]
    missing = [f"{w}/{a}" for w, a in refs if (w, a) not in runs.travel]
    if missing:
        log.error("--reference %s: not a row; the rows: %s", missing[0], [f"{w}/{a}" for w, a in runs.rows()])
        return 2
    if args.out is not None and args.out.exists():
        log.error("%s exists: nothing is overwritten", args.out)
        return 2
    table = compare_markdown(runs, refs, args.against_calm)
    print(table)
    if args.out is not None:
        atomic_write_text(args.out, table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
