"""Train an agent on training episodes, then evaluate it beside a baseline on held-out episodes.

    result = train_and_evaluate(agent, runners, TrainSettings(episodes=500, eval_episodes=50, seed=0),
                                run_dir, baseline=greedy_agent)

``runners(phase)`` makes the :class:`~evcd.env.runner.EpisodeRunner` of a phase, ``"train"`` or
``"eval"`` (libsumo runs one simulation per process, so the two are made one after the other, each
closed before the next). By default the two phases run on different background days, so the
evaluation measures the policy on traffic it never trained on.

1. **Training** (agents with ``learns``): the training episodes of the run seed (stream
   :data:`~evcd.evaluate.TRAIN_STREAM`) are played with exploration, and every transition reaches
   ``agent.observe``. TensorBoard gets ``charts/*`` per episode and ``losses/*`` over the episode's
   gradient steps, all at ``global_step`` = transitions seen. A checkpoint (agent state with its
   replay and generators, the rows so far, the position in the seed sequence) is written every
   ``checkpoint_every`` episodes and at the end (:mod:`evcd.checkpoint`: atomic, checksummed,
   ``weights_only``). ``resume=True`` continues from it; since an episode depends only on its seed
   and the agent's state, an interrupted and resumed run ends with the same weights as an
   uninterrupted one.
2. **Evaluation**: the agent, without exploration, on the evaluation episodes (stream
   :data:`~evcd.evaluate.EVAL_STREAM`, the same episodes ``scripts/evaluate.py`` runs for that
   seed), then the baseline (greedy) on the same episodes, and their paired difference with a
   bootstrap interval.

Files in ``run_dir``: ``train_episodes.csv``, ``episodes.csv`` (the agent's evaluation),
``baseline_episodes.csv``, ``results.json``, ``learning_curve.png``, ``checkpoints/``,
``tensorboard/``. Nothing already there is overwritten: a run directory that holds a checkpoint
is only entered again with ``resume=True``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from evcd.agents.base import Agent
from evcd.atomic import atomic_write_text
from evcd.checkpoint import CheckpointError, has_checkpoint, json_floats, load_checkpoint, save_checkpoint
from evcd.env.runner import EpisodeRow, EpisodeRunner
from evcd.evaluate import (
    BOOTSTRAP_RESAMPLES,
    TRAIN_STREAM,
    EpisodeProgress,
    EvalResult,
    bootstrap_ci,
    bootstrap_rng,
    episode_specs,
    episodes_csv_text,
    evaluate,
    results_dict,
)
from evcd.plots import plot_learning_curve
from evcd.train_log import TrainLog

log = logging.getLogger(__name__)

CHECKPOINTS = "checkpoints"
TENSORBOARD = "tensorboard"
TRAIN_CSV = "train_episodes.csv"
EVAL_CSV = "episodes.csv"
BASELINE_CSV = "baseline_episodes.csv"
RESULTS_JSON = "results.json"
CURVE_PNG = "learning_curve.png"
OUTPUTS = (TRAIN_CSV, EVAL_CSV, BASELINE_CSV, RESULTS_JSON, CURVE_PNG)
CHECKPOINT_FORMAT = "evcd.train/1"
#: Config keys that may differ between a run and its resumption.
RESUME_FREE_KEYS = frozenset({"resume", "progress"})

RunnerFactory = Callable[[str], EpisodeRunner]


@dataclass(frozen=True)
class TrainSettings:
    """How long to train and evaluate, and how to record it.

    Attributes:
        episodes: training episodes (0 for agents that do not learn).
        eval_episodes: evaluation episodes (>= 1).
        seed: the run seed: training and evaluation episodes derive from it (disjoint streams).
        checkpoint_every: write a checkpoint every this many training episodes (0: only at the end).
        progress: show progress bars.
        log_window: the training bar shows the mean travel time of this many latest episodes.
        resamples: bootstrap resamples of the intervals.
    """

    episodes: int
    eval_episodes: int
    seed: int
    checkpoint_every: int = 100
    progress: bool = True
    log_window: int = 50
    resamples: int = BOOTSTRAP_RESAMPLES

    def __post_init__(self) -> None:
        for key, low in (("episodes", 0), ("eval_episodes", 1), ("seed", 0), ("checkpoint_every", 0),
                         ("log_window", 1), ("resamples", 1)):  # fmt: skip
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise ValueError(f"{key}={value!r}: must be an integer >= {low}")


@dataclass
class TrainState:
    """Where training stands (saved in every checkpoint)."""

    episodes_done: int = 0
    transitions: int = 0
    wall_s: float = 0.0  # training wall time over every session (day builds excluded)
    prepare_s: float = 0.0  # day builds of the training runner
    sessions: int = 0  # how many times training was started or resumed
    rows: list[EpisodeRow] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain values for the checkpoint."""
        d = dataclasses.asdict(self)
        d["rows"] = [dataclasses.asdict(r) for r in self.rows]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainState:
        """The inverse of :meth:`to_dict`."""
        values = dict(d)
        values["rows"] = [EpisodeRow(**r) for r in values["rows"]]
        return cls(**values)


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_and_evaluate` measured (also written to ``results.json``)."""

    evaluation: EvalResult
    baseline: EvalResult | None
    paired: dict[str, Any] | None
    training: dict[str, Any]


# ---------------------------------------------------------------------------------------- statistics
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


# ---------------------------------------------------------------------------------------- run directory
def check_run_dir(run_dir: Path, resume: bool) -> None:
    """Refuse to start a new run where one already wrote, or to resume where nothing was written.

    Raises:
        FileExistsError: a new run (``resume=False``) in a directory holding a checkpoint or results.
        FileNotFoundError: ``resume=True`` but the directory holds no checkpoint and no results.
    """
    ckpt = run_dir / CHECKPOINTS
    written = [name for name in OUTPUTS if (run_dir / name).exists()]
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


def _config_diff(saved: Mapping[str, Any], current: Mapping[str, Any], prefix: str = "") -> list[str]:
    keys = sorted(set(saved) | set(current))
    out = []
    for key in keys:
        name = f"{prefix}{key}"
        if not prefix and key in RESUME_FREE_KEYS:
            continue
        a, b = saved.get(key, "<missing>"), current.get(key, "<missing>")
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += _config_diff(a, b, f"{name}.")
        elif a != b:
            out.append(f"{name}: {a!r} -> {b!r}")
    return out


# ---------------------------------------------------------------------------------------- training
def _checkpoint(run_dir: Path, agent: Agent, state: TrainState, config: Mapping[str, Any] | None) -> None:
    payload = {
        "format": CHECKPOINT_FORMAT,
        "agent": agent.state_dict(),  # type: ignore[attr-defined]
        "trainer": state.to_dict(),
        "config": dict(config) if config is not None else None,
    }
    path = save_checkpoint(run_dir / CHECKPOINTS, payload, f"ckpt_{state.episodes_done:07d}")
    log.info("checkpoint after %d episodes: %s", state.episodes_done, path)


def _restore(run_dir: Path, agent: Agent, config: Mapping[str, Any] | None) -> TrainState:
    payload = load_checkpoint(run_dir / CHECKPOINTS)
    if payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{run_dir / CHECKPOINTS}: not a training checkpoint (format "
                              f"{payload.get('format')!r}, expected {CHECKPOINT_FORMAT!r})")  # fmt: skip
    saved = payload.get("config")
    if config is not None and saved is not None:
        diff = _config_diff(saved, config)
        if diff:
            raise ValueError(
                "resume=true with settings that differ from the checkpoint's run (a resumed run "
                "must continue the same experiment): " + "; ".join(diff)
            )
    agent.load_state_dict(payload["agent"])  # type: ignore[attr-defined]
    state = TrainState.from_dict(payload["trainer"])
    log.info("resuming after %d training episodes (%d transitions)", state.episodes_done, state.transitions)
    return state


def _train(
    agent: Agent,
    runners: RunnerFactory,
    settings: TrainSettings,
    run_dir: Path,
    state: TrainState,
    config: Mapping[str, Any] | None,
    tlog: TrainLog,
) -> None:
    """Play the training episodes from ``state.episodes_done`` on, with checkpoints."""
    every = settings.checkpoint_every or settings.episodes
    specs = episode_specs(settings.seed, range(settings.episodes), TRAIN_STREAM)
    bar = EpisodeProgress(settings.episodes, f"train {agent.name}", settings.progress,
                          initial=state.episodes_done, window=settings.log_window)  # fmt: skip
    bar.travel = [r.travel_time for r in state.rows if not r.truncated]
    state.sessions += 1
    saved = state.episodes_done  # the position of the checkpoint this session started from
    tlog.start(agent.stats())
    runner = runners("train")
    try:
        t0 = time.perf_counter()
        runner.prepare()
        state.prepare_s += time.perf_counter() - t0
        session_start, wall_before = time.perf_counter(), state.wall_s

        def on_episode(row: EpisodeRow) -> None:
            state.rows.append(row)
            state.episodes_done += 1
            state.transitions += row.steps
            state.wall_s = wall_before + time.perf_counter() - session_start
            tlog.episode(row, agent.stats(), state.transitions, state.wall_s)
            bar(row)

        while state.episodes_done < settings.episodes:
            start = state.episodes_done
            stop = min(settings.episodes, (start // every + 1) * every)
            runner.run(specs[start:stop], agent, explore=True, learn=True, on_episode=on_episode)
            tlog.flush()
            _checkpoint(run_dir, agent, state, config)
            saved = state.episodes_done
    except KeyboardInterrupt:
        last = f"after {saved} episodes" if saved else "none yet"
        log.warning("interrupted after %d training episodes; resume=true continues from the last "
                    "checkpoint (%s)", state.episodes_done, last)  # fmt: skip
        raise
    finally:
        bar.close()
        runner.close()


# ---------------------------------------------------------------------------------------- the whole run
def train_and_evaluate(
    agent: Agent,
    runners: RunnerFactory,
    settings: TrainSettings,
    run_dir: str | Path,
    baseline: Agent | None = None,
    resume: bool = False,
    config: Mapping[str, Any] | None = None,
) -> TrainResult:
    """Train ``agent`` (if it learns), evaluate it and ``baseline`` on the same held-out episodes.

    Args:
        agent: the agent (a learner is trained first; a rule is only evaluated).
        runners: ``runners("train")`` / ``runners("eval")`` make each phase's runner.
        settings: episodes, seed, checkpoints.
        run_dir: where every file goes (see the module docstring).
        baseline: the rule the agent is compared with on the same episodes (``None``: no comparison;
            an agent of the baseline's name is its own baseline).
        resume: continue the run whose checkpoint is in ``run_dir``.
        config: the run's resolved settings (plain values): stored with checkpoints and results, and
            compared on resume.

    Raises:
        FileExistsError, FileNotFoundError: see :func:`check_run_dir`.
        ValueError: a resumed run's config differs from the checkpoint's, or a bad setting.
        CheckpointError: the checkpoint is corrupted or does not fit the agent.
    """
    run_dir = Path(run_dir)
    check_run_dir(run_dir, resume)
    if resume and (run_dir / RESULTS_JSON).exists():
        raise FileExistsError(f"{run_dir / RESULTS_JSON} exists: that run is complete (nothing to resume)")
    run_dir.mkdir(parents=True, exist_ok=True)
    episodes = settings.episodes if agent.learns else 0
    state = TrainState()
    if agent.learns and resume and has_checkpoint(run_dir / CHECKPOINTS):
        state = _restore(run_dir, agent, config)
    tlog = TrainLog(run_dir / TENSORBOARD, purge_step=state.transitions if resume else None)
    try:
        if not resume:
            tlog.config(config or {}, repr(agent))
        if episodes and state.episodes_done < episodes:
            _train(
                agent, runners, dataclasses.replace(settings, episodes=episodes), run_dir, state, config, tlog
            )
        evaluation, base = _evaluate(agent, runners, settings, baseline)
        paired = None
        if base is not None:
            paired = paired_difference(
                evaluation.rows, base.rows, bootstrap_rng(settings.seed), settings.resamples
            )
        training = _training_summary(agent, state, episodes)
        tlog.evaluation(evaluation, base, paired, state.transitions)
    finally:
        tlog.close()
    result = TrainResult(evaluation, base, paired, training)
    _write_outputs(run_dir, result, state, config)
    return result


def _evaluate(
    agent: Agent, runners: RunnerFactory, settings: TrainSettings, baseline: Agent | None
) -> tuple[EvalResult, EvalResult | None]:
    runner = runners("eval")
    try:
        runner.prepare()
        kwargs = {"progress": settings.progress, "resamples": settings.resamples}
        evaluation = evaluate(runner, agent, settings.eval_episodes, settings.seed, **kwargs)
        if baseline is None:
            return evaluation, None
        if baseline.name == agent.name and not agent.learns:
            return evaluation, evaluation
        return evaluation, evaluate(runner, baseline, settings.eval_episodes, settings.seed, **kwargs)
    finally:
        runner.close()


def _training_summary(agent: Agent, state: TrainState, episodes: int) -> dict[str, Any]:
    stats = agent.stats()
    charged = [r.travel_time for r in state.rows if not r.truncated]
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
        "truncated": sum(r.truncated for r in state.rows),
        "mean_travel_time": float(np.mean(charged)) if charged else math.nan,
        "mean_switches": float(np.mean([r.switches for r in state.rows])) if state.rows else math.nan,
    }


def _write_outputs(
    run_dir: Path, result: TrainResult, state: TrainState, config: Mapping[str, Any] | None
) -> None:
    if state.rows:
        atomic_write_text(run_dir / TRAIN_CSV, episodes_csv_text(state.rows))
        plot_learning_curve({result.evaluation.agent: state.rows}, run_dir / CURVE_PNG,
                            title=f"{result.evaluation.agent}: travel time per training episode")  # fmt: skip
    atomic_write_text(run_dir / EVAL_CSV, episodes_csv_text(result.evaluation.rows))
    if result.baseline is not None:
        atomic_write_text(run_dir / BASELINE_CSV, episodes_csv_text(result.baseline.rows))
    out = results_dict(result.evaluation, config)
    out["training"] = result.training
    if result.baseline is not None:
        out["baseline"] = {
            "agent": result.baseline.agent,
            "summary": dataclasses.asdict(result.baseline.summary),
        }
        out["paired_vs_baseline"] = result.paired
    atomic_write_text(run_dir / RESULTS_JSON, json.dumps(json_floats(out), indent=1, allow_nan=False) + "\n")
