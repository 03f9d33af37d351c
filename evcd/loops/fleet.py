"""The fleet's episodes in the loops (:mod:`evcd.env.fleet`, played by
:class:`~evcd.env.runners.fleet.FleetRunner`): which episodes, their statistics and the trainer's rows.

Training episodes draw their day from their seed; evaluation and validation episodes take the env's
days in turn (:func:`fleet_spec`), so that ``len(days)`` consecutive episodes are on distinct days: at
``guided_share`` 1 a fleet episode is fixed by its day, and a drawn day may repeat. A fleet
episode's score is its guided EVs' mean travel time; the summary (:func:`summarize_fleet`) and the
paired comparison (:func:`paired_fleet`) also cover every EV charging in the window.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np

from evcd.agents import check_agent_task
from evcd.env.runners.base import EpisodeSpec
from evcd.env.runners.fleet import FleetEpisode
from evcd.loops.seeds import EVAL_STREAM, bootstrap_rng, episode_spec
from evcd.loops.stats import BOOTSTRAP_RESAMPLES, bootstrap_ci, finite_mean, paired_values
from evcd.loops.train_state import TrainState
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

#: The travel times compared pairwise with each baseline: the guided EVs' and everybody's.
PAIRED_MEASURES = ("guided_travel", "all_travel")


def fleet_spec(seed: int, index: int, days: int, stream: int = EVAL_STREAM) -> EpisodeSpec:
    """Fleet episode ``index`` of ``stream`` of run ``seed`` on the env's day ``index mod days`` (days in
    turn): its reset seed (which draws the guided EVs) and agents' seeds are :func:`episode_spec`'s."""
    check_int("days", days, minimum=1)
    spec = episode_spec(seed, index, stream)
    return dataclasses.replace(spec, options={"day": index % days})


def fleet_dispatcher_learns(name: Any) -> bool:
    """Whether the fleet dispatcher ``name`` learns (``ValueError`` naming the fleet's agents if the
    fleet does not take it)."""
    return check_agent_task(str(name), "fleet").learns


@dataclass(frozen=True)
class FleetSummary:
    """Statistics of a run's fleet episodes (each episode's mean is one value).

    Attributes:
        episodes: fleet episodes played.
        guided_travel: mean over episodes of the guided EVs' mean travel time (episodes where one
            charged).
        guided_travel_ci: its 95 % bootstrap interval.
        all_travel: the same over every EV charging in the window.
        all_travel_ci: its 95 % bootstrap interval.
        queue_wait, herding, guided_travel_censored: means over episodes (:mod:`evcd.env.fleet.measures`).
        guided, truncated, all_unfinished, transitions: totals over episodes.
        mean_wall_s: mean wall-clock seconds per episode.
        distinct_episodes: episodes that differ in day or guided EVs (:func:`distinct_episodes`).
    """

    episodes: int
    guided_travel: float
    guided_travel_ci: tuple[float, float]
    all_travel: float
    all_travel_ci: tuple[float, float]
    queue_wait: float
    herding: float
    guided_travel_censored: float
    guided: int
    truncated: int
    all_unfinished: int
    transitions: int
    mean_wall_s: float
    distinct_episodes: int


def summarize_fleet(
    played: Sequence[FleetEpisode], rng: np.random.Generator, resamples: int = BOOTSTRAP_RESAMPLES
) -> FleetSummary:
    """The :class:`FleetSummary` of ``played`` (intervals drawn from ``rng``: the guided EVs' first).

    A warning says when episodes repeat: at ``guided_share`` 1 nothing is drawn, so an episode is
    fixed by its day and two episodes of one day are the same episode played twice (a deterministic
    policy then repeats its result, and the interval counts the copies as independent)."""
    means, intervals = {}, {}
    for key in ("guided_travel", "all_travel", "queue_wait", "herding", "guided_travel_censored"):
        values = np.array([getattr(ep.measures, key) for ep in played], dtype=np.float64)
        finite = values[np.isfinite(values)]
        means[key] = float(finite.mean()) if finite.size else math.nan
        if key in ("guided_travel", "all_travel"):
            intervals[f"{key}_ci"] = bootstrap_ci(finite, rng, resamples)
    distinct = distinct_episodes(played)
    if distinct < len(played):
        log.warning(
            "only %d of %d fleet episodes differ in day or guided EVs (at guided_share 1 an episode is "
            "fixed by its day): the interval counts the repeats as independent episodes; evaluate on at "
            "least as many days as episodes, or with a guided_share below 1", distinct, len(played),
        )  # fmt: skip
    return FleetSummary(
        episodes=len(played),
        **means,
        **intervals,
        guided=sum(ep.measures.guided for ep in played),
        truncated=sum(ep.measures.truncated for ep in played),
        all_unfinished=sum(ep.measures.all_unfinished for ep in played),
        transitions=sum(ep.transitions for ep in played),
        mean_wall_s=float(np.mean([ep.wall_s for ep in played])),
        distinct_episodes=distinct,
    )


def paired_fleet(
    played: Sequence[FleetEpisode], baseline: Sequence[FleetEpisode], seed: int,
    resamples: int = BOOTSTRAP_RESAMPLES,
) -> dict[str, dict[str, Any]]:  # fmt: skip
    """Per measure of :data:`PAIRED_MEASURES`, the agent minus the baseline on the same fleet episodes
    (:func:`~evcd.loops.stats.paired_values`; each interval from the run's bootstrap stream).

    Raises:
        ValueError: the two lists are not the same episodes (index and day) in the same order.
    """
    if [(e.index, e.day) for e in played] != [(e.index, e.day) for e in baseline]:
        raise ValueError("paired comparison: the agent's and the baseline's fleet episodes differ")
    return {key: paired_values([getattr(e.measures, key) for e in played],
                               [getattr(e.measures, key) for e in baseline], bootstrap_rng(seed), resamples)
            for key in PAIRED_MEASURES}  # fmt: skip


def distinct_episodes(played: Sequence[FleetEpisode]) -> int:
    """How many of ``played`` differ in their day or in the set of guided EVs that became agents
    (episodes equal in both are the same deterministic episode)."""
    return len({(ep.day, frozenset(ep.returns)) for ep in played})


@dataclass
class FleetTrainState(TrainState):
    """Where fleet training stands: :class:`~evcd.loops.train_state.TrainState` whose rows are the
    flat :meth:`FleetEpisode.row`\\ s, under a checkpoint format of its own."""

    FORMAT: ClassVar[str] = "evcd.fleet_train/1"

    def record(self, row: FleetEpisode) -> None:
        """Keep a training fleet episode's flat row (:meth:`FleetEpisode.row`)."""
        self.rows.append(row.row())

    def charged_travel(self) -> list[float]:
        """The guided EVs' mean travel time of each training episode where one charged."""
        return [t for r in self.rows if math.isfinite(t := float(r["guided_travel"]))]

    def row_dicts(self) -> list[dict[str, Any]]:
        """The training rows (``train_fleet_episodes.csv``, the checkpoint)."""
        return [dict(r) for r in self.rows]

    def curve_rows(self) -> list[Any]:
        """Per training episode, the guided EVs' mean travel time and switches per guided EV."""
        out = []
        for r in self.rows:
            travel = float(r["guided_travel"])
            out.append(SimpleNamespace(travel_time=travel, truncated=not math.isfinite(travel),
                                       switches=float(r["switches"])))  # fmt: skip
        return out

    def summary(self) -> dict[str, Any]:
        """The guided EVs' mean travel time over the training episodes where one charged."""
        return {"mean_guided_travel": finite_mean([float(r["guided_travel"]) for r in self.rows])}

    @classmethod
    def row_from_dict(cls, d: Mapping[str, Any]) -> Any:
        """A training row back from the checkpoint (kept flat)."""
        return dict(d)
