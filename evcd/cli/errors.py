"""How a script ends a run on a bad setting (:func:`stop_on_bad_setting`, and before Hydra composes,
:func:`refuse_removed_settings`)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from evcd.cli.run_record import RECORD_DIR, discard_refused_run_dir, process_start, write_run_record
from evcd.utils.removed import check_overrides


def stop_on_bad_setting(
    exc: Exception, log: logging.Logger, run_dir: Path | None = None, cfg: DictConfig | None = None
) -> NoReturn:
    """End a script's run on ``exc`` (a bad setting, a missing file, a corrupted checkpoint), logged as
    an error.

    A single run exits with code 2: the message names the value, no traceback. In a multirun (``-m``)
    ``exc`` is re-raised instead: Hydra's ``run_job`` catches ``Exception`` (not ``SystemExit``), records
    this job as FAILED and the launcher goes on with the other jobs; once they are done the sweep ends
    with Hydra's error naming the failed job's overrides (exit code 1). A ``SystemExit`` would escape
    ``run_job`` and end the whole sweep at once: the basic launcher stops at that job, and the joblib
    launcher exits with code 2 without finishing (or even starting) the others.

    A single run refused before it wrote anything leaves no directory behind: ``run_dir`` is removed
    if it holds nothing but this process's log (:func:`~evcd.cli.run_record.discard_refused_run_dir`;
    the message is on the console). A job of a multirun keeps its directory with its log, and gets
    its record (``cfg``) if it has none yet, so that ``scripts/make_table.py`` names it as failed with
    its reason; an existing record (another run's) is never replaced.
    """
    log.error("%s", exc)
    if HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN:
        if run_dir is not None and cfg is not None and not (run_dir / RECORD_DIR).exists():
            write_run_record(run_dir, cfg)
        raise exc
    if run_dir is not None:
        logging.shutdown()  # close the log file before its directory goes
        discard_refused_run_dir(run_dir, process_start())
    sys.exit(2)


def refuse_removed_settings(argv: Sequence[str], log: logging.Logger) -> None:
    """Before Hydra composes a script's config: a command line that sets a setting which has left evcd
    (:mod:`evcd.utils.removed`) ends with exit code 2 and one line naming it and the last commit that
    has it (Hydra would refuse the unknown key with a longer story and no commit)."""
    try:
        check_overrides([arg for arg in argv if not arg.startswith("-")])
    except ValueError as exc:
        log.error("%s", exc)
        sys.exit(2)
