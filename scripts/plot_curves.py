"""Overlay the learning curves of training runs: travel time per training episode, and switches.

    python scripts/plot_curves.py outputs/train/<dqn run> outputs/train/<dueling run> --out curves.png
    python scripts/plot_curves.py RUN... greedy_on_train_episodes.csv --reference "queue_aware=250"

Each run directory's ``train_episodes.csv`` is one curve, labelled with its agent (from
``results.json``) or ``--label``; an episodes CSV given directly (e.g. a rule run on the same
episodes) is one curve too, labelled with its file name. ``--reference "LABEL=SECONDS"`` draws a
horizontal line.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from evcd.loops.curves import plot_learning_curve
from evcd.loops.run_files import RESULTS_JSON, TRAIN_CSV, read_episodes_csv

log = logging.getLogger("plot_curves")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="training run directories or episodes CSV files")
    p.add_argument("--out", type=Path, default=Path("learning_curves.png"), help="PNG to write")
    p.add_argument("--label", action="append", default=[], help="a label per run (default: its agent)")
    p.add_argument("--reference", action="append", default=[], metavar="LABEL=SECONDS",
                   help="a horizontal reference line")  # fmt: skip
    p.add_argument("--window", type=int, default=50, help="episodes in the rolling mean (default 50)")
    p.add_argument("--title", default="", help="figure title")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        if args.out.exists() and not args.force:
            raise ValueError(f"{args.out} exists; pass --force to replace it")
        if args.label and len(args.label) != len(args.runs):
            raise ValueError(f"{len(args.label)} --label for {len(args.runs)} runs: give one per run or none")
        if args.window < 1:
            raise ValueError(f"--window={args.window}: must be >= 1")
        references = {}
        for ref in args.reference:
            label, sep, value = ref.rpartition("=")
            if not sep or not label:
                raise ValueError(f"--reference {ref!r}: expected LABEL=SECONDS")
            references[label] = float(value)
        curves = {}
        for i, run in enumerate(args.runs):
            csv_file = run if run.is_file() else run / TRAIN_CSV
            if not csv_file.is_file():
                raise ValueError(f"{run}: no {TRAIN_CSV} (not a finished training run of a learning agent)")
            label = args.label[i] if args.label else (run.stem if run.is_file() else _agent(run))
            if label in curves:
                label = f"{label} ({run.name})"
            curves[label] = read_episodes_csv(csv_file)
    except (ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    plot_learning_curve(curves, args.out, window=args.window, references=references, title=args.title)
    log.info("wrote %s", args.out)
    return 0


def _agent(run: Path) -> str:
    try:
        return str(json.loads((run / RESULTS_JSON).read_text())["agent"])
    except (OSError, ValueError, KeyError):
        return run.name


if __name__ == "__main__":
    sys.exit(main())
