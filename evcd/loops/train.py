"""Train an agent on training episodes, then evaluate it beside baseline rules on held-out episodes:
one loop for both tasks (the single target and the fleet) and every agent.

    result = train_and_evaluate(agent, runners, TrainSettings(episodes=500, eval_episodes=50, seed=0),
                                run_dir, baselines={"greedy": greedy_agent})

``runners(phase)`` makes the :class:`~evcd.env.runners.base.EpisodeRunner` of a phase, ``"train"``,
``"eval"`` or ``"validation"`` (libsumo runs one simulation per process, so they are made one after
the other, each closed before the next). By default the phases run on different background days, so
the evaluation measures the policy on traffic it never trained on. The runners' task
(:attr:`~evcd.env.runners.base.EpisodeRunner.task`) says what a row is and how it is summarised,
paired and written (:mod:`evcd.loops.tasks`): a :class:`~evcd.env.runners.fleet.FleetRunner` makes a
fleet run, where every guided EV's transitions reach the one shared learner.

1. **Training** (agents with ``learns``): the training episodes of the run seed (stream
   :data:`~evcd.loops.seeds.TRAIN_STREAM`) are played with exploration, and every transition reaches
   ``agent.observe``. TensorBoard gets ``charts/*`` per episode and ``losses/*`` over the episode's
   gradient steps, all at ``global_step`` = transitions seen (:mod:`evcd.loops.train_log`). A
   checkpoint (agent state with its replay and generators, the rows so far, the validations) is
   written every ``checkpoint_every`` episodes and at the end (:mod:`evcd.loops.train_state`).
   ``resume=True`` continues from it; since an episode depends only on its seed and the agent's
   state, an interrupted and resumed run ends with the same weights as an uninterrupted one.
2. **Validation** (every ``validation.every`` episodes and at the end: :mod:`evcd.loops.validation`):
   the policy without exploration on fixed episodes of the tuning days, the rules once beside it.
   With ``beside``, a learner's rules (the validation's and the baselines) are played in a second
   process while it trains (:mod:`evcd.loops.beside`).
3. **Evaluation**: the agent (with ``validation.select_best``, the policy of its best validation:
   :mod:`evcd.loops.best_policy`), without exploration, on the evaluation episodes (stream
   :data:`~evcd.loops.seeds.EVAL_STREAM`, the same episodes ``scripts/evaluate.py`` runs for that
   seed), then each baseline rule on the same episodes, and the paired difference with each, with a
   bootstrap interval.

Files in ``run_dir``: ``train_episodes.csv``, ``episodes.csv`` (the agent's evaluation),
``baseline_<rule>_episodes.csv``, ``results.json``, ``learning_curve.png``, ``checkpoints/`` (the
latest checkpoint, and the one after each validation: ``ckpt_<episodes>.pt``, a policy
``scripts/evaluate.py`` can play, so that a training length chosen on the validation needs no
retraining), ``tensorboard/`` (and ``best/`` with ``validation.select_best``); a fleet run writes
``train_fleet_episodes.csv``, ``fleet_episodes.csv``, ``baseline_<rule>_fleet_episodes.csv`` and
``fleet_trace.png`` instead of the episodes files. Nothing already there is overwritten: a run
directory that holds a checkpoint is only entered again with ``resume=True``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from evcd.agents.base import Agent
from evcd.env.runners.base import EpisodeRunner, EpisodeSpec
from evcd.loops.beside import RulesBeside
from evcd.loops.best_policy import check_learned, keep_if_best, policy_to_evaluate
from evcd.loops.curves import plot_learning_curve
from evcd.loops.evaluate import Dispatcher, evaluate
from evcd.loops.progress import EpisodeProgress
from evcd.loops.run_files import CURVE_PNG, RESULTS_JSON, episodes_csv_text, results_dict, rows_csv_text
from evcd.loops.seeds import TRAIN_STREAM, VALIDATION_STREAM, episode_specs
from evcd.loops.stats import BOOTSTRAP_RESAMPLES, EvalResult
from evcd.loops.tasks import Task, task_of
from evcd.loops.train_log import TrainLog
from evcd.loops.train_state import TrainState, save_training, start_run, training_counters
from evcd.loops.validation import ValidationSettings, Validator
from evcd.utils.atomic import atomic_write_json, atomic_write_text, json_floats
from evcd.utils.checkpoint import state_sha256
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
        validation: the periodic held-out evaluation during training (:mod:`evcd.loops.validation`).
        rotate_days: with this many training days (> 1), each call of ``checkpoint_every`` episodes
            plays on one of them, in turn (the episodes' ``day`` reset option); 0 or 1: each episode
            draws its day from its seed.
    """

    episodes: int
    eval_episodes: int
    seed: int
    checkpoint_every: int = 100
    progress: bool = True
    log_window: int = 50
    resamples: int = BOOTSTRAP_RESAMPLES
    validation: ValidationSettings = dataclasses.field(default_factory=ValidationSettings)
    rotate_days: int = 0

    def __post_init__(self) -> None:
        for key, low in (("episodes", 0), ("eval_episodes", 1), ("seed", 0), ("checkpoint_every", 0),
                         ("log_window", 1), ("resamples", 1), ("rotate_days", 0)):  # fmt: skip
            check_int(key, getattr(self, key), minimum=low)
        every = self.validation.every
        if every and self.checkpoint_every and every % self.checkpoint_every:
            raise ValueError(
                f"train.validation.every={every}: must be a multiple of train.checkpoint_every="
                f"{self.checkpoint_every} (training episodes are played in calls of that many)"
            )


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_and_evaluate` measured (also written to ``results.json``)."""

    evaluation: EvalResult
    baselines: dict[str, EvalResult]
    paired: dict[str, dict[str, Any]]  # rule -> the agent's paired difference with it
    training: dict[str, Any]


def training_specs(settings: TrainSettings) -> list[EpisodeSpec]:
    """The run's training episodes: stream :data:`TRAIN_STREAM` of its seed, each call of
    ``checkpoint_every`` episodes on one training day in turn when ``rotate_days`` > 1."""
    specs = episode_specs(settings.seed, range(settings.episodes), TRAIN_STREAM)
    if settings.rotate_days <= 1:
        return specs
    every = settings.checkpoint_every or settings.episodes
    return [dataclasses.replace(s, options={"day": (s.index // every) % settings.rotate_days}) for s in specs]


def train_episodes(
    agent: Agent,
    runner: Callable[[], EpisodeRunner],
    specs: Sequence[EpisodeSpec],
    settings: TrainSettings,
    run_dir: Path,
    state: TrainState,
    config: Mapping[str, Any] | None,
    tlog: TrainLog,
    validator: Validator | None,
) -> None:
    """The training loop of both tasks: play ``specs`` from ``state.episodes_done`` on, exploring and
    learning, ``settings.checkpoint_every`` per call of the runner (``runner()`` makes it), with the
    periodic validation (``validator``), the best policy kept (:mod:`evcd.loops.best_policy`) and a
    checkpoint after every call."""
    episodes = len(specs)
    every = settings.checkpoint_every or episodes
    bar = EpisodeProgress(episodes, f"train {agent.name}", settings.progress, initial=state.episodes_done,
                          window=settings.log_window)  # fmt: skip
    bar.travel = state.charged_travel()
    state.sessions += 1
    saved = state.episodes_done  # the position of the checkpoint this session started from
    tlog.start(agent.stats())
    played = runner()
    try:
        t0 = time.perf_counter()
        played.prepare()
        state.prepare_s += time.perf_counter() - t0
        session_start, wall_before, validation_before = time.perf_counter(), state.wall_s, state.validation_s

        def on_episode(row: Any) -> None:
            state.record(row)
            state.episodes_done += 1
            state.transitions += row.steps
            paused = state.validation_s - validation_before
            state.wall_s = wall_before + time.perf_counter() - session_start - paused
            tlog.episode(row, agent.stats(), state.transitions, state.wall_s, agent.scalars())
            bar(row)

        while state.episodes_done < episodes:
            start = state.episodes_done
            stop = min(episodes, (start // every + 1) * every)
            played.run(specs[start:stop], agent, explore=True, learn=True, on_episode=on_episode)
            if validator is not None and validator.due(state.episodes_done, episodes):
                played.close()  # one simulation per process: the next call starts its own again
                _validate(agent, validator, settings, run_dir, state, tlog)
            tlog.flush()
            # the policy of every validation stays evaluable (scripts/evaluate.py agent.checkpoint=...)
            validated = [p.episodes_done for p in state.validation.points]
            save_training(run_dir, agent, state, config, keep=validated)
            saved = state.episodes_done
    except KeyboardInterrupt:
        last = f"after {saved} episodes" if saved else "none yet"
        log.warning("interrupted after %d training episodes; resume=true continues from the last "
                    "checkpoint (%s)", state.episodes_done, last)  # fmt: skip
        raise
    finally:
        bar.close()
        played.close()


def _validate(
    agent: Agent,
    validator: Validator,
    settings: TrainSettings,
    run_dir: Path,
    state: TrainState,
    tlog: TrainLog,
) -> None:
    """Validate the policy now (no simulation of the training may be open), log it and keep it if best."""
    t1 = time.perf_counter()
    validator.validate(agent, state.episodes_done, state.transitions, state.validation)
    state.validation_s += time.perf_counter() - t1
    tlog.validation(state.validation, state.transitions)
    keep_if_best(run_dir, agent, settings.validation, state.validation)


# ---------------------------------------------------------------------------------------- the whole run
def train_and_evaluate(
    agent: Dispatcher,
    runners: RunnerFactory,
    settings: TrainSettings,
    run_dir: str | Path,
    baselines: Mapping[str, Dispatcher] | None = None,
    resume: bool = False,
    config: Mapping[str, Any] | None = None,
    validation_rules: Mapping[str, Agent] | None = None,
    on_start: Callable[[], None] | None = None,
    beside: RunnerFactory | None = None,
) -> TrainResult:
    """Train ``agent`` (if it learns), evaluate it and the ``baselines`` on the same held-out episodes,
    on either task: the runners' (:attr:`~evcd.env.runners.base.EpisodeRunner.task`; the fleet's
    rows, summaries, pairs and files are :mod:`evcd.loops.tasks`'s :class:`~evcd.loops.tasks.FleetTask`).

    Args:
        agent: the agent (a learner is trained first; a rule, or the hindsight bound, is only evaluated).
        runners: ``runners("train")`` / ``runners("eval")`` make each phase's runner.
        settings: episodes, seed, checkpoints.
        run_dir: where every file goes (see the module docstring).
        baselines: the rules the agent is compared with on the same episodes, by name (an agent of a
            rule's name is its own baseline).
        resume: continue the run whose checkpoint is in ``run_dir``.
        config: the run's resolved settings (plain values): stored with checkpoints and results, and
            compared on resume.
        validation_rules: the rules validated on the periodic validation's episodes beside the agent
            (``settings.validation``; ``runners("validation")`` makes its runner).
        on_start: called once ``run_dir`` passed every check, before anything is written into it.
        beside: a picklable ``runners`` (e.g. :class:`~evcd.loops.beside.RunnerRecipe`): a learner's
            validation rules and baselines are played in a second process while it trains
            (:mod:`evcd.loops.beside`: the same rows, on a core that would idle); ``None``: in turn here.

    Raises:
        FileExistsError, FileNotFoundError: see :func:`check_run_dir`.
        ValueError: a resumed run's config differs from the checkpoint's, or a bad setting.
        CheckpointError: the checkpoint is corrupted, of the other task, or does not fit the agent.
    """
    run_dir = Path(run_dir)
    runner = runners("eval")  # made now to know the task; it starts nothing until the evaluation
    task = task_of(runner)
    state, tlog = start_run(run_dir, agent, resume, config, task.state, on_start)
    episodes = settings.episodes if agent.learns else 0
    side: RulesBeside | None = None
    try:
        if episodes and state.episodes_done < episodes:
            validator = None
            rules = (validation_rules or {}) if settings.validation.every else {}
            to_play = {n: r for n, r in rules.items() if n not in state.validation.rules}
            if beside is not None and (to_play or baselines):
                side = RulesBeside(beside, settings, to_play, baselines or {})
            if settings.validation.every:

                def specs(played: EpisodeRunner) -> list[EpisodeSpec]:
                    return task.specs(settings.seed, settings.validation.episodes, played, VALIDATION_STREAM)

                validator = Validator(runners, settings.validation, rules, specs,
                                      side.validation_rules if side is not None else None)  # fmt: skip
            train_episodes(agent, lambda: runners("train"), training_specs(settings), settings, run_dir,
                           state, config, tlog, validator)  # fmt: skip
        check_learned(agent, episodes)
        selected = policy_to_evaluate(run_dir, agent, settings.validation, state.validation, episodes)
        evaluation, bases = _evaluate(agent, runner, settings, baselines or {}, side)
        paired = {name: task.paired(evaluation.rows, base.rows, settings.seed, settings.resamples)
                  for name, base in bases.items()}  # fmt: skip
        learner = agent if isinstance(agent, Agent) and agent.learns else None
        stats = agent.stats() if isinstance(agent, Agent) else {}
        policy = state_sha256(learner.policy_state_dict()) if learner is not None else None
        training = {**training_counters(stats, state, episodes), **state.summary(),
                    "evaluated_after_episodes": selected, "policy_sha256": policy}  # fmt: skip
        tlog.scalars(task.score(evaluation.summary), {n: task.score(b.summary) for n, b in bases.items()},
                     {n: task.score_pair(p) for n, p in paired.items()}, state.transitions)  # fmt: skip
    finally:
        tlog.close()
        if side is not None:
            side.close()
    result = TrainResult(evaluation, bases, paired, training)
    _write_outputs(run_dir, task, result, state, config, runner)
    return result


def _evaluate(
    agent: Dispatcher,
    runner: EpisodeRunner,
    settings: TrainSettings,
    baselines: Mapping[str, Dispatcher],
    side: RulesBeside | None = None,
) -> tuple[EvalResult, dict[str, EvalResult]]:
    try:
        runner.prepare()
        kwargs = {"progress": settings.progress, "resamples": settings.resamples}
        evaluation = evaluate(runner, agent, settings.eval_episodes, settings.seed, **kwargs)
        if side is not None:  # played beside the training
            return evaluation, dict(side.baselines())
        bases = {}
        for name, baseline in baselines.items():
            same = baseline.name == agent.name and not agent.learns
            bases[name] = evaluation if same else evaluate(runner, baseline, settings.eval_episodes,
                                                           settings.seed, **kwargs)  # fmt: skip
        return evaluation, bases
    finally:
        runner.close()


def _write_outputs(
    run_dir: Path,
    task: Task,
    result: TrainResult,
    state: TrainState,
    config: Mapping[str, Any] | None,
    runner: EpisodeRunner,
) -> None:
    agent = result.evaluation.agent
    if state.rows:
        atomic_write_text(run_dir / task.train_csv, rows_csv_text(state.row_dicts()))
        plot_learning_curve({agent: state.curve_rows()}, run_dir / CURVE_PNG, title=task.curve_title(agent),
                            validation=state.validation, **task.curve)  # fmt: skip
    atomic_write_text(run_dir / task.eval_csv, episodes_csv_text(result.evaluation.rows))
    for name, base in result.baselines.items():
        atomic_write_text(run_dir / task.baseline_csv(name), episodes_csv_text(base.rows))
    task.figures(run_dir, result.evaluation, result.baselines, runner)
    out = results_dict(result.evaluation, config)
    out["training"] = result.training
    if state.validation.points:
        out["validation"] = state.validation.to_dict()
    if result.baselines:
        out["baselines"] = {name: {"summary": dataclasses.asdict(base.summary), "paired": result.paired[name]}
                            for name, base in result.baselines.items()}  # fmt: skip
    atomic_write_json(run_dir / RESULTS_JSON, json_floats(out))
