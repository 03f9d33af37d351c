"""Atomic file writes: a reader sees the old file or the new one, never a partial one."""

from __future__ import annotations

import io
import json
import math
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

# the process's umask, read once at import (os.umask can only be read by setting it)
_UMASK = os.umask(0o022)
os.umask(_UMASK)
#: Mode of the files written here: what ``open(path, "w")`` would give (``mkstemp`` gives 0600).
FILE_MODE = 0o666 & ~_UMASK


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and ``os.replace``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, FILE_MODE)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def json_floats(value: Any) -> Any:
    """NaN/inf -> ``None`` recursively (strict JSON has no NaN); tuples become lists."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: json_floats(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_floats(v) for v in value]
    return value


def atomic_write_json(path: str | Path, value: Any) -> Path:
    """Write ``value`` as strict JSON (NaN as ``null``, one space of indent, a final newline) atomically."""
    return atomic_write_text(path, json.dumps(json_floats(value), indent=1, allow_nan=False) + "\n")


def atomic_write_png(figure: Any, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib ``figure`` as a PNG atomically (rendered in memory, then written)."""
    buf = io.BytesIO()
    figure.savefig(buf, format="png", dpi=dpi)
    return atomic_write_bytes(path, buf.getvalue())
