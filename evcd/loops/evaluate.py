"""Run a dispatcher on evaluation episodes and summarise its travel times.

    result = evaluate(runner, agent, episodes=50, seed=0)          # or a plain ChargingNavEnv
    write_episodes_csv(result, run_dir / "episodes.csv")           # evcd.loops.run_files
    write_results_json(result, run_dir / "results.json", config=...)

Episode ``i`` of run ``seed`` is the same for every dispatcher (:mod:`evcd.loops.seeds`), so two
dispatchers evaluated with the same seed are compared on the same episodes. Episodes are played by a
runner (:mod:`evcd.env.runners`); a dispatcher is an agent (played without exploration, and never
learning: :meth:`~evcd.agents.Agent.observe` is not called), the hindsight bound
(:mod:`evcd.loops.hindsight`) or, on the fleet, the clairvoyant bound (:mod:`evcd.loops.fleet_bound`).
Only episodes that end by charging enter the travel-time statistics
(:mod:`evcd.loops.stats`); truncated ones are counted and listed. The same function evaluates on the
fleet (a :class:`~evcd.env.runners.fleet.FleetRunner`): its episodes take the days in turn and its
summary is the fleet's (:mod:`evcd.loops.tasks`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import gymnasium

from evcd.agents.base import Agent
from evcd.env.runners import EpisodeRow, EpisodeRunner, EpisodeSpec, SingleEnvRunner
from evcd.loops.fleet_bound import FleetBound
from evcd.loops.hindsight import HindsightBound
from evcd.loops.progress import EpisodeProgress
from evcd.loops.seeds import bootstrap_rng, check_seed, episode_spec
from evcd.loops.stats import BOOTSTRAP_RESAMPLES, EvalResult
from evcd.loops.tasks import task_of
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

#: What a run evaluates: an agent, or a bound (the single target's hindsight, the fleet's clairvoyant).
Dispatcher = Agent | HindsightBound | FleetBound
#: The bounds: measurements that play their own runs (:meth:`HindsightBound.play`), not policies.
BOUNDS = (HindsightBound, FleetBound)


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


def play(
    runner: EpisodeRunner, dispatcher: Dispatcher, specs: Sequence[EpisodeSpec], on_episode: Any = None
) -> tuple[list[EpisodeRow], dict[str, Any]]:
    """Play ``specs`` without exploration or learning: the rows (in spec order) and the dispatcher's
    extra results for ``results.json`` (a bound's report: the hindsight bound's per-station times, the
    fleet bound's per-episode bound; none for an agent)."""
    if isinstance(dispatcher, BOUNDS):
        return dispatcher.play(runner, specs, on_episode=on_episode), dispatcher.report()
    return runner.run(specs, dispatcher, explore=False, learn=False, on_episode=on_episode), {}


def evaluate(
    env: gymnasium.Env | EpisodeRunner,
    agent: Dispatcher,
    episodes: int,
    seed: int,
    progress: bool = True,
    resamples: int = BOOTSTRAP_RESAMPLES,
    specs: Sequence[EpisodeSpec] | None = None,
) -> EvalResult:
    """Run ``agent`` for ``episodes`` episodes, without exploration or learning.

    Args:
        env: a :class:`~evcd.env.ChargingNavEnv` (or any env with its ``info`` keys), or a runner
            (:mod:`evcd.env.runners`, a fleet's included). It is not closed here.
        agent: the dispatcher: an agent, or a bound (hindsight; the fleet's clairvoyant bound).
        episodes: number of episodes (>= 1).
        seed: the run seed (>= 0): the episodes and the bootstrap derive from it.
        progress: show a tqdm progress bar (on stderr).
        resamples: bootstrap resamples of the confidence interval.
        specs: the episodes to run (default: the first ``episodes`` of the evaluation stream of
            ``seed``, the task's :meth:`~evcd.loops.tasks.Task.specs`); ``episodes`` must equal their
            number.

    Raises:
        ValueError: ``episodes`` or ``seed`` out of range.
    """
    episodes = check_int("episodes", episodes, minimum=1)
    seed = check_seed(seed)
    runner = as_runner(env)
    task = task_of(runner)
    if specs is None:
        specs = task.specs(seed, episodes, runner)
    elif len(specs) != episodes:
        raise ValueError(f"episodes={episodes} but {len(specs)} specs given")
    runs = agent.runs_per_episode if isinstance(agent, BOUNDS) else 1
    bar = EpisodeProgress(len(specs) * runs, f"evaluate {agent.name}", progress)
    try:
        rows, extra = play(runner, agent, specs, on_episode=bar)
    finally:
        bar.close()
    for row in rows:
        log.debug("%s", row)
    summary = task.summarize(rows, bootstrap_rng(seed), resamples)
    return EvalResult(agent.name, seed, tuple(rows), summary, extra, task.name)
