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
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Self

import numpy as np

from evcd.env.runner import EpisodeRow, EpisodeRunner, EpisodeSpec, Transition


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

    # ------------------------------------------------------------------ many episodes at once
    def episode_state(self) -> Any:
        """What the agent keeps about the current episode (by default its generator), so that a
        runner with several episodes in flight (the batched engine) can switch between them:
        ``state = agent.episode_state()`` after ``begin_episode``, later
        ``agent.set_episode_state(state)`` before acting for that episode. Agents with more
        per-episode state (a station drawn at departure, ...) override both."""
        return self.rng

    def set_episode_state(self, state: Any) -> None:
        """Make ``state`` (from :meth:`episode_state`) the current episode's."""
        self.rng = state

    def act_episodes(
        self, obs: np.ndarray, states: Sequence[Any], explore: bool = False
    ) -> tuple[np.ndarray, list[Any]]:
        """Decide for ``k`` targets of different episodes due at the same time: observations
        ``(k, 3m)`` and each episode's state; returns the actions and the updated states. The
        result equals calling :meth:`act` for each in turn with its state current; agents with a
        network override it with one forward pass."""
        actions, out = [], []
        for o, state in zip(np.asarray(obs), states, strict=True):
            self.set_episode_state(state)
            actions.append(self.act(o, explore))
            out.append(self.episode_state())
        return np.array(actions, dtype=np.int64), out

    # ------------------------------------------------------------------ how the agent is played
    @property
    def runs_per_episode(self) -> int:
        """Runs of an episode that :meth:`play` makes (one for a policy)."""
        return 1

    def play(
        self,
        runner: EpisodeRunner,
        specs: Sequence[EpisodeSpec],
        explore: bool = False,
        learn: bool = False,
        on_episode: Callable[[EpisodeRow], None] | None = None,
    ) -> list[EpisodeRow]:
        """Play the episodes ``specs`` through ``runner``; one row per spec, in spec order.

        A policy is simply run (``runner.run``). Agents that are not a policy but a measurement
        built from several runs of each episode (the hindsight bound) override it; ``on_episode``
        then sees every run (:attr:`runs_per_episode` per episode).
        """
        return runner.run(specs, self, explore=explore, learn=learn, on_episode=on_episode)

    def report(self) -> dict[str, Any]:
        """Extra results of the latest :meth:`play` for ``results.json`` (key -> plain values)."""
        return {}

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
