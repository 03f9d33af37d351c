"""Where a training run stands, and how it survives being killed: checkpoints and resume.

Every ``checkpoint_every`` episodes and at the end the trainer writes the agent (networks, optimizer,
replay, counters, generators), the trainer's position (:class:`TrainState`: episodes done, their
rows) and the run's config, atomically (:mod:`evcd.utils.checkpoint`). A resumed run loads them and
refuses a config that differs (but in :data:`RESUME_FREE_KEYS`); since an episode depends only on its
seed and the agent's state, it ends with exactly the weights of an uninterrupted run. A new run never
enters a directory that holds a checkpoint or results (:func:`check_run_dir`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, Self, TypeVar

import numpy as np

from evcd.agents.base import Agent
from evcd.env.runners.base import EpisodeRow
from evcd.loops.run_files import CHECKPOINTS, OUTPUTS, RESULTS_JSON, TENSORBOARD
from evcd.loops.train_log import TrainLog
from evcd.loops.validation import ValidationRecord
from evcd.utils.checkpoint import CheckpointError, has_checkpoint, load_checkpoint, save_checkpoint
from evcd.utils.removed import drop_removed

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "evcd.train/1"
#: Config keys that may differ between a run and its resumption.
RESUME_FREE_KEYS = frozenset({"resume", "progress"})


class SavedState(Protocol):
    """A trainer's position as saved in its checkpoints (:class:`TrainState`, and the fleet's
    :class:`~evcd.loops.fleet.FleetTrainState`)."""

    FORMAT: ClassVar[str]
    episodes_done: int
    transitions: int

    def to_dict(self) -> dict[str, Any]: ...


S = TypeVar("S", bound="TrainState")


@dataclass
class TrainState:
    """Where training stands (saved in every checkpoint). The single target's rows are
    :class:`EpisodeRow`\\ s; the fleet's state (:class:`~evcd.loops.fleet.FleetTrainState`) keeps its own
    form of row and a checkpoint format of its own."""

    FORMAT: ClassVar[str] = CHECKPOINT_FORMAT
    episodes_done: int = 0
    transitions: int = 0
    wall_s: float = 0.0  # training wall time over every session (day builds excluded)
    prepare_s: float = 0.0  # day builds of the training runner
    sessions: int = 0  # how many times training was started or resumed
    validation_s: float = 0.0  # wall time of the periodic validations (not in wall_s)
    rows: list[Any] = dataclasses.field(default_factory=list)
    validation: ValidationRecord = dataclasses.field(default_factory=ValidationRecord)

    def record(self, row: EpisodeRow) -> None:
        """Keep a training episode's row."""
        self.rows.append(row)

    def charged_travel(self) -> list[float]:
        """The travel times of the training episodes that ended charging."""
        return [r.travel_time for r in self.rows if not r.truncated]

    def row_dicts(self) -> list[dict[str, Any]]:
        """The training rows as plain values (``train_episodes.csv``, the checkpoint)."""
        return [r.row() for r in self.rows]

    def curve_rows(self) -> list[Any]:
        """The training rows as the learning curve reads them (``travel_time``, ``truncated``,
        ``switches``)."""
        return list(self.rows)

    def summary(self) -> dict[str, Any]:
        """What ``results.json`` reports of the training episodes (beside :func:`training_counters`)."""
        charged = self.charged_travel()
        return {
            "truncated": sum(r.truncated for r in self.rows),
            "mean_travel_time": float(np.mean(charged)) if charged else math.nan,
            "mean_switches": float(np.mean([r.switches for r in self.rows])) if self.rows else math.nan,
        }

    @classmethod
    def row_from_dict(cls, d: Mapping[str, Any]) -> Any:
        """A training row back from :meth:`row_dicts`."""
        return EpisodeRow(**d)

    def to_dict(self) -> dict[str, Any]:
        """Plain values for the checkpoint."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["rows"] = self.row_dicts()
        d["validation"] = self.validation.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Self:
        """The inverse of :meth:`to_dict`."""
        values = dict(d)
        values["rows"] = [cls.row_from_dict(r) for r in values["rows"]]
        values["validation"] = ValidationRecord.from_dict(values.get("validation"))
        return cls(**values)


def training_counters(stats: Mapping[str, Any], state: Any, episodes: int) -> dict[str, Any]:
    """What every trainer reports of its training in ``results.json`` (``training``): ``state`` (a
    :class:`TrainState` or the fleet's) and the agent's :meth:`~evcd.agents.Agent.stats` (empty for
    the hindsight bound)."""
    return {
        "episodes": episodes,
        "episodes_done": state.episodes_done,
        "transitions": state.transitions,
        "wall_s": state.wall_s,
        "day_build_s": state.prepare_s,
        "sessions": state.sessions,
        "transitions_per_second": state.transitions / state.wall_s if state.wall_s > 0 else math.nan,
        "gradient_steps": int(stats.get("gradient_steps", 0)),
        "target_updates": int(stats.get("target_updates", 0)),
        "final_epsilon": stats.get("epsilon", math.nan),
        "validation_s": state.validation_s,
    }


def start_run(
    run_dir: Path,
    agent: Any,
    resume: bool,
    config: Mapping[str, Any] | None,
    state_cls: type[S],
    on_start: Callable[[], None] | None = None,
) -> tuple[S, TrainLog]:
    """Enter ``run_dir`` for a new run or to resume one: the trainer's position (the checkpoint's with
    ``resume`` and an ``agent`` that learns, else a fresh ``state_cls()``) and the run's TensorBoard log
    (a resumed run hides what the interrupted one wrote after its checkpoint; a new one records the
    config). The caller closes the log. ``on_start`` is called once every check passed, before anything
    is written (the scripts write the run's Hydra record then: a refused run leaves the directory as
    it was).

    Raises:
        FileExistsError, FileNotFoundError: see :func:`check_run_dir`; or a resume of a complete run.
        ValueError, CheckpointError: see :func:`restore_training`.
    """
    check_run_dir(run_dir, resume)
    if resume and (run_dir / RESULTS_JSON).exists():
        raise FileExistsError(f"{run_dir / RESULTS_JSON} exists: that run is complete (nothing to resume)")
    run_dir.mkdir(parents=True, exist_ok=True)
    state = state_cls()
    if agent.learns and resume and has_checkpoint(run_dir / CHECKPOINTS):
        state = restore_training(run_dir, agent, config, state_cls)
    if on_start is not None:
        on_start()
    tlog = TrainLog(run_dir / TENSORBOARD, purge_step=state.transitions if resume else None)
    if not resume:
        tlog.config(config or {}, repr(agent))
    return state, tlog


def check_run_dir(run_dir: Path, resume: bool) -> None:
    """Refuse to start a new run where one already wrote, or to resume where nothing was written.

    Raises:
        FileExistsError: a new run (``resume=False``) in a directory holding a checkpoint or results.
        FileNotFoundError: ``resume=True`` but the directory holds no checkpoint and no results.
    """
    ckpt = run_dir / CHECKPOINTS
    written = sorted(p.name for pattern in OUTPUTS for p in run_dir.glob(pattern))
    if not resume and (has_checkpoint(ckpt) or written):
        found = "a checkpoint" if has_checkpoint(ckpt) else ", ".join(written)
        raise FileExistsError(
            f"{run_dir} already holds {found}: pass resume=true to continue that run, or use a new "
            "run directory (nothing there is overwritten)"
        )
    if resume and not has_checkpoint(ckpt) and not (run_dir / RESULTS_JSON).exists():
        raise FileNotFoundError(
            f"resume=true but {run_dir} holds no checkpoint ({ckpt / 'latest.json'} is missing): "
            "resume needs the run directory of an earlier training run (hydra.run.dir=...)"
        )


def config_diff(
    saved: Mapping[str, Any], current: Mapping[str, Any], prefix: str = "", what: str = "resume"
) -> list[str]:
    """``"key: saved -> current"`` for every setting that differs (nested keys dotted), but those of
    :data:`RESUME_FREE_KEYS` and a setting the saved run did not have that is off now (``false``,
    ``null``, ``[]`` or a number 0, e.g. a margin): an option added to evcd since the checkpoint, at
    the value that keeps what the run did (evcd's options are off by default; logged, beginning with
    ``what``)."""
    keys = sorted(set(saved) | set(current))
    out = []
    for key in keys:
        name = f"{prefix}{key}"
        if not prefix and key in RESUME_FREE_KEYS:
            continue
        a, b = saved.get(key, "<missing>"), current.get(key, "<missing>")
        if key not in saved and _is_off(b):
            log.info("%s: %s=%r is new since the checkpoint's run; off, as that run was", what, name, b)
            continue
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += config_diff(a, b, f"{name}.", what)
        elif a != b:
            out.append(f"{name}: {a!r} -> {b!r}")
    return out


def _is_off(value: Any) -> bool:
    """``False``, ``None``, an empty list or a number 0 (not a bool): an option that is off."""
    zero = isinstance(value, int | float) and not isinstance(value, bool) and value == 0
    return value is False or value is None or zero or (isinstance(value, list | tuple) and not value)


def checkpoint_name(episodes_done: int) -> str:
    """The stem of a run's checkpoint after ``episodes_done`` training episodes (``ckpt_0001200``)."""
    return f"ckpt_{episodes_done:07d}"


