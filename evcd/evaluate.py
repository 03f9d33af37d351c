"""Run an agent for a number of episodes and summarise its travel times.

    result = evaluate(env, agent, episodes=50, seed=0)
    write_episodes_csv(result, run_dir / "episodes.csv")
    write_results_json(result, run_dir / "results.json", config=...)

Seeds: everything derives from the run seed through ``numpy.random.SeedSequence`` spawn keys, so an
episode depends only on ``(seed, i)``, never on the episodes run before it:

- episode ``i``: ``SeedSequence(seed, spawn_key=(0, i))`` gives the ``env.reset`` seed and the
  generator handed to ``agent.begin_episode`` (see :func:`episode_seed`);
- the bootstrap: ``SeedSequence(seed, spawn_key=(1,))``.

Only episodes that end by charging (``terminated``) enter the travel-time statistics; truncated ones
are counted and listed. The agent never learns here: :meth:`Agent.observe` is not called.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from tqdm import tqdm

from evcd.agents.base import Agent
from evcd.atomic import atomic_write_text

log = logging.getLogger(__name__)

BOOTSTRAP_RESAMPLES = 10_000
_EPISODE_KEY = 0
_BOOTSTRAP_KEY = 1


@dataclass(frozen=True)
class EpisodeRow:
    """One evaluated episode (a row of ``episodes.csv``).

    Attributes:
        episode: index in the run (0-based).
        seed: the ``env.reset`` seed (reproduces the target and the background day).
        departure: the target's departure (s of day).
        origin: the target's origin edge.
        day: the background day's demand seed.
        choices: the action of every slot, joined by ``-`` (e.g. ``"2-2-4"``).
        station: the station index the target ended at (last choice).
        station_id: that station's id.
        travel_time: seconds from departure to the start of charging (to the end if truncated).
        queue_wait: seconds the target waited in car parks.
        reason: why the episode ended (``"charging"`` or a truncation reason of the env).
        truncated: the episode ended without charging.
        episode_return: sum of the rewards.
        wall_s: wall-clock seconds of the episode (reset included).
    """

    episode: int
    seed: int
    departure: float
    origin: str
    day: int
    choices: str
    station: int
    station_id: str
    travel_time: float
    queue_wait: float
    reason: str
    truncated: bool
    episode_return: float
    wall_s: float


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
    """Rows and summary of :func:`evaluate`."""

    agent: str
    seed: int
    rows: tuple[EpisodeRow, ...]
    summary: EvalSummary


# ---------------------------------------------------------------------------------------- seeds
def episode_seed(seed: int, episode: int) -> tuple[int, np.random.Generator]:
    """The ``env.reset`` seed and the agent's generator of episode ``episode`` of run ``seed``."""
    env_ss, agent_ss = np.random.SeedSequence(seed, spawn_key=(_EPISODE_KEY, episode)).spawn(2)
    reset_seed = int(env_ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))  # fits int64
    return reset_seed, np.random.default_rng(agent_ss)


