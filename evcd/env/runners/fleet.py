"""Fleet episodes behind the runner interface (``task=fleet``): one dispatcher for every guided EV.

    runner = FleetRunner(FleetEnv(evs=600))
    played = runner.run(specs, agent, explore=True, learn=True, on_episode=log_row)   # FleetEpisodes

At every tick the guided EVs due together are decided in ONE :meth:`Policy.decide` call (``(k, 4m)``
observations, one episode state per guided EV), so a centralised rule sees them all and a network
does one forward pass. A learning dispatcher is the independent-learners baseline with parameter
sharing: one network for every guided EV, each EV's transitions handed to ``observe`` with its own
episode state (so n-step returns or rollouts never mix two EVs), then its ``end_episode``; an EV
that could no longer be observed (:data:`~evcd.env.episode_rules.UNOBSERVED`) ends without its last
transition, as in the single-target engines.

Seeds: the spec gives the ``reset`` seed (day and guided EVs) and a ``SeedSequence`` from which each
guided EV, in the order it appears, gets its own generator.
"""

from __future__ import annotations

import math
import time as wallclock
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evcd.env.episode_rules import UNOBSERVED
from evcd.env.fleet import FleetEnv
from evcd.env.fleet.measures import FleetMeasures
from evcd.env.runners.base import EnvRunner, EpisodeSpec, Policy
from evcd.env.transition import Transition


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

    @property
    def steps(self) -> int:
        """Agent steps (decisions) in the episode, as :attr:`EpisodeRow.steps`."""
        return self.transitions

    @property
    def travel_time(self) -> float:
        """The guided EVs' mean travel time (NaN if none charged): the episode's score."""
        return float(self.measures.guided_travel)

    @property
    def truncated(self) -> bool:
        """No guided EV charged."""
        return not math.isfinite(self.travel_time)

    def charts(self) -> dict[str, float]:
        """What a training curve shows of the episode (TensorBoard ``charts/<key>``; finite values)."""
        row = self.row()
        keys = ("guided_travel", "all_travel", "queue_wait", "herding", "switches", "truncated")
        return {k: float(row[k]) for k in keys if math.isfinite(float(row[k]))}


class FleetRunner(EnvRunner):
    """Fleet episodes one after another in one :class:`~evcd.env.fleet.FleetEnv` (each starts a fresh
    SUMO from its window's snapshot). Rows are :class:`FleetEpisode`\\ s.

    Args:
        env: the fleet; the runner closes it in :meth:`close`.
    """

    task = "fleet"

    def __init__(self, env: FleetEnv) -> None:
        super().__init__(env)

    def run(  # type: ignore[override]
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: Callable[[FleetEpisode], None] | None = None,
    ) -> list[FleetEpisode]:
        """Play ``specs`` in order; one :class:`FleetEpisode` each."""
        played = []
        for spec in specs:
            played.append(self.episode(spec, agent, explore=explore, learn=learn))
            if on_episode is not None:
                on_episode(played[-1])
        return played

    def episode(self, spec: EpisodeSpec, agent: Policy, *, explore: bool = False, learn: bool = False
                ) -> FleetEpisode:  # fmt: skip
        """Play the fleet episode ``spec`` with ``agent`` deciding for every guided EV.

        Args:
            spec: the episode (its ``reset`` seed and agents' seed sequence; ``options`` go to ``reset``).
            agent: the dispatcher (rules or a learner).
            explore: a learner may explore.
            learn: hand every agent step to ``agent.observe`` (with that EV's episode state), then
                each EV's end to ``agent.end_episode``.
        """
        env = self.env
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
                    if not (truncs[a] and infos[a].get("reason") in UNOBSERVED):
                        step = Transition(obs[a], chosen[a], float(rewards[a]), next_obs[a], bool(terms[a]),
                                          bool(truncs[a]))  # fmt: skip
                        agent.observe(step, states[a])
                    if terms[a] or truncs[a]:
                        agent.end_episode(states[a])
            obs = next_obs
        day = env.days[env.day].demand_seed if env.day is not None else -1
        return FleetEpisode(spec.index, day, env.measures(), returns, transitions,
                            wallclock.perf_counter() - t0, list(env.trace))  # fmt: skip
