"""What a run writes: the files' names, and the episodes and results files (read back by
:mod:`evcd.report`).

A run directory (``scripts/train.py``) holds ``train_episodes.csv``, ``episodes.csv``,
``baseline_<rule>_episodes.csv`` (each baseline rule on the same episodes), ``results.json``,
``learning_curve.png``, ``checkpoints/`` and ``tensorboard/``; ``scripts/evaluate.py`` writes
``episodes.csv`` and ``results.json``. A fleet run (``task=fleet``) writes ``train_fleet_episodes.csv``,
``fleet_episodes.csv``, ``baseline_<rule>_fleet_episodes.csv`` and ``fleet_trace.png`` instead of the
episodes files (one row per fleet episode; :mod:`evcd.loops.tasks`). Every file is written
atomically; none already there is overwritten unless asked.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from evcd import ENV_ID, FLEET_ENV_ID
from evcd.env.runners.base import EpisodeRow
from evcd.loops.machine import machine_record
from evcd.loops.stats import EvalResult
from evcd.utils.atomic import atomic_write_json, atomic_write_text, json_floats
from evcd.utils.provenance import code_record

CHECKPOINTS = "checkpoints"
TENSORBOARD = "tensorboard"
TRAIN_CSV = "train_episodes.csv"
EVAL_CSV = "episodes.csv"
RESULTS_JSON = "results.json"
CURVE_PNG = "learning_curve.png"
FLEET_TRAIN_CSV = "train_fleet_episodes.csv"
FLEET_CSV = "fleet_episodes.csv"
FLEET_PNG = "fleet_trace.png"
#: The files of a finished run (a new run refuses a directory that holds one of them), as glob patterns.
OUTPUTS = (TRAIN_CSV, EVAL_CSV, "baseline_*_episodes.csv", RESULTS_JSON, CURVE_PNG,
           FLEET_TRAIN_CSV, FLEET_CSV, FLEET_PNG)  # fmt: skip


def baseline_csv(rule: str, fleet: bool = False) -> str:
    """The episodes file of the baseline rule ``rule`` (evaluated on the run's evaluation episodes);
    ``fleet``: of a fleet run."""
    return f"baseline_{rule}_{'fleet_' if fleet else ''}episodes.csv"


CSV_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(EpisodeRow))


def refuse_clobber(path: Path, overwrite: bool) -> None:
    """Refuse to replace ``path`` unless ``overwrite``.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
    """
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists: refusing to overwrite it (pass overwrite=True)")


def episodes_csv_text(rows: Sequence[Any]) -> str:
    """``rows`` (:class:`EpisodeRow`\\ s, or fleet episodes: anything with ``row()``) as CSV text with a
    header (floats written with ``repr`` precision; no rows: the :class:`EpisodeRow` header)."""
    if not rows:
        return ",".join(CSV_FIELDS) + "\n"
    return rows_csv_text([r.row() for r in rows])


def read_episodes_csv(path: str | Path) -> list[EpisodeRow]:
    """The rows of an ``episodes.csv`` (or ``train_episodes.csv``) written by :func:`episodes_csv_text`.

    Raises:
        ValueError: the file lacks a column of :class:`EpisodeRow` (the message names the file).
    """
    types = {f.name: f.type for f in dataclasses.fields(EpisodeRow)}
    convert = {"int": int, "float": float, "str": str, "bool": lambda v: v == "True"}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [k for k in CSV_FIELDS if k not in (reader.fieldnames or ()) and k != "switches"]
        if missing:
            raise ValueError(f"{path}: not an episodes file (missing columns {missing})")
        return [
            EpisodeRow(**{k: convert[types[k]](v) for k, v in row.items() if k in types}) for row in reader
        ]


def write_episodes_csv(result: EvalResult, path: str | Path, overwrite: bool = False) -> Path:
    """Write the per-episode rows (either task's) to ``path`` atomically.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    refuse_clobber(path, overwrite)
    return atomic_write_text(path, episodes_csv_text(result.rows))


#: The versioned id of each task's environment (Gymnasium's for the single target, PettingZoo's name for
#: the fleet), as ``results.json`` records it.
ENVIRONMENTS = {"single": ENV_ID, "fleet": FLEET_ENV_ID}


def results_dict(result: EvalResult, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The content of ``results.json``: task, the environment's versioned id, agent, seed, summary,
    per-episode rows, optional config, the agent's own extras (:attr:`EvalResult.extra`, e.g.
    ``hindsight``), the code (evcd's version and commit: :func:`~evcd.utils.provenance.code_record`) and
    the machine the numbers were computed on (:func:`~evcd.loops.machine.machine_record`)."""
    return json_floats(
        {
            "task": result.task,
            "environment": ENVIRONMENTS[result.task],
            "agent": result.agent,
            "seed": result.seed,
            "summary": dataclasses.asdict(result.summary),
            "episodes": [r.row() for r in result.rows],
            "config": dict(config) if config is not None else None,
            **result.extra,
            "code": code_record(),
            "machine": machine_record(),
        }
    )


def write_results_json(
    result: EvalResult, path: str | Path, config: Mapping[str, Any] | None = None, overwrite: bool = False
) -> Path:
    """Write :func:`results_dict` to ``path`` atomically (strict JSON: NaN becomes ``null``).

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    refuse_clobber(path, overwrite)
    return atomic_write_json(path, results_dict(result, config))


def rows_csv_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """Flat rows (the same keys each, e.g. :meth:`~evcd.env.runners.fleet.FleetEpisode.row`) as CSV text."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else [], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()