def bootstrap_rng(seed: int) -> np.random.Generator:
    """The generator of a run's bootstrap."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_BOOTSTRAP_KEY,)))


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed={seed!r}: must be an integer >= 0")
    return int(seed)


# ---------------------------------------------------------------------------------------- statistics
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
    if resamples < 1:
        raise ValueError(f"resamples={resamples}: must be >= 1")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level={level}: must be in (0, 1)")
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


# ---------------------------------------------------------------------------------------- the loop
def run_episode(
    env: gymnasium.Env, agent: Agent, episode: int, seed: int, explore: bool = False
) -> EpisodeRow:
    """Run episode ``episode`` of run ``seed`` to its end; return its row."""
    reset_seed, agent_rng = episode_seed(seed, episode)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=reset_seed)
    agent.begin_episode(agent_rng)
    choices: list[int] = []
    total = 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        action = agent.act(obs, explore=explore)
        choices.append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
    return EpisodeRow(
        episode=episode,
        seed=reset_seed,
        departure=float(info["departure"]),
        origin=str(info.get("origin", "")),
        day=int(info.get("day", -1)),
        choices="-".join(map(str, choices)),
        station=-1 if info.get("station") is None else int(info["station"]),
        station_id=str(info.get("station_id", "")),
        travel_time=float(info["travel_time"]),
        queue_wait=float(info["queue_wait"]),
        reason=str(info["reason"]),
        truncated=bool(truncated and not terminated),
        episode_return=total,
        wall_s=time.perf_counter() - t0,
    )


def evaluate(
    env: gymnasium.Env,
    agent: Agent,
    episodes: int,
    seed: int,
    progress: bool = True,
    resamples: int = BOOTSTRAP_RESAMPLES,
) -> EvalResult:
    """Run ``agent`` for ``episodes`` episodes of ``env``, without exploration or learning.

    Args:
        env: a :class:`~evcd.env.ChargingNavEnv` (or any env with its ``info`` keys).
        agent: the dispatcher.
        episodes: number of episodes (>= 1).
        seed: the run seed (>= 0); see the module docstring for what derives from it.
        progress: show a tqdm progress bar (on stderr).
        resamples: bootstrap resamples of the confidence interval.

    Raises:
        ValueError: ``episodes`` or ``seed`` out of range.
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int | np.integer) or episodes < 1:
        raise ValueError(f"episodes={episodes!r}: must be an integer >= 1")
    seed = _check_seed(seed)
    rows: list[EpisodeRow] = []
    bar = tqdm(
        range(int(episodes)), desc=f"evaluate {agent.name}", unit="ep", mininterval=2, disable=not progress
    )
    for i in bar:
        row = run_episode(env, agent, i, seed)
        rows.append(row)
        log.debug("episode %d: %s", i, row)
        done = [r.travel_time for r in rows if not r.truncated]
        bar.set_postfix(
            mean_T=f"{np.mean(done):.0f}s" if done else "-", truncated=len(rows) - len(done), refresh=False
        )
    bar.close()
    summary = summarize(rows, bootstrap_rng(seed), resamples)
    return EvalResult(agent=agent.name, seed=seed, rows=tuple(rows), summary=summary)


# ---------------------------------------------------------------------------------------- writers
CSV_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(EpisodeRow))


def _refuse_clobber(path: Path, overwrite: bool) -> None:
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists: refusing to overwrite it (pass overwrite=True)")


def episodes_csv_text(rows: Sequence[EpisodeRow]) -> str:
    """``rows`` as CSV text with a header (floats written with ``repr`` precision)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow(dataclasses.asdict(row))
    return buf.getvalue()


def write_episodes_csv(result: EvalResult, path: str | Path, overwrite: bool = False) -> Path:
    """Write the per-episode rows to ``path`` atomically.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    _refuse_clobber(path, overwrite)
    return atomic_write_text(path, episodes_csv_text(result.rows))


def _json_safe(value: Any) -> Any:
    """NaN/inf -> None (strict JSON has no NaN), recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


def results_dict(result: EvalResult, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The content of ``results.json``: agent, seed, summary, per-episode rows, optional config."""
    return _json_safe(
        {
            "agent": result.agent,
            "seed": result.seed,
            "summary": dataclasses.asdict(result.summary),
            "episodes": [dataclasses.asdict(r) for r in result.rows],
            "config": dict(config) if config is not None else None,
        }
    )


def write_results_json(
    result: EvalResult, path: str | Path, config: Mapping[str, Any] | None = None, overwrite: bool = False
) -> Path:
    """Write :func:`results_dict` to ``path`` atomically (strict JSON: NaN becomes ``null``).

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    _refuse_clobber(path, overwrite)
    text = json.dumps(results_dict(result, config), indent=1, allow_nan=False)
    return atomic_write_text(path, text + "\n")
