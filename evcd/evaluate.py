"""Run an agent for a number of episodes and summarise its travel times.

    result = evaluate(env, agent, episodes=50, seed=0)
    write_episodes_csv(result, run_dir / "episodes.csv")
    write_results_json(result, run_dir / "results.json", config=...)

Seeds: everything derives from the run seed through ``numpy.random.SeedSequence`` spawn keys, so an
episode depends only on ``(seed, stream, i)``, never on the episodes run before it:

- evaluation episode ``i``: ``SeedSequence(seed, spawn_key=(0, i))`` gives the ``env.reset`` seed
  and the generator handed to ``agent.begin_episode`` (see :func:`episode_spec`);
- the bootstrap: ``SeedSequence(seed, spawn_key=(1,))``; the agent's own generator in the scripts:
  ``spawn_key=(2,)``; training episodes (:mod:`evcd.train`): ``spawn_key=(3, i)``, a stream disjoint
  from the evaluation episodes'.

Episodes are played by a runner (:mod:`evcd.env.runner`); :func:`evaluate` also takes a plain
environment. Only episodes that end by charging (``terminated``) enter the travel-time statistics;
truncated ones are counted and listed. The agent never learns here: :meth:`Agent.observe` is not
called.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from tqdm import tqdm

from evcd.agents.base import Agent
from evcd.atomic import atomic_write_text
from evcd.env.runner import EpisodeRow, EpisodeRunner, EpisodeSpec, SingleEnvRunner

log = logging.getLogger(__name__)

BOOTSTRAP_RESAMPLES = 10_000
#: Spawn keys of the seed streams (see the module docstring).
EVAL_STREAM = 0
BOOTSTRAP_STREAM = 1
AGENT_STREAM = 2
TRAIN_STREAM = 3


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
    #: the agent's :meth:`~evcd.agents.Agent.report` (e.g. hindsight's station per episode)
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)


# ---------------------------------------------------------------------------------------- seeds
def episode_spec(seed: int, episode: int, stream: int = EVAL_STREAM) -> EpisodeSpec:
    """Episode ``episode`` of stream ``stream`` of run ``seed`` (its reset seed and agent seed)."""
    env_ss, agent_ss = np.random.SeedSequence(seed, spawn_key=(stream, episode)).spawn(2)
    reset_seed = int(env_ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))  # fits int64
    return EpisodeSpec(int(episode), reset_seed, agent_ss)


def episode_specs(seed: int, indices: Sequence[int] | range, stream: int = EVAL_STREAM) -> list[EpisodeSpec]:
    """:func:`episode_spec` for each index."""
    return [episode_spec(seed, i, stream) for i in indices]


def episode_seed(seed: int, episode: int, stream: int = EVAL_STREAM) -> tuple[int, np.random.Generator]:
    """The ``env.reset`` seed and the agent's generator of episode ``episode`` of run ``seed``."""
    spec = episode_spec(seed, episode, stream)
    return spec.reset_seed, spec.agent_rng()


def bootstrap_rng(seed: int) -> np.random.Generator:
    """The generator of a run's bootstrap."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(BOOTSTRAP_STREAM,)))


def agent_rng(seed: int) -> np.random.Generator:
    """The generator a script builds its agent with (network initialisation, replay sampling)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(AGENT_STREAM,)))


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
def as_runner(env_or_runner: gymnasium.Env | EpisodeRunner) -> EpisodeRunner:
    """``env_or_runner`` if it is a runner, else a :class:`SingleEnvRunner` over the environment."""
    if isinstance(env_or_runner, EpisodeRunner):
        return env_or_runner
    return SingleEnvRunner(env_or_runner)


def run_episode(
    env: gymnasium.Env, agent: Agent, episode: int, seed: int, explore: bool = False
) -> EpisodeRow:
    """Run episode ``episode`` of run ``seed`` to its end; return its row."""
    return SingleEnvRunner(env).episode(episode_spec(seed, episode), agent, explore=explore, learn=False)


