"""Locate the SUMO command-line tools shipped by the ``eclipse-sumo`` wheel.

No ``SUMO_HOME`` is needed: the wheel knows where it lives. Every module that runs a SUMO
binary (netconvert, netgenerate, sumo) goes through :func:`binary` and :func:`tool_env`.
"""

from __future__ import annotations

import logging
import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

import sumo

log = logging.getLogger(__name__)

SUMO_HOME = Path(sumo.SUMO_HOME)


def binary(name: str) -> str:
    """Return the absolute path of the SUMO tool ``name`` (e.g. ``"netconvert"``)."""
    path = SUMO_HOME / "bin" / name
    if not path.exists():
        raise FileNotFoundError(f"SUMO tool {name!r} not found at {path}; is eclipse-sumo installed?")
    return str(path)


def tool_env() -> dict[str, str]:
    """Environment for SUMO tools: SUMO_HOME and PROJ_DATA point into the wheel."""
    env = dict(os.environ)
    env["SUMO_HOME"] = str(SUMO_HOME)
    proj = SUMO_HOME / "data" / "proj"
    if proj.is_dir():
        env.setdefault("PROJ_DATA", str(proj))
    return env


def run_tool(name: str, args: Sequence[str], cwd: str | Path | None = None) -> subprocess.CompletedProcess:
    """Run SUMO tool ``name`` with ``args``; raise ``RuntimeError`` with its stderr on failure."""
    cmd = [binary(name), *map(str, args)]
    log.debug("running %s", " ".join(cmd))
    proc = subprocess.run(cmd, cwd=cwd, env=tool_env(), capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout)[-3000:]
        raise RuntimeError(f"{name} failed (exit {proc.returncode}):\n{tail}")
    return proc
