"""The agent interface shared by the dispatchers: heuristics and learning agents (DQN).

An agent maps the environment's observation ``[D, N, Z]`` (see :mod:`evcd.env.observation`) to a
station index. The runner that drives it (:mod:`evcd.env.runner`, for the trainer and the
evaluation) calls

    agent.begin_episode(rng)              # after env.reset(): forget the last episode
    action = agent.act(obs, explore)      # once per decision slot
    agent.observe(Transition(...))        # learning agents only: after every env.step()

Every source of randomness is a ``numpy.random.Generator`` handed in (at construction, optionally
replaced per episode), never the global one, so a run is reproducible from its seed.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, Self

import numpy as np

from evcd.env.runner import Transition


def split_observation(obs: np.ndarray, n_stations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(D, N, Z)``: the three length-``n_stations`` parts of an observation vector.

    Raises:
        ValueError: ``obs`` is not a flat vector of length ``3 * n_stations``.
    """
    vec = np.asarray(obs)
    if vec.shape != (3 * n_stations,):
        raise ValueError(
            f"observation of shape {vec.shape}: expected ({3 * n_stations},) = [D, N, Z] for "
            f"{n_stations} stations"
        )
    return vec[:n_stations], vec[n_stations : 2 * n_stations], vec[2 * n_stations :]


class Agent(ABC):
    """A dispatcher: picks the station the target drives to, once per decision slot.

    Args:
        n_stations: number of stations ``m`` (the action space is ``Discrete(m)``).
        rng: the agent's random generator (derive it from the run seed).

    Subclasses set :attr:`name` (the registry key, see :func:`evcd.agents.make_agent`) and implement
    :meth:`act`; learning agents also override :meth:`observe`.
    """

    name: ClassVar[str]
    #: Whether the agent learns from :meth:`observe` (the trainer runs a training phase for it).
    learns: ClassVar[bool] = False

    def __init__(self, n_stations: int, rng: np.random.Generator) -> None:
        if isinstance(n_stations, bool) or not isinstance(n_stations, int | np.integer) or n_stations < 1:
            raise ValueError(f"n_stations={n_stations!r}: must be an integer >= 1")
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng={rng!r}: must be a numpy.random.Generator (derive it from the run seed)")
        self.n_stations = int(n_stations)
        self.rng = rng

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """Constructor arguments this agent reads off an environment (beyond ``n_stations``).

        Agents whose behaviour depends on the environment's settings (observation scaling, charging
        points, observation size, ...) override this; :func:`evcd.agents.make_agent_for_env` uses it.
        """
        del env
        return {}

    def begin_episode(self, rng: np.random.Generator | None = None) -> None:
        """Start an episode (call after every ``env.reset()``).

        Args:
            rng: if given, the generator the agent draws from from now on (e.g. one derived from the
                episode's seed, so that an episode does not depend on the ones run before it).
        """
        if rng is not None:
            self.rng = rng

    @abstractmethod
    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station to drive to, given the observation of the current slot.

        Args:
            obs: the environment's observation ``[D, N, Z]`` (float32, length ``3 * n_stations``).
            explore: whether a learning agent may explore (training); heuristics ignore it.
        """

    def act_batch(self, obs: np.ndarray, explore: bool = False) -> np.ndarray:
        """:meth:`act` for observations ``(k, 3m)`` of ``k`` targets due at the same time (a runner
        that co-simulates episodes may call it); agents with a network override it with one
        forward pass. This default calls :meth:`act` row by row."""
        return np.array([self.act(o, explore) for o in np.asarray(obs)], dtype=np.int64)

    def observe(self, transition: Transition) -> None:  # noqa: B027  (a hook: no-op by default)
        """Learning hook, called after every step while training; the heuristics ignore it."""

    def stats(self) -> dict[str, float]:
        """Learning statistics for logs (cumulative counters and current schedules); none here."""
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_stations={self.n_stations})"

    @classmethod
    def from_env(cls, env: Any, rng: np.random.Generator, **kwargs: Any) -> Self:
        """This agent for ``env`` (its number of stations and :meth:`env_kwargs`), plus ``kwargs``."""
        return cls(int(env.action_space.n), rng, **{**cls.env_kwargs(env), **kwargs})
