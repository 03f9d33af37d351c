"""Periodic held-out evaluation during training: a curve that shows learning, not the time of day.

The training curve of a run plays each call's episodes in the order of their departures, so it
rises and falls with the peaks of the day. The validation curve does not: every ``every`` training
episodes the current policy, without exploration and without learning, plays the same fixed set of
validation episodes (the task's first ``episodes`` of stream
:data:`~evcd.loops.seeds.VALIDATION_STREAM` of the run seed, on the validation days:
:meth:`evcd.loops.tasks.Task.specs`), and the rules (greedy, queue_aware) play the very same
episodes once, so that each point of the curve is comparable with the others and with the rules.

The validation neither explores nor learns and draws from generators of its own, so a run with it
trains to exactly the weights of a run without it (tested). With ``select_best`` the run evaluates
the policy of its best validation instead of its last (:mod:`evcd.loops.best_policy`): model
selection on the tuning days, which never touches the evaluation days.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from evcd.agents.base import Agent
from evcd.env.runners import EpisodeRunner, EpisodeSpec
from evcd.loops.stats import finite_mean
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ValidationSettings:
    """When and on what the policy is validated during training.

    Attributes:
        every: training episodes between two validations (0: none); a multiple of the run's
            ``checkpoint_every``, so that validating does not change how training episodes are
            grouped into engine calls.
        episodes: validation episodes.
        select_best: evaluate the policy of the best validation (fewest truncated validation
            episodes, then the lowest mean travel time; the earliest on a tie) instead of the last.
    """

    every: int = 0
    episodes: int = 30
    select_best: bool = False

    def __post_init__(self) -> None:
        check_int("train.validation.every", self.every, minimum=0)
        check_int("train.validation.episodes", self.episodes, minimum=1)
        if not isinstance(self.select_best, bool):
            raise ValueError(f"train.validation.select_best={self.select_best!r}: must be true or false")
        if self.select_best and not self.every:
            raise ValueError("train.validation.select_best=true needs a validation to select by: set "
                             "train.validation.every > 0")  # fmt: skip

    def due(self, episodes_done: int, total: int) -> bool:
        """Whether a validation follows ``episodes_done`` of ``total`` training episodes (and always
        the last), for either task's trainer."""
        return self.every > 0 and (episodes_done % self.every == 0 or episodes_done == total)


@dataclass
class ValidationPoint:
    """The policy's validation after ``episodes_done`` training episodes (``transitions`` seen)."""

    episodes_done: int
    transitions: int
    travel_times: list[float]  # per validation episode; NaN where it was truncated

    @property
    def mean(self) -> float:
        """Mean travel time over the episodes that charged (NaN if none)."""
        return finite_mean(self.travel_times)

    @property
    def truncated(self) -> int:
        """Validation episodes that ended without a charge."""
        return sum(not math.isfinite(t) for t in self.travel_times)

    def rank(self) -> tuple[int, float]:
        """Sort key of the best validation: fewest truncated episodes, then the lowest mean."""
        mean = self.mean
        return self.truncated, mean if math.isfinite(mean) else math.inf


@dataclass
class ValidationRecord:
    """Every validation of a run and the rules' travel times on the same episodes (saved in the
    training checkpoints, so that a resumed run keeps its curve)."""

    points: list[ValidationPoint] = field(default_factory=list)
    rules: dict[str, list[float]] = field(default_factory=dict)

    def best(self) -> ValidationPoint | None:
        """The best point (:meth:`ValidationPoint.rank`; the earliest on a tie), ``None`` before any."""
        return min(self.points, key=ValidationPoint.rank) if self.points else None

    def to_dict(self) -> dict[str, Any]:
        """Plain values (NaN as ``None``: strict JSON)."""

        def plain(values: list[float]) -> list[float | None]:
            return [v if math.isfinite(v) else None for v in values]

        return {
            "points": [{"episodes_done": p.episodes_done, "transitions": p.transitions,
                        "mean": p.mean if math.isfinite(p.mean) else None,
                        "travel_times": plain(p.travel_times)} for p in self.points],
            "rules": {name: plain(times) for name, times in self.rules.items()},
            "rule_means": {name: _json(finite_mean(times)) for name, times in self.rules.items()},
            "best_episodes_done": best.episodes_done if (best := self.best()) is not None else None,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> ValidationRecord:
        """The inverse of :meth:`to_dict`."""
        if not d:
            return cls()

        def floats(values: list[Any]) -> list[float]:
            return [math.nan if v is None else float(v) for v in values]

        points = [ValidationPoint(int(p["episodes_done"]), int(p["transitions"]), floats(p["travel_times"]))
                  for p in d.get("points", [])]  # fmt: skip
        return cls(points, {name: floats(times) for name, times in d.get("rules", {}).items()})


def _json(value: float) -> float | None:
    return value if math.isfinite(value) else None


def travel_times(rows: Sequence[Any]) -> list[float]:
    """The validation values of ``rows``: each row's ``travel_time``, NaN where it is ``truncated``."""
    return [math.nan if r.truncated else float(r.travel_time) for r in rows]


class Validator:
    """Plays the validation episodes (see the module docstring).

    Args:
        runners: makes the validation runner (``runners("validation")``); made and closed per
            validation (libsumo: one simulation per process, the training runner's is closed first).
        settings: how often and how many episodes.
        rules: the rules validated once on the same episodes, by name.
        specs: ``specs(runner)`` -> the validation episodes (the same at every validation; the run's
            task says which: :meth:`evcd.loops.tasks.Task.specs` of the validation stream).
        played: ``played()`` -> rules' values played elsewhere on the same episodes (by name; a second
            process: :mod:`evcd.loops.beside`), asked for at the first validation; those rules are not
            played here.

    A validation value is a row's ``travel_time`` (NaN where it is ``truncated``): the target's travel
    time, or a fleet episode's guided EVs' mean.
    """

    def __init__(
        self,
        runners: Callable[[str], EpisodeRunner],
        settings: ValidationSettings,
        rules: Mapping[str, Agent],
        specs: Callable[[EpisodeRunner], list[EpisodeSpec]],
        played: Callable[[], Mapping[str, list[float]]] | None = None,
    ) -> None:
        self.runners = runners
        self.settings = settings
        self.rules = dict(rules)
        self.specs = specs
        self.played = played

    def due(self, episodes_done: int, total: int) -> bool:
        """Whether a validation follows ``episodes_done`` training episodes (and always the last)."""
        return self.settings.due(episodes_done, total)

    def validate(self, agent: Agent, episodes_done: int, transitions: int, record: ValidationRecord) -> None:
        """Play the validation episodes with ``agent`` (and, the first time, the rules); add a point."""
        if self.played is not None and any(name not in record.rules for name in self.rules):
            for name, values in self.played().items():
                record.rules.setdefault(name, list(values))
        runner = self.runners("validation")
        specs = self.specs(runner)
        try:
            runner.prepare()
            for name, rule in self.rules.items():
                if name not in record.rules:
                    record.rules[name] = travel_times(runner.run(specs, rule))
            rows = runner.run(specs, agent)
        finally:
            runner.close()
        point = ValidationPoint(episodes_done, transitions, travel_times(rows))
        record.points.append(point)
        rules = ", ".join(f"{n} {finite_mean(t):.1f} s" for n, t in record.rules.items())
        log.info("validation after %d episodes: %.1f s over %d episodes (%s)", episodes_done, point.mean,
                 len(rows), rules)  # fmt: skip
