"""Train an agent on training episodes, then evaluate it beside a baseline on held-out episodes.

    result = train_and_evaluate(agent, runners, TrainSettings(episodes=500, eval_episodes=50, seed=0),
                                run_dir, baseline=greedy_agent)

``runners(phase)`` makes the :class:`~evcd.env.runners.base.EpisodeRunner` of a phase, ``"train"`` or
``"eval"`` (libsumo runs one simulation per process, so the two are made one after the other, each
closed before the next). By default the two phases run on different background days, so the
evaluation measures the policy on traffic it never trained on.

1. **Training** (agents with ``learns``): the training episodes of the run seed (stream
   :data:`~evcd.loops.seeds.TRAIN_STREAM`) are played with exploration, and every transition reaches
   ``agent.observe``. TensorBoard gets ``charts/*`` per episode and ``losses/*`` over the episode's
   gradient steps, all at ``global_step`` = transitions seen. A checkpoint (agent state with its
   replay and generators, the rows so far, the position in the seed sequence) is written every
   ``checkpoint_every`` episodes and at the end (:mod:`evcd.loops.train_state`). ``resume=True``
   continues from it; since an episode depends only on its seed
   and the agent's state, an interrupted and resumed run ends with the same weights as an
   uninterrupted one.
2. **Evaluation**: the agent, without exploration, on the evaluation episodes (stream
   :data:`~evcd.loops.seeds.EVAL_STREAM`, the same episodes ``scripts/evaluate.py`` runs for that
   seed), then the baseline (greedy) on the same episodes, and their paired difference with a
   bootstrap interval.

Files in ``run_dir``: ``train_episodes.csv``, ``episodes.csv`` (the agent's evaluation),
``baseline_episodes.csv``, ``results.json``, ``learning_curve.png``, ``checkpoints/``,
``tensorboard/``. Nothing already there is overwritten: a run directory that holds a checkpoint
is only entered again with ``resume=True``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from evcd.agents.base import Agent
from evcd.env.runners.base import EpisodeRow, EpisodeRunner
from evcd.loops.curves import plot_learning_curve
from evcd.loops.evaluate import Dispatcher, evaluate
from evcd.loops.progress import EpisodeProgress
from evcd.loops.run_files import (
    BASELINE_CSV,
    CHECKPOINTS,
    CURVE_PNG,
    EVAL_CSV,
    RESULTS_JSON,
    TENSORBOARD,
    TRAIN_CSV,
    episodes_csv_text,
    results_dict,
)
from evcd.loops.seeds import TRAIN_STREAM, bootstrap_rng, episode_specs
from evcd.loops.stats import BOOTSTRAP_RESAMPLES, EvalResult, paired_difference
from evcd.loops.train_log import TrainLog
from evcd.loops.train_state import TrainState, check_run_dir, restore_training, save_training
from evcd.utils.atomic import atomic_write_json, atomic_write_text
from evcd.utils.checkpoint import has_checkpoint
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

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
            check_int(key, getattr(self, key), minimum=low)


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_and_evaluate` measured (also written to ``results.json``)."""

    evaluation: EvalResult
    baseline: EvalResult | None
    paired: dict[str, Any] | None
    training: dict[str, Any]


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
            save_training(run_dir, agent, state, config)
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
    agent: Dispatcher,
    runners: RunnerFactory,
    settings: TrainSettings,
    run_dir: str | Path,
    baseline: Dispatcher | None = None,
    resume: bool = False,
    config: Mapping[str, Any] | None = None,
) -> TrainResult:
    """Train ``agent`` (if it learns), evaluate it and ``baseline`` on the same held-out episodes.

    Args:
        agent: the agent (a learner is trained first; a rule, or the hindsight bound, is only evaluated).
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
        state = restore_training(run_dir, agent, config)
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
    agent: Dispatcher, runners: RunnerFactory, settings: TrainSettings, baseline: Dispatcher | None
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


def _training_summary(agent: Dispatcher, state: TrainState, episodes: int) -> dict[str, Any]:
    stats = agent.stats() if isinstance(agent, Agent) else {}
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
    atomic_write_json(run_dir / RESULTS_JSON, out)
