"""Train a shared-parameter learner on the fleet, then evaluate it beside the fleet's rules.

    result = train_and_evaluate_fleet(agent, envs, FleetTrainSettings(episodes=60, eval_episodes=5, seed=0),
                                      run_dir, baselines={"queue_aware": rule})

``envs`` maps a phase to its :class:`~evcd.env.fleet.FleetEnv`: ``"train"`` (training days),
``"eval"`` (held-out days) and, with a periodic validation, ``"validation"`` (tuning days). libsumo
runs one simulation per process, and each fleet episode starts a fresh one, so a phase's env is
closed before the next phase plays.

1. **Training**: the single target's training loop (:func:`~evcd.loops.train.train_episodes`) over
   fleet episodes: episode ``i`` of the training stream of the run seed (its day drawn by its reset
   seed among the training days) is played with exploration, and every guided EV's transitions reach
   ``agent.observe`` with that EV's own episode state (:class:`~evcd.env.runners.fleet.FleetRunner`:
   independent learners sharing one policy). TensorBoard gets the fleet's ``charts/*``
   per episode at ``global_step`` = agent steps seen. A checkpoint (agent with its replay and
   generators, the rows so far, the validations) is written every ``checkpoint_every`` episodes and
   at the end; ``resume=True`` continues from it, and since a fleet episode depends only on its seed
   and the agent's state, a resumed run ends with the weights of an uninterrupted one (tested).
2. **Validation** (every ``validation.every`` episodes and at the end; the single target's
   :class:`~evcd.loops.validation.Validator`): the policy without exploration on fixed fleet episodes
   of the tuning days (taken in turn: :func:`~evcd.loops.fleet.fleet_spec`), the rules once on the same
   episodes; each point is the mean over episodes of the guided EVs' mean travel time. It neither
   explores nor learns, so it does not change the weights (tested).
3. **Evaluation**: the agent (with ``validation.select_best``, the policy of its best validation:
   :mod:`evcd.loops.best_policy`) without exploration on the evaluation stream's fleet episodes (the ones
   ``scripts/evaluate.py task=fleet`` plays for the seed), each baseline on the very same episodes (same
   day, same guided EVs), and per baseline the paired difference of the guided EVs' and of all EVs'
   mean travel time per episode, with a bootstrap interval over episodes.

Files in ``run_dir``: ``train_fleet_episodes.csv``, ``fleet_episodes.csv``,
``baseline_<rule>_fleet_episodes.csv``, ``results.json``, ``learning_curve.png`` (guided EVs' mean travel
time per training episode and the validation curve), ``fleet_trace.png`` (the first evaluation
episode, per dispatcher), ``checkpoints/``, ``tensorboard/`` (and ``best/`` with
``validation.select_best``). Nothing already there is overwritten.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any, ClassVar

from evcd.agents.base import Agent
from evcd.env.fleet import FleetEnv
from evcd.env.runners.fleet import FleetEpisode, FleetRunner
from evcd.loops.best_policy import check_learned, policy_to_evaluate
from evcd.loops.curves import plot_learning_curve
from evcd.loops.fleet import evaluate_fleet, fleet_spec
from evcd.loops.fleet_figure import plot_fleet_traces
from evcd.loops.run_files import (
    CURVE_PNG,
    FLEET_CSV,
    FLEET_PNG,
    FLEET_TRAIN_CSV,
    RESULTS_JSON,
    baseline_csv,
    rows_csv_text,
)
from evcd.loops.seeds import TRAIN_STREAM, VALIDATION_STREAM, bootstrap_rng, episode_specs
from evcd.loops.stats import BOOTSTRAP_RESAMPLES, paired_values
from evcd.loops.train import train_episodes
from evcd.loops.train_state import start_run, training_counters
from evcd.loops.validation import ValidationRecord, ValidationSettings, Validator, finite_mean
from evcd.utils.atomic import atomic_write_json, atomic_write_text, json_floats
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

#: The travel times compared pairwise with each baseline: the guided EVs' and everybody's.
PAIRED_MEASURES = ("guided_travel", "all_travel")


@dataclass(frozen=True)
class FleetTrainSettings:
    """How long to train and evaluate on the fleet.

    Attributes:
        episodes: training fleet episodes (>= 1).
        eval_episodes: evaluation fleet episodes (>= 1).
        seed: the run seed (training, validation and evaluation episodes: disjoint streams).
        checkpoint_every: a checkpoint every this many training episodes (0: only at the end).
        progress: show progress bars.
        resamples: bootstrap resamples of the intervals.
        validation: the periodic held-out validation (``every`` a multiple of ``checkpoint_every``).
    """

    episodes: int
    eval_episodes: int
    seed: int
    checkpoint_every: int = 10
    progress: bool = True
    resamples: int = BOOTSTRAP_RESAMPLES
    validation: ValidationSettings = dataclasses.field(default_factory=ValidationSettings)

    def __post_init__(self) -> None:
        for key, low in (("episodes", 1), ("eval_episodes", 1), ("seed", 0), ("checkpoint_every", 0),
                         ("resamples", 1)):  # fmt: skip
            check_int(key, getattr(self, key), minimum=low)
        every = self.validation.every
        if every and self.checkpoint_every and every % self.checkpoint_every:
            raise ValueError(f"train.validation.every={every}: must be a multiple of train.checkpoint_every="
                             f"{self.checkpoint_every} (validations follow checkpoints)")  # fmt: skip


@dataclass
class FleetTrainState:
    """Where fleet training stands (saved in every checkpoint)."""

    FORMAT: ClassVar[str] = "evcd.fleet_train/1"
    episodes_done: int = 0
    transitions: int = 0  # agent steps seen
    wall_s: float = 0.0  # training wall time over every session (day builds and validations excluded)
    prepare_s: float = 0.0  # day builds of the training days
    sessions: int = 0
    validation_s: float = 0.0
    rows: list[dict[str, Any]] = field(default_factory=list)  # FleetEpisode.row() per training episode
    validation: ValidationRecord = field(default_factory=ValidationRecord)

    def record(self, episode: FleetEpisode) -> None:
        """Keep a training fleet episode's flat row (:meth:`FleetEpisode.row`)."""
        self.rows.append(episode.row())

    def charged_travel(self) -> list[float]:
        """The guided EVs' mean travel time of each training episode where one charged."""
        return [t for r in self.rows if math.isfinite(t := float(r["guided_travel"]))]

    def to_dict(self) -> dict[str, Any]:
        """Plain values for the checkpoint."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["rows"] = [dict(r) for r in self.rows]
        d["validation"] = self.validation.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FleetTrainState:
        """The inverse of :meth:`to_dict`."""
        values = dict(d)
        values["rows"] = [dict(r) for r in values["rows"]]
        values["validation"] = ValidationRecord.from_dict(values.get("validation"))
        return cls(**values)


@dataclass(frozen=True)
class FleetTrainResult:
    """What :func:`train_and_evaluate_fleet` measured (also in ``results.json``)."""

    agent: str
    summary: dict[str, Any]
    episodes: list[FleetEpisode]
    baselines: dict[str, tuple[dict[str, Any], list[FleetEpisode]]]  # rule -> (summary, episodes)
    paired: dict[str, dict[str, dict[str, Any]]]  # rule -> measure -> paired difference
    training: dict[str, Any]


def train_and_evaluate_fleet(
    agent: Agent,
    envs: Mapping[str, FleetEnv],
    settings: FleetTrainSettings,
    run_dir: str | Path,
    baselines: Mapping[str, Agent] | None = None,
    resume: bool = False,
    config: Mapping[str, Any] | None = None,
    validation_rules: Mapping[str, Agent] | None = None,
    on_start: Callable[[], None] | None = None,
) -> FleetTrainResult:
    """Train ``agent`` on the fleet (if it learns), evaluate it and the ``baselines`` on the same
    held-out fleet episodes; write the run's files (module docstring). ``on_start`` is called once
    ``run_dir`` passed every check, before anything is written into it.

    Raises:
        FileExistsError, FileNotFoundError: a new run where one wrote, a resume where none did.
        ValueError: a resumed run's config differs from the checkpoint's.
        CheckpointError: the checkpoint is damaged or not a fleet training checkpoint.
    """
    run_dir = Path(run_dir)
    state, tlog = start_run(run_dir, agent, resume, config, FleetTrainState, on_start)
    episodes = settings.episodes if agent.learns else 0
    try:
        if episodes and state.episodes_done < episodes:
            validator = None
            if settings.validation.every:
                days = len(envs["validation"].days)
                checks = [fleet_spec(settings.seed, i, days, VALIDATION_STREAM)
                          for i in range(settings.validation.episodes)]  # fmt: skip
                validator = Validator(lambda phase: FleetRunner(envs[phase]), settings.validation,
                                      settings.seed, validation_rules or {}, checks)  # fmt: skip
            specs = episode_specs(settings.seed, range(settings.episodes), TRAIN_STREAM)
            train_episodes(agent, lambda: FleetRunner(envs["train"]), specs, settings, run_dir, state, config,
                           tlog, validator)  # fmt: skip
        check_learned(agent, episodes)
        selected = policy_to_evaluate(run_dir, agent, settings.validation, state.validation, episodes)
        training = {**_training_summary(agent, state, episodes), "evaluated_after_episodes": selected}
        result = _evaluate(agent, envs["eval"], settings, baselines or {}, training)
        rules = {n: s["guided_travel"] for n, (s, _) in result.baselines.items()}
        paired = {n: p["guided_travel"] for n, p in result.paired.items()}
        tlog.scalars(result.summary["guided_travel"], rules, paired, state.transitions)
    finally:
        tlog.close()
    _write_outputs(run_dir, result, state, envs["eval"], config)
    return result


def _evaluate(
    agent: Agent, env: FleetEnv, settings: FleetTrainSettings, baselines: Mapping[str, Agent],
    training: dict[str, Any],
) -> FleetTrainResult:  # fmt: skip
    kwargs = {"progress": settings.progress, "resamples": settings.resamples}
    runner = FleetRunner(env)
    try:
        runner.prepare()
        played, summary = evaluate_fleet(runner, agent, settings.eval_episodes, settings.seed, **kwargs)
        bases = {name: evaluate_fleet(runner, rule, settings.eval_episodes, settings.seed, **kwargs)
                 for name, rule in baselines.items()}  # fmt: skip
    finally:
        runner.close()
    rng = bootstrap_rng(settings.seed)
    paired = {
        name: {key: paired_values([getattr(e.measures, key) for e in played],
                                  [getattr(e.measures, key) for e in eps], rng, settings.resamples)
               for key in PAIRED_MEASURES}
        for name, (eps, _) in bases.items()
    }  # fmt: skip
    return FleetTrainResult(agent.name, summary, played, {n: (s, e) for n, (e, s) in bases.items()}, paired,
                            training)  # fmt: skip


def _training_summary(agent: Agent, state: FleetTrainState, episodes: int) -> dict[str, Any]:
    return {
        **training_counters(agent.stats(), state, episodes),
        "mean_guided_travel": finite_mean([float(r["guided_travel"]) for r in state.rows]),
    }


def _curve_rows(rows: list[dict[str, Any]]) -> list[SimpleNamespace]:
    """Training rows as the learning curve reads them (per episode: the guided EVs' mean)."""
    out = []
    for r in rows:
        travel = float(r["guided_travel"])
        out.append(SimpleNamespace(travel_time=travel, truncated=not math.isfinite(travel),
                                   switches=float(r["switches"])))  # fmt: skip
    return out


def _write_outputs(
    run_dir: Path,
    result: FleetTrainResult,
    state: FleetTrainState,
    env: FleetEnv,
    config: Mapping[str, Any] | None,
) -> None:
    if state.rows:
        atomic_write_text(run_dir / FLEET_TRAIN_CSV, rows_csv_text(state.rows))
        title = f"{result.agent} on the fleet: guided EVs' mean travel time per training episode"
        plot_learning_curve({result.agent: _curve_rows(state.rows)}, run_dir / CURVE_PNG, window=10,
                            title=title, validation=state.validation,
                            travel_label="guided EVs' mean travel time",
                            switches_label="switches per guided EV")  # fmt: skip
    atomic_write_text(run_dir / FLEET_CSV, rows_csv_text([e.row() for e in result.episodes]))
    for name, (_, eps) in result.baselines.items():
        atomic_write_text(run_dir / baseline_csv(name, fleet=True), rows_csv_text([e.row() for e in eps]))
    first = result.episodes[0]
    traces = {result.agent: first.trace, **{n: eps[0].trace for n, (_, eps) in result.baselines.items()}}
    title = f"evaluation episode 0 (day {first.day}, {first.measures.guided} guided EVs)"
    plot_fleet_traces(traces, [st.id for st in env.stations], run_dir / FLEET_PNG, title=title)
    out: dict[str, Any] = {
        "task": "fleet",
        "agent": result.agent,
        "seed": result.summary["seed"],
        "summary": result.summary,
        "episodes": [e.row() for e in result.episodes],
        "baselines": {
            n: {"summary": s, "paired": result.paired[n]} for n, (s, _) in result.baselines.items()
        },
        "training": result.training,
        "config": dict(config) if config is not None else None,
    }
    if state.validation.points:
        out["validation"] = state.validation.to_dict()
    atomic_write_json(run_dir / RESULTS_JSON, json_floats(out))