class EpisodeProgress:
    """A tqdm bar over episodes showing the running mean travel time (and the truncated count).

    Args:
        total: episodes expected.
        desc: the bar's label.
        enabled: show it (on stderr).
        initial: episodes already done (a resumed run).
        window: the mean covers the latest ``window`` charged episodes (``None``: all).
    """

    def __init__(
        self, total: int, desc: str, enabled: bool = True, initial: int = 0, window: int | None = None
    ) -> None:
        self.bar = tqdm(
            total=total, initial=initial, desc=desc, unit="ep", mininterval=2, disable=not enabled
        )
        self.window = window
        self.travel: list[float] = []
        self.truncated = 0

    def __call__(self, row: EpisodeRow) -> None:
        """Count ``row`` (use the instance as a runner's ``on_episode``)."""
        if row.truncated:
            self.truncated += 1
        else:
            self.travel.append(row.travel_time)
        recent = self.travel[-self.window :] if self.window else self.travel
        self.bar.set_postfix(mean_T=f"{np.mean(recent):.0f}s" if recent else "-", truncated=self.truncated,
                             refresh=False)  # fmt: skip
        self.bar.update(1)

    def close(self) -> None:
        """Close the bar."""
        self.bar.close()


def evaluate(
    env: gymnasium.Env | EpisodeRunner,
    agent: Agent,
    episodes: int,
    seed: int,
    progress: bool = True,
    resamples: int = BOOTSTRAP_RESAMPLES,
    specs: Sequence[EpisodeSpec] | None = None,
) -> EvalResult:
    """Run ``agent`` for ``episodes`` episodes, without exploration or learning.

    Args:
        env: a :class:`~evcd.env.ChargingNavEnv` (or any env with its ``info`` keys), or a runner
            (:mod:`evcd.env.runner`). It is not closed here.
        agent: the dispatcher.
        episodes: number of episodes (>= 1).
        seed: the run seed (>= 0); see the module docstring for what derives from it.
        progress: show a tqdm progress bar (on stderr).
        resamples: bootstrap resamples of the confidence interval.
        specs: the episodes to run (default: the first ``episodes`` of the evaluation stream of
            ``seed``); ``episodes`` must equal their number.

    Raises:
        ValueError: ``episodes`` or ``seed`` out of range.
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int | np.integer) or episodes < 1:
        raise ValueError(f"episodes={episodes!r}: must be an integer >= 1")
    seed = _check_seed(seed)
    if specs is None:
        specs = episode_specs(seed, range(int(episodes)))
    elif len(specs) != episodes:
        raise ValueError(f"episodes={episodes} but {len(specs)} specs given")
    bar = EpisodeProgress(len(specs) * agent.runs_per_episode, f"evaluate {agent.name}", progress)
    try:
        rows = agent.play(as_runner(env), specs, explore=False, learn=False, on_episode=bar)
    finally:
        bar.close()
    for row in rows:
        log.debug("episode %d: %s", row.episode, row)
    summary = summarize(rows, bootstrap_rng(seed), resamples)
    return EvalResult(agent=agent.name, seed=seed, rows=tuple(rows), summary=summary, extra=agent.report())


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


def read_episodes_csv(path: str | Path) -> list[EpisodeRow]:
    """The rows of an ``episodes.csv`` (or ``train_episodes.csv``) written by :func:`episodes_csv_text`.

    Raises:
        ValueError: the file lacks a column of :class:`EpisodeRow` (the message names the file).
    """
    types = {f.name: f.type for f in dataclasses.fields(EpisodeRow)}
    convert = {"int": int, "float": float, "str": str, "bool": lambda v: v == "True"}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [k for k in CSV_FIELDS if k not in (reader.fieldnames or ()) and k != "switches"]
        if missing:
            raise ValueError(f"{path}: not an episodes file (missing columns {missing})")
        return [
            EpisodeRow(**{k: convert[types[k]](v) for k, v in row.items() if k in types}) for row in reader
        ]


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
    """The content of ``results.json``: agent, seed, summary, per-episode rows, optional config, and
    the agent's own extras (:attr:`EvalResult.extra`, e.g. ``hindsight``)."""
    return _json_safe(
        {
            "agent": result.agent,
            "seed": result.seed,
            "summary": dataclasses.asdict(result.summary),
            "episodes": [dataclasses.asdict(r) for r in result.rows],
            "config": dict(config) if config is not None else None,
            **result.extra,
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
