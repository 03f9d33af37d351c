"""The fleet's episodes in the loops (:mod:`evcd.env.fleet`, played by
:class:`~evcd.env.runners.fleet.FleetRunner`): which episodes, which dispatchers, and the evaluation.

Training episodes draw their day from their seed; evaluation and validation episodes take the env's
days in turn (:func:`fleet_spec`), so that ``len(days)`` consecutive episodes are on distinct days: at
``guided_share`` 1 a fleet episode is fixed by its day, and a drawn day may repeat.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from tqdm import tqdm

from evcd.agents import agent_names, check_agent_task
from evcd.env.runners.base import EpisodeSpec, Policy
from evcd.env.runners.fleet import FleetEpisode, FleetRunner
from evcd.loops.seeds import EVAL_STREAM, bootstrap_rng, episode_spec
from evcd.loops.stats import bootstrap_ci
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)


def fleet_spec(seed: int, index: int, days: int, stream: int = EVAL_STREAM) -> EpisodeSpec:
    """Fleet episode ``index`` of ``stream`` of run ``seed`` on the env's day ``index mod days`` (days in
    turn): its reset seed (which draws the guided EVs) and agents' seeds are :func:`episode_spec`'s."""
    check_int("days", days, minimum=1)
    spec = episode_spec(seed, index, stream)
    return dataclasses.replace(spec, options={"day": index % days})


def check_fleet_dispatcher(name: Any) -> str:
    """``name`` if the fleet can be given it: a registered agent that reads ``[D, N, Z, H]`` (the
    rules, and the learners: one network shared by every guided EV).

    Raises:
        ValueError: not a fleet dispatcher (the message lists them).
    """
    if name not in agent_names():
        raise ValueError(f"agent {name!r} is not a fleet dispatcher (task=fleet); "
                         f"the fleet takes: {', '.join(agent_names('fleet'))}")  # fmt: skip
    check_agent_task(str(name), "fleet")
    return str(name)


def fleet_dispatcher_learns(name: Any) -> bool:
    """Whether the fleet dispatcher ``name`` learns (``ValueError`` if the fleet does not take it)."""
    return check_agent_task(check_fleet_dispatcher(name), "fleet").learns


def evaluate_fleet(
    runner: FleetRunner, agent: Policy, episodes: int, seed: int, *, progress: bool = True,
    resamples: int = 10_000,
) -> tuple[list[FleetEpisode], dict[str, Any]]:  # fmt: skip
    """Play ``episodes`` fleet episodes (evaluation stream of ``seed``, the env's days in turn:
    :func:`fleet_spec`; no exploration); return them and their summary: per measure the mean over
    episodes, and for the guided and all-EV travel times the 95 % bootstrap interval of the mean over
    episodes (each episode's mean is one value).

    ``distinct_episodes`` counts the episodes that differ in day or guided agents: at ``guided_share``
    1 nothing is drawn, so an episode is fixed by its day and two episodes of one day are the same
    episode played twice (a deterministic policy then repeats its result, and the interval counts
    the copies as independent); a warning says so when it happens (more episodes than days at share 1)."""
    env = runner.env
    specs = [fleet_spec(seed, i, len(env.days)) for i in range(episodes)]
    with tqdm(
        total=episodes, desc=f"fleet {getattr(agent, 'name', '')}", unit="ep", disable=not progress
    ) as bar:
        played = runner.run(specs, agent, on_episode=lambda _: bar.update(1))
    rng = bootstrap_rng(seed)
    summary: dict[str, Any] = {"episodes": episodes, "seed": seed}
    for key in ("guided_travel", "all_travel", "queue_wait", "herding", "guided_travel_censored"):
        values = np.array([getattr(ep.measures, key) for ep in played], dtype=np.float64)
        finite = values[np.isfinite(values)]
        summary[key] = float(finite.mean()) if finite.size else math.nan
        if key in ("guided_travel", "all_travel"):
            summary[f"{key}_ci"] = list(bootstrap_ci(finite, rng, resamples))
    for key in ("guided", "truncated", "all_unfinished", "transitions"):
        summary[key] = int(
            sum(ep.transitions if key == "transitions" else getattr(ep.measures, key) for ep in played)
        )
    summary["mean_wall_s"] = float(np.mean([ep.wall_s for ep in played]))
    summary["distinct_episodes"] = distinct = distinct_episodes(played)
    if distinct < len(played):
        log.warning(
            "%s: only %d of %d fleet episodes differ in day or guided EVs (guided_share %g; at 1 an "
            "episode is fixed by its day): the interval counts the repeats as independent episodes; "
            "evaluate on at least as many days as episodes, or with a guided_share below 1",
            getattr(agent, "name", "fleet"), distinct, len(played), env.guided_share,
        )  # fmt: skip
    return played, summary


def distinct_episodes(played: Sequence[FleetEpisode]) -> int:
    """How many of ``played`` differ in their day or in the set of guided EVs that became agents
    (episodes equal in both are the same deterministic episode)."""
    return len({(ep.day, frozenset(ep.returns)) for ep in played})
