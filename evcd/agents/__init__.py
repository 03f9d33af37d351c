"""Dispatchers: who picks the charging station.

    rng = np.random.default_rng(seed)
    agent = make_agent("greedy", n_stations=5, rng=rng)      # or make_agent_for_env("greedy", env, rng)
    agent = make_agent("dueling_ddqn", 5, rng, lr=1e-3)      # DQNAgent(double=True, dueling=True)

Agents are dispatchers only: they decide, and learners learn from transitions; they never play
episodes themselves (the runners of :mod:`evcd.env.runners` do, and the loops of :mod:`evcd.loops`
drive them; the best station in hindsight, a bound rather than a policy, is
:mod:`evcd.loops.hindsight`).

The registry maps a name to a class path (imported on first use, so that the heuristics do not pay
for torch) and to the defaults that name implies: ``dqn`` and ``dueling_ddqn`` are the one
:class:`~evcd.agents.dqn.DQNAgent` with its two switches off or on.

Two registered rules need the fleet's observation ``[D, N, Z, H]`` (:mod:`evcd.env.fleet`,
:mod:`evcd.agents.fleet_rules`): ``reservation`` and ``central``. :data:`AGENT_NAMES` lists the
dispatchers of the single environment (each has its ``conf/agent/<name>.yaml``), which the fleet-only
rules are not; :data:`FLEET_AGENT_NAMES` lists the agents that take the fleet's observation.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from evcd.agents.base import (
    OBSERVATION_LAYOUTS,
    Agent,
    EpisodeState,
    Transition,
    observation_blocks,
    observation_units,
    split_observation,
)

#: Agent name -> (``module:Class``, the constructor arguments that name implies).
_REGISTRY: dict[str, tuple[str, dict[str, Any]]] = {
    "random": ("evcd.agents.heuristics:RandomAgent", {}),
    "greedy": ("evcd.agents.heuristics:GreedyAgent", {}),
    "queue_aware": ("evcd.agents.heuristics:QueueAwareAgent", {}),
    "dqn": ("evcd.agents.dqn:DQNAgent", {"double": False, "dueling": False}),
    "dueling_ddqn": ("evcd.agents.dqn:DQNAgent", {"double": True, "dueling": True}),
    "reservation": ("evcd.agents.fleet_rules:ReservationAgent", {}),
    "central": ("evcd.agents.fleet_rules:CentralAgent", {}),
}
#: The registered agents that read only the fleet's observation ``[D, N, Z, H]``.
_FLEET_ONLY: tuple[str, ...] = ("reservation", "central")
#: The dispatchers of the single environment (``[D, N, Z]``; each has ``conf/agent/<name>.yaml``).
AGENT_NAMES: tuple[str, ...] = tuple(name for name in _REGISTRY if name not in _FLEET_ONLY)
#: The agents that take the fleet's observation ``[D, N, Z, H]`` (:mod:`evcd.env.fleet`).
FLEET_AGENT_NAMES: tuple[str, ...] = ("random", "greedy", "queue_aware", *_FLEET_ONLY)


def agent_class(name: str) -> type[Agent]:
    """The agent class registered as ``name``.

    Raises:
        ValueError: ``name`` is not registered (the message lists the registered names).
    """
    if name not in _REGISTRY:
        raise ValueError(f"agent {name!r} is unknown; known agents: {', '.join(_REGISTRY)}")
    module, _, cls_name = _REGISTRY[name][0].partition(":")
    return getattr(importlib.import_module(module), cls_name)


def agent_defaults(name: str) -> dict[str, Any]:
    """The constructor arguments the name ``name`` implies (e.g. ``dueling_ddqn``: both switches on)."""
    agent_class(name)
    return dict(_REGISTRY[name][1])


def _check_kwargs(cls: type[Agent], name: str, kwargs: dict[str, Any]) -> None:
    params = cls.option_names()
    unknown = sorted(set(kwargs) - set(params))
    if unknown:
        raise ValueError(f"agent {name!r}: unknown options {unknown}; it takes {params or 'none'}")


def make_agent(name: str, n_stations: int, rng: np.random.Generator, **kwargs: Any) -> Agent:
    """A new agent ``name`` for ``n_stations`` stations drawing from ``rng``; ``kwargs`` go to its class.

    Raises:
        ValueError: unknown agent or option, or a bad value (each message names it).
    """
    cls = agent_class(name)
    _check_kwargs(cls, name, kwargs)
    return cls(n_stations, rng, **{**agent_defaults(name), **kwargs})


def make_agent_for_env(name: str, env: Any, rng: np.random.Generator, **kwargs: Any) -> Agent:
    """:func:`make_agent` with the number of stations and the settings the agent needs read off
    ``env`` (a :class:`~evcd.env.ChargingNavEnv`, wrapped or not); ``kwargs`` override them."""
    cls = agent_class(name)
    _check_kwargs(cls, name, kwargs)
    return cls.from_env(env, rng, **{**agent_defaults(name), **kwargs})


__all__ = [
    "AGENT_NAMES",
    "FLEET_AGENT_NAMES",
    "OBSERVATION_LAYOUTS",
    "Agent",
    "EpisodeState",
    "Transition",
    "agent_class",
    "agent_defaults",
    "make_agent",
    "make_agent_for_env",
    "observation_blocks",
    "observation_units",
    "split_observation",
]
