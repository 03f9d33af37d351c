"""The fleet's cost: a fleet episode against the same window of its day simulated alone, and the
learner's speed on the fleet.

``fleet_overhead`` = wall time of a fleet episode (reset included: snapshot load, every guided EV
observing and deciding at every tick, greedy) / wall time of the same span of the same day, loaded
from the same snapshot and simulated with its charging points but nobody guided. Both are measured in
the same process, alternating, on the same episodes; the ratio of the sums is reported.
``fleet_transitions_per_second``: agent steps per second of wall time while a shared-parameter DQN
explores and learns on fleet episodes (training stream; reset and SUMO included); each row says the
span both runs simulated, and the learner's gradient steps say it learned while it was timed.
"""

from __future__ import annotations

import logging
import time as wallclock
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from evcd.agents import make_agent_for_env
from evcd.agents.dqn import DQNConfig
from evcd.agents.heuristics import GreedyAgent
from evcd.env.fleet import FleetEnv
from evcd.env.runners.fleet import FleetRunner
from evcd.loops.seeds import TRAIN_STREAM, episode_spec, episode_specs

log = logging.getLogger(__name__)


def fleet_overhead(env_kwargs: Mapping[str, Any], episodes: int = 3, seed: int = 0) -> dict[str, Any]:
    """Time ``episodes`` fleet episodes and the same spans of their days alone; return the figures.

    Args:
        env_kwargs: :class:`~evcd.env.fleet.FleetEnv` arguments (``guided_share`` 1 for the highest
            competition).
        episodes: episodes to time (evaluation stream of ``seed``).
        seed: run seed.
    """
    env = FleetEnv(**env_kwargs)
    try:
        env.prepare()
        fleet_s, alone_s, rows = 0.0, 0.0, []
        for i in range(episodes):
            spec = episode_spec(seed, i)
            t0 = wallclock.perf_counter()
            ep = FleetRunner(env).episode(spec, GreedyAgent(len(env.stations), np.random.default_rng(seed)))
            fleet = wallclock.perf_counter() - t0
            end = ep.trace[-1][0]
            sim = env.simulation
            t0 = wallclock.perf_counter()
            sim.close()  # as the fleet's reset: a fresh SUMO from the snapshot
            sim.start_at(env.day, env.config.departure_window[0])
            sim.driver.step(until=end)
            alone = wallclock.perf_counter() - t0
            fleet_s += fleet
            alone_s += alone
            start = env.config.departure_window[0]
            rows.append({"episode": i, "fleet_s": round(fleet, 3), "alone_s": round(alone, 3),
                         "sim_span_s": end - start, "alone_span_s": sim.driver.time - start,
                         "decisions": ep.transitions, "guided": ep.measures.guided})  # fmt: skip
            log.info("fleet episode %d: %.1f s, the day alone %.1f s (%d guided EVs, %d decisions)",
                     i, fleet, alone, ep.measures.guided, ep.transitions)  # fmt: skip
    finally:
        env.close()
    return {
        "fleet_overhead": fleet_s / alone_s if alone_s > 0 else None,
        "goals": {"fleet_overhead": "<= 1.5"},
        "episodes": rows,
    }


def fleet_learning_rate(
    env_kwargs: Mapping[str, Any], config: DQNConfig, episodes: int = 2, seed: int = 0
) -> dict[str, Any]:
    """Agent steps per second while Dueling DDQN (``config``) learns on ``episodes`` fleet episodes, on
    one torch thread as ``scripts/train.py`` learns (``torch_threads``: beside a second job, a second
    thread made the learner's updates ten times slower here)."""
    torch.set_num_threads(1)
    env = FleetEnv(**env_kwargs)
    try:
        env.prepare()
        agent = make_agent_for_env("dueling_ddqn", env, np.random.default_rng(seed), config=config)
        t0 = wallclock.perf_counter()
        specs = episode_specs(seed, range(episodes), TRAIN_STREAM)
        played = FleetRunner(env).run(specs, agent, explore=True, learn=True)
        wall = wallclock.perf_counter() - t0
    finally:
        env.close()
    steps = sum(ep.transitions for ep in played)
    log.info("fleet learning: %d agent steps in %.1f s (%d episodes)", steps, wall, episodes)
    return {"fleet_transitions_per_second": steps / wall, "transitions": steps, "wall_s": wall,
            "episodes": episodes, "gradient_steps": agent.stats()["gradient_steps"]}  # fmt: skip
