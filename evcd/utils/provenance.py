"""Which code made a number: evcd's version and the git commit of the checkout it runs from.

    code_record()   # {"evcd": "0.1.0", "commit": "a3e96b2...", "dirty": False}

Every ``results.json`` carries it beside the environment's versioned id and the machine
(:mod:`evcd.loops.machine`), so that a row can be tied to the dynamics and the code that made it.
``commit`` is the full hash of ``HEAD`` when evcd runs from a git checkout of its own repository
(an editable install, as the README's), with ``dirty`` true where tracked files differ from it; from
anywhere else (an installed wheel, a copy) it reads ``"not a git checkout"`` and ``dirty`` is
``None``: the version alone names the code then.
"""

from __future__ import annotations

import functools
import importlib.metadata
import subprocess
from pathlib import Path
from typing import Any

import evcd

#: What ``commit`` reads where evcd does not run from a git checkout of its own repository.
NOT_A_CHECKOUT = "not a git checkout"


def evcd_version() -> str:
    """evcd's installed version (the package's own where it is not installed)."""
    try:
        return importlib.metadata.version("evcd")
    except importlib.metadata.PackageNotFoundError:
        return evcd.__version__


def git_commit(root: str | Path) -> tuple[str, bool | None]:
    """The commit checked out in the git repository whose top level is ``root``, and whether tracked
    files differ from it; ``(NOT_A_CHECKOUT, None)`` where ``root`` is not such a top level (no git,
    no repository, or ``root`` inside another repository's work tree)."""
    root = Path(root).resolve()

    def git(*args: str) -> str:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10)
        if out.returncode != 0:
            raise OSError(out.stderr.strip())
        return out.stdout.strip()

    try:
        if Path(git("rev-parse", "--show-toplevel")).resolve() != root:
            return NOT_A_CHECKOUT, None
        return git("rev-parse", "HEAD"), bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return NOT_A_CHECKOUT, None


@functools.cache
def code_record() -> dict[str, Any]:
    """evcd's version, the commit it runs from and whether the checkout has uncommitted changes (read
    once per process)."""
    commit, dirty = git_commit(Path(evcd.__file__).resolve().parents[1])
    return {"evcd": evcd_version(), "commit": commit, "dirty": dirty}
