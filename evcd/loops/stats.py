"""Statistics of a run's episodes: the bootstrap interval of a mean, a run's summary, and the paired
difference of two dispatchers on the same episodes.

Only episodes that end by charging enter the travel-time statistics; truncated ones are counted
apart. Every interval is a percentile bootstrap drawn from a generator handed in (the run's
bootstrap stream, :func:`evcd.loops.seeds.bootstrap_rng`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evcd.env.runners.base import EpisodeRow
from evcd.utils.validation import check_int, check_real


def finite_mean(values: Sequence[float]) -> float:
    """The mean of the finite values (a truncated episode's NaN left out); NaN if there is none."""
    charged = [v for v in values if math.isfinite(v)]
    return float(np.mean(charged)) if charged else math.nan


BOOTSTRAP_RESAMPLES = 10_000


@dataclass(frozen=True)
class EvalSummary:
    """Statistics of a run. Travel-time statistics cover the non-truncated episodes only (NaN if none).

    Attributes:
        episodes: episodes run.
        completed: episodes that ended with the target charging.
        truncated: episodes that did not.
        mean_travel_time: mean ``T_travel`` (s).
        median_travel_time: median ``T_travel`` (s).
        ci_low: lower end of the bootstrap confidence interval of the mean (s).
        ci_high: upper end.
        ci_level: the interval's confidence level.
        mean_queue_wait: mean queueing time (s).
        mean_return: mean episode return (all episodes).
        mean_wall_s: mean wall-clock seconds per episode (all episodes).
    """

    episodes: int
    completed: int
    truncated: int
    mean_travel_time: float
    median_travel_time: float
    ci_low: float
    ci_high: float
    ci_level: float
    mean_queue_wait: float
    mean_return: float
    mean_wall_s: float


@dataclass(frozen=True)
class EvalResult:
    """Rows and summary of :func:`~evcd.loops.evaluate.evaluate`: the single target's
    (:class:`EpisodeRow` rows, an :class:`EvalSummary`) or the fleet's
    (:class:`~evcd.env.runners.fleet.FleetEpisode` rows, a :class:`~evcd.loops.fleet.FleetSummary`)."""

    agent: str
    seed: int
    rows: tuple[Any, ...]
    summary: Any
    #: the agent's :meth:`~evcd.agents.Agent.report` (e.g. hindsight's station per episode)
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    #: the episodes' task (:mod:`evcd.loops.tasks`)
    task: str = "single"


def bootstrap_ci(
    values: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    resamples: int = BOOTSTRAP_RESAMPLES,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the mean of ``values``.

    Vectorised: one ``(resamples, n)`` index draw. ``(nan, nan)`` for no values; a single value gives
    a zero-width interval.

    Raises:
        ValueError: ``resamples < 1``, ``level`` outside (0, 1), or non-finite values.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"values of shape {x.shape}: must be one-dimensional")
    check_int("resamples", resamples, minimum=1)
    check_real("level", level, low=0.0, high=1.0, low_open=True, high_open=True)
    if not np.isfinite(x).all():
        raise ValueError("values: must all be finite")
    if x.size == 0:
        return math.nan, math.nan
    # chunked so that n x resamples indices stay within a few MB
    chunk = max(1, 2_000_000 // x.size)
    means = np.concatenate(
        [x[rng.integers(x.size, size=(min(chunk, resamples - i), x.size))].mean(axis=1)
         for i in range(0, resamples, chunk)]
    )  # fmt: skip
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(means, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def summarize(
    rows: Sequence[EpisodeRow],
    rng: np.random.Generator,
    resamples: int = BOOTSTRAP_RESAMPLES,
    level: float = 0.95,
) -> EvalSummary:
    """The :class:`EvalSummary` of ``rows`` (bootstrap drawn from ``rng``)."""
    done = [r for r in rows if not r.truncated]
    travel = np.array([r.travel_time for r in done], dtype=np.float64)
    lo, hi = bootstrap_ci(travel, rng, resamples, level)

    def mean(values: list[float]) -> float:
        return float(np.mean(values)) if values else math.nan

    return EvalSummary(
        episodes=len(rows),
        completed=len(done),
        truncated=len(rows) - len(done),
        mean_travel_time=mean(list(travel)),
        median_travel_time=float(np.median(travel)) if travel.size else math.nan,
        ci_low=lo,
        ci_high=hi,
        ci_level=level,
        mean_queue_wait=mean([r.queue_wait for r in done]),
        mean_return=mean([r.episode_return for r in rows]),
        mean_wall_s=mean([r.wall_s for r in rows]),
    )


def paired_difference(
    agent_rows: Sequence[EpisodeRow],
    baseline_rows: Sequence[EpisodeRow],
    rng: np.random.Generator,
    resamples: int = BOOTSTRAP_RESAMPLES,
) -> dict[str, Any]:
    """Agent minus baseline travel time on the same episodes (those both ended charging).

    Negative means the agent is faster. Returns the mean difference with its percentile bootstrap
    95% interval, the number of pairs, and how often the agent was faster, equal or slower.

    Raises:
        ValueError: the rows are not the same episodes (seeds) in the same order.
    """
    if [r.seed for r in agent_rows] != [r.seed for r in baseline_rows]:
        raise ValueError("paired comparison: the agent's and the baseline's episodes differ")
    pairs = [(a.travel_time, b.travel_time) for a, b in zip(agent_rows, baseline_rows, strict=True)
             if not a.truncated and not b.truncated]  # fmt: skip
    return paired_values([a for a, _ in pairs], [b for _, b in pairs], rng, resamples)


def paired_values(
    agent: Sequence[float],
    baseline: Sequence[float],
    rng: np.random.Generator,
    resamples: int = BOOTSTRAP_RESAMPLES,
) -> dict[str, Any]:
    """Agent minus baseline over paired values (the same episodes, in the same order); pairs where
    either value is not finite (NaN: nothing to measure) are left out.

    Negative means the agent's value is lower. Returns the mean difference with its percentile
    bootstrap 95% interval, the number of pairs, and how often the agent was lower, equal or higher.

    Raises:
        ValueError: the two sequences differ in length.
    """
    if len(agent) != len(baseline):
        raise ValueError(f"paired comparison: {len(agent)} values against {len(baseline)}")
    pairs = [(float(a), float(b)) for a, b in zip(agent, baseline, strict=True)
             if math.isfinite(a) and math.isfinite(b)]  # fmt: skip
    diff = np.array([a - b for a, b in pairs], dtype=np.float64)
    lo, hi = bootstrap_ci(diff, rng, resamples)
    return {
        "pairs": len(pairs),
        "mean_difference": float(diff.mean()) if diff.size else math.nan,
        "ci_low": lo,
        "ci_high": hi,
        "agent_mean": float(np.mean([a for a, _ in pairs])) if pairs else math.nan,
        "baseline_mean": float(np.mean([b for _, b in pairs])) if pairs else math.nan,
        "agent_faster": int((diff < 0).sum()),
        "equal": int((diff == 0).sum()),
        "agent_slower": int((diff > 0).sum()),
    }
