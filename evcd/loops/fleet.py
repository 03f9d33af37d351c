"""Play fleet episodes (:mod:`evcd.env.fleet`) with one dispatcher for all guided EVs.

At every tick the agents due together are decided in ONE :meth:`~evcd.agents.Agent.decide` call
(``(k, 4m)`` observations, one episode state per guided EV), so a centralised rule sees them all and a
network does one forward pass. A learning dispatcher is the independent-learners baseline with
parameter sharing: one network for every guided EV, every EV's transitions into its one replay (each
EV has its own episode state, so n-step returns never mix two EVs).

Seeds: the episode's ``EpisodeSpec`` gives the ``reset`` seed (day and guided EVs) and a
``SeedSequence`` from which each guided EV, in the order it appears, gets its own generator. Training
episodes draw their day from that seed; evaluation and validation episodes take the env's days in turn
(:func:`fleet_spec`), so that ``len(days)`` consecutive episodes are on distinct days: at
``guided_share`` 1 a fleet episode is fixed by its day, and a drawn day may repeat.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time as wallclock
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from evcd.agents import agent_names, check_agent_task
from evcd.env.episode_rules import UNOBSERVED
from evcd.env.fleet import FleetEnv
from evcd.env.fleet.measures import FleetMeasures
from evcd.env.runners.base import EpisodeSpec, Policy
from evcd.env.transition import Transition
from evcd.loops.seeds import EVAL_STREAM, TRAIN_STREAM, bootstrap_rng, episode_spec
from evcd.loops.stats import bootstrap_ci
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)


@dataclass
class FleetEpisode:
    """What one fleet episode gave.

    Attributes:
        index: the episode's number in its run.
        day: the background day's demand seed.
        measures: :class:`~evcd.env.fleet.measures.FleetMeasures`.
        returns: each guided agent's summed reward.
        transitions: agent steps played (decisions).
        wall_s: seconds it took.
        trace: the env's per-tick trace (time, vehicles at each station, guided EVs heading to each).
    """

    index: int
    day: int
    measures: FleetMeasures
    returns: dict[str, float]
    transitions: int
    wall_s: float
    trace: list[tuple[float, tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)

    def row(self) -> dict[str, Any]:
        """One flat row (for CSV / JSON)."""
        return {"episode": self.index, "day": self.day, "transitions": self.transitions,
                "wall_s": round(self.wall_s, 3), **self.measures.to_dict()}  # fmt: skip


def fleet_spec(seed: int, index: int, days: int, stream: int = EVAL_STREAM) -> EpisodeSpec:
    """Fleet episode ``index`` of ``stream`` of run ``seed`` on the env's day ``index mod days`` (days in
    turn): its reset seed (which draws the guided EVs) and agents' seeds are :func:`episode_spec`'s."""
    check_int("days", days, minimum=1)
    spec = episode_spec(seed, index, stream)
    return dataclasses.replace(spec, options={"day": index % days})


def play_fleet(
    env: FleetEnv, agent: Policy, spec: EpisodeSpec, *, explore: bool = False, learn: bool = False
) -> FleetEpisode:
    """Play the fleet episode ``spec`` with ``agent`` deciding for every guided EV.

    Args:
        env: the fleet.
        agent: the dispatcher (rules or a learner).
        spec: the episode (its ``reset`` seed and agents' seed sequence; ``options`` go to ``reset``).
        explore: a learner may explore.
        learn: hand every agent step to ``agent.observe`` (with that EV's episode state).
    """
    t0 = wallclock.perf_counter()
    obs, _ = env.reset(seed=spec.reset_seed, options=dict(spec.options) if spec.options else None)
    states: dict[str, Any] = {}
    returns: dict[str, float] = {}
    seeds = spec.agent_seed

    def admit(agents: list[str]) -> None:
        for a in agents:
            if a not in states:
                (child,) = seeds.spawn(1)
                states[a] = agent.new_episode(np.random.default_rng(child))
                returns[a] = 0.0

    admit(env.agents)
    transitions = 0
    while env.agents:
        due = list(env.agents)
        batch = np.stack([obs[a] for a in due])
        actions = agent.decide(batch, [states[a] for a in due], explore)
        chosen = {a: int(x) for a, x in zip(due, actions, strict=True)}
        next_obs, rewards, terms, truncs, infos = env.step(chosen)
        transitions += len(due)
        admit([a for a in next_obs if a not in states])
        for a, r in rewards.items():
            returns[a] += r
        if learn:
            for a in due:
                ended = bool(terms[a]) or bool(truncs[a])
                if not (truncs[a] and infos[a].get("reason") in UNOBSERVED):
                    step = Transition(obs[a], chosen[a], float(rewards[a]), next_obs[a], bool(terms[a]),
                                      bool(truncs[a]))  # fmt: skip
                    agent.observe(step, states[a])
                if ended:
                    agent.end_episode(states[a])
        obs = next_obs
    day = env.days[env.day].demand_seed if env.day is not None else -1
    return FleetEpisode(spec.index, day, env.measures(), returns, transitions,
                        wallclock.perf_counter() - t0, list(env.trace))  # fmt: skip


def train_fleet(
    env: FleetEnv, agent: Policy, episodes: int, seed: int, *, progress: bool = False
) -> list[FleetEpisode]:
    """Train a learning dispatcher on ``episodes`` fleet episodes (the training stream of ``seed``,
    disjoint from the evaluation's): every guided EV explores through its own episode state and every
    agent step goes to :meth:`observe` (independent learners sharing one network and one replay)."""
    played = []
    with tqdm(total=episodes, desc="fleet training", unit="ep", disable=not progress) as bar:
        for i in range(episodes):
            played.append(
                play_fleet(env, agent, episode_spec(seed, i, TRAIN_STREAM), explore=True, learn=True)
            )
            bar.update(1)
    return played


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
    env: FleetEnv, agent: Policy, episodes: int, seed: int, *, progress: bool = True, resamples: int = 10_000
) -> tuple[list[FleetEpisode], dict[str, Any]]:
    """Play ``episodes`` fleet episodes (evaluation stream of ``seed``, the env's days in turn:
    :func:`fleet_spec`; no exploration); return them and their summary: per measure the mean over
    episodes, and for the guided and all-EV travel times the 95 % bootstrap interval of the mean over
    episodes (each episode's mean is one value).

    ``distinct_episodes`` counts the episodes that differ in day or guided agents: at ``guided_share``
    1 nothing is drawn, so an episode is fixed by its day and two episodes of one day are the same
    episode played twice (a deterministic policy then repeats its result, and the interval counts
    the copies as independent); a warning says so when it happens (more episodes than days at share 1)."""
    played: list[FleetEpisode] = []
    with tqdm(
        total=episodes, desc=f"fleet {getattr(agent, 'name', '')}", unit="ep", disable=not progress
    ) as bar:
        for i in range(episodes):
            played.append(play_fleet(env, agent, fleet_spec(seed, i, len(env.days))))
            bar.update(1)
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
