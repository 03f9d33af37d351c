"""How a script ends a run on a bad setting (:func:`stop_on_bad_setting`)."""

from __future__ import annotations

import logging
import sys
from typing import NoReturn

from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode


def stop_on_bad_setting(exc: Exception, log: logging.Logger) -> NoReturn:
    """End a script's run on ``exc`` (a bad setting, a missing file, a corrupted checkpoint), logged as
    an error.

    A single run exits with code 2: the message names the value, no traceback. In a multirun (``-m``)
    ``exc`` is re-raised instead: Hydra's ``run_job`` catches ``Exception`` (not ``SystemExit``), records
    this job as FAILED and the launcher goes on with the other jobs; once they are done the sweep ends
    with Hydra's error naming the failed job's overrides (exit code 1). A ``SystemExit`` would escape
    ``run_job`` and end the whole sweep at once: the basic launcher stops at that job, and the joblib
    launcher exits with code 2 without finishing (or even starting) the others.
    """
    log.error("%s", exc)
    if HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN:
        raise exc
    sys.exit(2)
