"""What the two tasks differ in once their episodes are played: which episodes evaluate and validate,
how their rows are summarised and paired, and which files hold them.

    task = task_of(runner)                        # a runner declares its task (EpisodeRunner.task)
    specs = task.specs(seed, episodes, runner)    # the evaluation episodes of run ``seed``
    summary = task.summarize(rows, bootstrap_rng(seed), resamples)

The loops (training, validation, evaluation: :mod:`evcd.loops.train`, :mod:`evcd.loops.validation`,
:mod:`evcd.loops.evaluate`) are the same for both tasks and every agent; what they need to know of a
task is here. The single target (:class:`Task`): rows are
:class:`~evcd.env.runners.base.EpisodeRow`\\ s, a row's score is the target's travel time. The fleet
(:class:`FleetTask`): rows are :class:`~evcd.env.runners.fleet.FleetEpisode`\\ s, scored by their
guided EVs' mean travel time; its episodes take the days in turn, and its runs also write
``fleet_trace.png``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from evcd.env.runners.base import EpisodeRunner, EpisodeSpec
from evcd.env.runners.fleet import FleetRunner
from evcd.loops.fleet import FleetSummary, FleetTrainState, fleet_spec, paired_fleet, summarize_fleet
from evcd.loops.fleet_figure import plot_fleet_traces
from evcd.loops.run_files import EVAL_CSV, FLEET_CSV, FLEET_PNG, FLEET_TRAIN_CSV, TRAIN_CSV, baseline_csv
from evcd.loops.seeds import EVAL_STREAM, bootstrap_rng, episode_specs
from evcd.loops.stats import EvalResult, EvalSummary, paired_difference, summarize
from evcd.loops.train_state import TrainState


class Task:
    """The single target's episodes (the base: a task overrides what differs)."""

    name: ClassVar[str] = "single"
    #: the training state its checkpoints hold
    state: ClassVar[type[TrainState]] = TrainState
    train_csv: ClassVar[str] = TRAIN_CSV
    eval_csv: ClassVar[str] = EVAL_CSV
    #: options of the learning curve (:func:`~evcd.loops.curves.plot_learning_curve`)
    curve: ClassVar[Mapping[str, Any]] = MappingProxyType({})

    def specs(
        self, seed: int, episodes: int, runner: EpisodeRunner, stream: int = EVAL_STREAM
    ) -> list[EpisodeSpec]:
        """The first ``episodes`` episodes of ``stream`` of run ``seed`` (each draws its day)."""
        return episode_specs(seed, range(episodes), stream)

    def summarize(self, rows: Sequence[Any], rng: np.random.Generator, resamples: int) -> EvalSummary:
        """The run's summary (:func:`~evcd.loops.stats.summarize`)."""
        return summarize(rows, rng, resamples)

    def paired(
        self, rows: Sequence[Any], baseline: Sequence[Any], seed: int, resamples: int
    ) -> dict[str, Any]:
        """The agent minus a baseline on the same episodes (:func:`~evcd.loops.stats.paired_difference`;
        the interval from the run's bootstrap stream)."""
        return paired_difference(rows, baseline, bootstrap_rng(seed), resamples)

    def score(self, summary: Any) -> float:
        """The summary's headline: the mean travel time (what a sweeper minimises)."""
        return float(summary.mean_travel_time)

    def score_pair(self, paired: Mapping[str, Any]) -> Mapping[str, Any]:
        """The headline of a paired comparison (``mean_difference``, ``ci_low``, ...)."""
        return paired

    def baseline_csv(self, rule: str) -> str:
        """The episodes file of the baseline ``rule``."""
        return baseline_csv(rule)

    def curve_title(self, agent: str) -> str:
        """The learning curve's title."""
        return f"{agent}: travel time per training episode"

    def figures(
        self,
        run_dir: Path,
        evaluation: EvalResult,
        baselines: Mapping[str, EvalResult],
        runner: EpisodeRunner,
    ) -> None:
        """The task's own figures of an evaluation (none for the single target)."""


class FleetTask(Task):
    """The fleet's episodes (see the module docstring)."""

    name = "fleet"
    state = FleetTrainState
    train_csv = FLEET_TRAIN_CSV
    eval_csv = FLEET_CSV
    curve = MappingProxyType({"window": 10, "travel_label": "guided EVs' mean travel time",
                              "switches_label": "switches per guided EV"})  # fmt: skip

    def specs(
        self, seed: int, episodes: int, runner: EpisodeRunner, stream: int = EVAL_STREAM
    ) -> list[EpisodeSpec]:
        """The first ``episodes`` fleet episodes of ``stream``, the runner's days in turn
        (:func:`~evcd.loops.fleet.fleet_spec`)."""
        days = len(_fleet(runner).env.days)
        return [fleet_spec(seed, i, days, stream) for i in range(episodes)]

    def summarize(self, rows: Sequence[Any], rng: np.random.Generator, resamples: int) -> FleetSummary:
        """The fleet run's summary (:func:`~evcd.loops.fleet.summarize_fleet`)."""
        return summarize_fleet(rows, rng, resamples)

    def paired(
        self, rows: Sequence[Any], baseline: Sequence[Any], seed: int, resamples: int
    ) -> dict[str, dict[str, Any]]:
        """Per measure, the agent minus a baseline (:func:`~evcd.loops.fleet.paired_fleet`)."""
        return paired_fleet(rows, baseline, seed, resamples)

    def score(self, summary: Any) -> float:
        """The guided EVs' mean travel time."""
        return float(summary.guided_travel)

    def score_pair(self, paired: Mapping[str, Any]) -> Mapping[str, Any]:
        """The guided EVs' paired difference."""
        return paired["guided_travel"]

    def baseline_csv(self, rule: str) -> str:
        """The fleet episodes file of the baseline ``rule``."""
        return baseline_csv(rule, fleet=True)

    def curve_title(self, agent: str) -> str:
        """The learning curve's title."""
        return f"{agent} on the fleet: guided EVs' mean travel time per training episode"

    def figures(
        self,
        run_dir: Path,
        evaluation: EvalResult,
        baselines: Mapping[str, EvalResult],
        runner: EpisodeRunner,
    ) -> None:
        """``fleet_trace.png``: the first evaluation episode of the agent and of each baseline."""
        first = evaluation.rows[0]
        traces = {evaluation.agent: first.trace, **{n: b.rows[0].trace for n, b in baselines.items()}}
        stations = [st.id for st in _fleet(runner).env.stations]
        title = f"evaluation episode 0 (day {first.day}, {first.measures.guided} guided EVs)"
        plot_fleet_traces(traces, stations, run_dir / FLEET_PNG, title=title)


def _fleet(runner: EpisodeRunner) -> FleetRunner:
    if not isinstance(runner, FleetRunner):
        raise TypeError(f"a fleet task needs a FleetRunner, not {type(runner).__name__}")
    return runner


#: The tasks by name.
TASKS: dict[str, Task] = {task.name: task for task in (Task(), FleetTask())}


def task_of(runner: EpisodeRunner) -> Task:
    """The task of ``runner``'s episodes (:attr:`~evcd.env.runners.base.EpisodeRunner.task`)."""
    return TASKS[getattr(runner, "task", "single")]