def save_training(
    run_dir: Path, agent: Agent, state: SavedState, config: Mapping[str, Any] | None, keep: Sequence[int] = ()
) -> None:
    """Write the agent, the trainer's position (its class's ``FORMAT``) and the config as the run's
    latest checkpoint; the older ones are dropped but those after ``keep`` episodes (the validated
    policies: :func:`checkpoint_name`)."""
    payload = {
        "format": state.FORMAT,
        "agent": agent.state_dict(),
        "trainer": state.to_dict(),
        "config": dict(config) if config is not None else None,
    }
    kept = [checkpoint_name(n) for n in keep]
    path = save_checkpoint(run_dir / CHECKPOINTS, payload, checkpoint_name(state.episodes_done), kept)
    log.info("checkpoint after %d episodes: %s", state.episodes_done, path)


def restore_training(
    run_dir: Path, agent: Agent, config: Mapping[str, Any] | None, state_cls: type[S] = TrainState
) -> S:
    """Load the run's latest checkpoint into ``agent``; the trainer's position (a ``state_cls``).

    Raises:
        CheckpointError: not a checkpoint of ``state_cls``'s trainer (its ``FORMAT``), or damaged.
        ValueError: ``config`` differs from the checkpoint's run (the message names each difference),
            or that run used a setting which has left evcd (:mod:`evcd.utils.removed`).
    """
    payload = load_checkpoint(run_dir / CHECKPOINTS)
    expected = state_cls.FORMAT
    if payload.get("format") != expected:
        raise CheckpointError(f"{run_dir / CHECKPOINTS}: not a checkpoint of this trainer (format "
                              f"{payload.get('format')!r}, expected {expected!r})")  # fmt: skip
    saved = payload.get("config")
    if config is not None and saved is not None:
        diff = config_diff(drop_removed(saved), config)
        if diff:
            raise ValueError(
                "resume=true with settings that differ from the checkpoint's run (a resumed run "
                "must continue the same experiment): " + "; ".join(diff)
            )
    agent.load_state_dict(payload["agent"])
    state = state_cls.from_dict(payload["trainer"])
    log.info("resuming after %d training episodes (%d transitions)", state.episodes_done, state.transitions)
    return state
