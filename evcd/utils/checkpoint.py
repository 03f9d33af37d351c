"""Checkpoint files: atomic, checksummed, and loaded without unpickling arbitrary objects.

    save_checkpoint(run_dir / "checkpoints", state, name="ckpt_000100")   # state: tensors, numpy, primitives
    state = load_checkpoint(run_dir / "checkpoints")                        # the latest one

A checkpoint folder holds ``<name>.pt`` files (``torch.save``) and ``latest.json``, the pointer to the
newest one with its SHA-256. A save writes the new ``.pt`` through a temporary file and
``os.replace``, then replaces the pointer the same way, then deletes the older ``.pt`` files: a
process killed at any moment leaves the pointer naming a complete, verified file (the previous one
or the new one). Loading goes through ``torch.load(weights_only=True)``, which only rebuilds tensors
and plain containers; numpy arrays are stored as tensors and turned back on load
(:func:`to_torch` / :func:`to_numpy`).
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from evcd.utils.atomic import atomic_write_bytes, atomic_write_text

log = logging.getLogger(__name__)

POINTER = "latest.json"
SUFFIX = ".pt"


class CheckpointError(ValueError):
    """A checkpoint is missing, corrupted, truncated or does not fit what loads it."""


def to_torch(value: Any) -> Any:
    """``value`` with every numpy array (and numpy scalar) turned into a tensor / Python number,
    recursively through dicts, lists and tuples, so that ``torch.load(weights_only=True)`` reads it."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(value))
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {k: to_torch(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(to_torch(v) for v in value)
    return value


def to_numpy(value: Any) -> Any:
    """The inverse of :func:`to_torch` for containers: every tensor becomes a numpy array."""
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().numpy()
    if isinstance(value, Mapping):
        return {k: to_numpy(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(to_numpy(v) for v in value)
    return value


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def save_checkpoint(
    directory: str | Path, state: Mapping[str, Any], name: str, keep: Collection[str] = ()
) -> Path:
    """Write ``state`` as ``directory/<name>.pt``, point ``latest.json`` at it, drop older ones (but
    those named in ``keep``).

    Args:
        directory: the checkpoint folder (created if missing).
        state: tensors, numpy arrays, plain Python values and containers of them.
        name: file stem, e.g. ``"ckpt_000100"`` (letters, digits, ``_`` and ``-``).
        keep: stems of older checkpoints in ``directory`` to leave in place.

    Returns:
        The path of the new checkpoint file.
    """
    if not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ValueError(f"checkpoint name={name!r}: use letters, digits, '_' and '-'")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    torch.save(to_torch(dict(state)), buf)
    data = buf.getvalue()
    path = atomic_write_bytes(directory / f"{name}{SUFFIX}", data)
    pointer = {"file": path.name, "sha256": _sha256(data), "bytes": len(data)}
    atomic_write_text(directory / POINTER, json.dumps(pointer, indent=1) + "\n")
    for old in directory.glob(f"*{SUFFIX}"):
        if old.name != path.name and old.name.removesuffix(SUFFIX) not in keep:
            old.unlink(missing_ok=True)
    for stale in directory.glob(".*.tmp"):  # left by a process killed mid-write
        stale.unlink(missing_ok=True)
    return path


def has_checkpoint(directory: str | Path) -> bool:
    """Whether ``directory`` holds a checkpoint pointer (``latest.json``)."""
    return (Path(directory) / POINTER).is_file()


def resolve(path: str | Path) -> tuple[Path, str | None]:
    """The checkpoint file ``path`` designates and its expected SHA-256 (``None`` for a bare file).

    ``path`` may be a checkpoint folder, its ``latest.json``, a run directory (its ``checkpoints/``)
    or a ``.pt`` file.

    Raises:
        CheckpointError: nothing loadable there.
    """
    path = Path(path)
    if path.is_dir() and not (path / POINTER).is_file() and (path / "checkpoints" / POINTER).is_file():
        path = path / "checkpoints"
    if path.is_dir():
        path = path / POINTER
    if not path.exists():
        raise CheckpointError(f"checkpoint {str(path)!r}: no such file (expected a .pt file, a "
                              f"checkpoint folder with {POINTER}, or a run directory)")  # fmt: skip
    if path.name != POINTER:
        return path, None
    try:
        pointer = json.loads(path.read_text())
        target, sha = path.parent / str(pointer["file"]), str(pointer["sha256"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CheckpointError(f"checkpoint pointer {str(path)!r} is unreadable: {exc}") from exc
    if not target.is_file():
        raise CheckpointError(f"checkpoint pointer {str(path)!r} names {target.name!r}, which is missing")
    return target, sha


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_checkpoint` (see :func:`resolve` for ``path``).

    Tensors stay tensors (pass parts through :func:`to_numpy` where arrays are wanted).

    Raises:
        CheckpointError: missing, corrupted (checksum), truncated or not a checkpoint at all.
    """
    target, sha = resolve(path)
    data = target.read_bytes()
    if sha is not None and _sha256(data) != sha:
        raise CheckpointError(
            f"checkpoint {str(target)!r} is corrupted or truncated: its SHA-256 differs from the one "
            f"recorded in {POINTER} ({len(data)} bytes read)"
        )
    try:
        state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for a damaged file
        # not torch's message: it advises weights_only=False, i.e. unpickling an unknown file
        raise CheckpointError(
            f"checkpoint {str(target)!r} is corrupted, truncated or not an evcd checkpoint (torch cannot "
            f"read it: {type(exc).__name__}); give the checkpoints/ folder or run directory of a "
            "finished training run, or retrain"
        ) from None
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {str(target)!r} does not hold a dict (got {type(state).__name__})")
    return state


def _update(h: Any, obj: Any) -> None:
    """Feed ``obj`` (nested dicts, lists, tensors, arrays, numbers, strings) into the hash ``h``."""
    if isinstance(obj, Mapping):
        for key in sorted(obj, key=str):
            h.update(f"<{key}>".encode())
            _update(h, obj[key])
    elif isinstance(obj, list | tuple):
        h.update(f"[{len(obj)}]".encode())
        for item in obj:
            _update(h, item)
    elif isinstance(obj, torch.Tensor):
        array = obj.detach().cpu().contiguous().numpy()
        h.update(f"{array.dtype}{array.shape}".encode())
        h.update(array.tobytes())
    elif isinstance(obj, np.ndarray):
        h.update(f"{obj.dtype}{obj.shape}".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
    else:
        h.update(repr(obj).encode())


def state_sha256(state: Any) -> str:
    """Hex SHA-256 of a (nested) state: the same values in the same structure give the same digest."""
    h = hashlib.sha256()
    _update(h, state)
    return h.hexdigest()
