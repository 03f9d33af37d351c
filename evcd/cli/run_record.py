"""The record of a run that Hydra keeps in ``<run>/.hydra/``, written only once the run is accepted.

Hydra writes ``.hydra/{config,overrides,hydra}.yaml`` into the run directory before the script's
first line runs, so a run that evcd then refuses (a new run where a finished one wrote, a resume with
changed settings) used to replace the record of the very run it refused to touch, and
``scripts/make_table.py``, which matches jobs through ``overrides.yaml``, lost that run. The configs
set ``hydra.output_subdir: null`` (Hydra writes nothing there) and the scripts call
:func:`write_run_record` once their checks passed; :func:`discard_refused_run_dir` removes the
directory a refused run made for itself (it holds nothing but Hydra's log of the refusal).
"""

from __future__ import annotations

import re
import time
from datetime import datetime
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evcd.utils.atomic import atomic_write_text

RECORD_DIR = ".hydra"
_STAMP = "%Y-%m-%d %H:%M:%S"
_FIRST_STAMP = re.compile(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),\d+\]")


def write_run_record(run_dir: Path, cfg: DictConfig) -> Path:
    """Write Hydra's record of this run into ``run_dir/.hydra`` (``config.yaml``: the task's config,
    ``overrides.yaml``: the command line's overrides, ``hydra.yaml``: Hydra's own settings), each file
    atomically; return the folder."""
    hydra_cfg = HydraConfig.get()
    folder = Path(run_dir) / RECORD_DIR
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "config.yaml", OmegaConf.to_yaml(cfg))
    atomic_write_text(folder / "overrides.yaml", OmegaConf.to_yaml(hydra_cfg.overrides.task))
    atomic_write_text(folder / "hydra.yaml", OmegaConf.to_yaml(OmegaConf.create({"hydra": hydra_cfg})))
    return folder


def discard_refused_run_dir(run_dir: Path, started: float) -> bool:
    """Remove ``run_dir`` if it holds nothing but logs that this process began (a run refused before
    its start, in a directory Hydra made for it); return whether it did. ``started``: the process's
    start (``time.time()``).

    A log counts as this process's when its first line is stamped (Hydra's ``[%Y-%m-%d %H:%M:%S,ms]``)
    no earlier than ``started``; a directory holding anything else, or a log begun before (an earlier
    run's, appended to), is left as it is.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return False
    entries = list(run_dir.iterdir())
    if not entries or any(not p.is_file() or p.suffix != ".log" for p in entries):
        return False
    since = datetime.fromtimestamp(int(started)).strftime(_STAMP)
    for p in entries:
        with open(p, encoding="utf-8", errors="replace") as f:
            match = _FIRST_STAMP.match(f.readline())
        if match is None or match.group(1) < since:
            return False
    for p in entries:
        p.unlink()
    run_dir.rmdir()
    return True


def process_start() -> float:
    """When this process started (``time.time()`` at the import of this module, which the scripts
    import before Hydra makes the run directory)."""
    return _STARTED


_STARTED = time.time()
