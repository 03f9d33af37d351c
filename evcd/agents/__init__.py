"""Dispatchers: who picks the charging station.

    rng = np.random.default_rng(seed)
    agent = make_agent("greedy", n_stations=5, rng=rng)      # or make_agent_for_env("greedy", env, rng)
    agent = make_agent("dueling_ddqn", 5, rng, lr=1e-3)      # DQNAgent(double=True, dueling=True)

Agents are dispatchers only: they decide, and learners learn from transitions; they never play
episodes themselves (the runners of :mod:`evcd.env.runners` do, and the loops of :mod:`evcd.loops`
drive them; the best station in hindsight, a bound rather than a policy, is
:mod:`evcd.loops.hindsight`).

The registry (:mod:`evcd.agents.registry`) maps a name to a class and to the defaults that name
implies: ``dqn`` and ``dueling_ddqn`` are the one :class:`~evcd.agents.dqn.DQNAgent` with its two
switches off or on. Other packages add agents with :func:`register_agent` or an entry point in the
group ``evcd.agents``; the tasks an agent takes are the observation layouts it declares
(:func:`agent_names`: ``"single"``, ``[D, N, Z]``; ``"fleet"``, ``[D, N, Z, H]``, which only the
fleet's rules ``reservation`` and ``central`` read alone, and ``planned``, which plays a plan by vehicle
id on the fleet, :mod:`evcd.agents.planned`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from evcd.agents.base import (
    OBSERVATION_LAYOUTS,
    Agent,
    EpisodeState,
    Transition,
    observation_blocks,
    observation_layout,
    observation_letters,
    observation_units,
    split_observation,
)
from evcd.agents.registry import (
    ENTRY_POINT_GROUP,
    TASK_BLOCKS,
    agent_class,
    agent_defaults,
    agent_names,
    check_agent_task,
    check_options,
    register_agent,
    unregister_agent,
)


def make_agent(name: str, n_stations: int, rng: np.random.Generator, **kwargs: Any) -> Agent:
    """A new agent ``name`` for ``n_stations`` stations drawing from ``rng``; ``kwargs`` go to its class.

    Raises:
        ValueError: unknown agent or option, or a bad value (each message names it).
    """
    cls = agent_class(name)
    check_options(cls, name, kwargs)
    return cls(n_stations, rng, **{**agent_defaults(name), **kwargs})


def make_agent_for_env(name: str, env: Any, rng: np.random.Generator, **kwargs: Any) -> Agent:
    """:func:`make_agent` with the number of stations and the settings the agent needs read off
    ``env`` (a :class:`~evcd.env.ChargingNavEnv`, wrapped or not); ``kwargs`` override them."""
    cls = agent_class(name)
    check_options(cls, name, kwargs)
    return cls.from_env(env, rng, **{**agent_defaults(name), **kwargs})


__all__ = [
    "ENTRY_POINT_GROUP",
    "OBSERVATION_LAYOUTS",
    "TASK_BLOCKS",
    "Agent",
    "EpisodeState",
    "Transition",
    "agent_class",
    "agent_defaults",
    "agent_names",
    "check_agent_task",
    "make_agent",
    "make_agent_for_env",
    "observation_blocks",
    "observation_layout",
    "observation_letters",
    "observation_units",
    "register_agent",
    "split_observation",
    "unregister_agent",
]
