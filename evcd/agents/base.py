"""The agent interface shared by the dispatchers: heuristics and learning agents (DQN).

An agent maps the environment's observation ``[D, N, Z]`` (see :mod:`evcd.env.observation`) to a
station index. It acts in one way, :meth:`Agent.decide`: the observations of ``k`` episodes due at
the same time and each episode's state (:meth:`Agent.new_episode`: its generator, and what the agent
keeps per episode, such as a station drawn at departure), so that one agent can drive several
episodes at once (the batched engine) and one network forward pass serves them all. For one episode
at a time, as with a Gymnasium environment:

    agent.begin_episode(rng)              # after env.reset(): a new episode state
    action = agent.act(obs, explore)      # once per decision slot: decide() on that one episode
    agent.observe(Transition(...))        # learning agents only: after every env.step()

Every source of randomness is a ``numpy.random.Generator`` handed in (at construction, and per
episode), never the global one, so a run is reproducible from its seed.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np

from evcd.env.transition import Transition
from evcd.utils.validation import check_int


def split_observation(obs: np.ndarray, n_stations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(D, N, Z)``: the three length-``n_stations`` parts of an observation vector (or, for a
    batch ``(k, 3m)``, of each row: arrays ``(k, m)``).

    Raises:
        ValueError: ``obs`` is not ``(3 * n_stations,)`` or ``(k, 3 * n_stations)``.
    """
    vec = np.asarray(obs)
    if vec.ndim not in (1, 2) or vec.shape[-1] != 3 * n_stations:
        raise ValueError(
            f"observation of shape {vec.shape}: expected ({3 * n_stations},) = [D, N, Z] for "
            f"{n_stations} stations (or a batch of them)"
        )
    m = n_stations
    return vec[..., :m], vec[..., m : 2 * m], vec[..., 2 * m :]


def observation_units(env: Any) -> dict[str, Any]:
    """What an agent needs to read the observations of ``env`` (a :class:`~evcd.env.ChargingNavEnv`,
    wrapped or not) in physical units: each station's charging points and whether the environment
    normalises (:func:`evcd.env.observation.unit_divisors`)."""
    base = env.unwrapped
    return {"points": [st.points for st in base.stations], "normalized": bool(base.config.normalize_obs)}


@dataclass
class EpisodeState:
    """What an agent keeps about one episode: by default only the episode's generator. Agents that
    keep more (a station drawn at departure, an exploration draw) subclass it."""

    rng: np.random.Generator


class Agent(ABC):
    """A dispatcher: picks the station the target drives to, once per decision slot.

    Args:
        n_stations: number of stations ``m`` (the action space is ``Discrete(m)``).
        rng: the agent's random generator (derive it from the run seed); episodes begun without a
            generator of their own draw from it.

    Subclasses set :attr:`name` (the registry key, see :func:`evcd.agents.make_agent`) and implement
    :meth:`decide`; learning agents also override :meth:`observe`.
    """

    name: ClassVar[str]
    #: Whether the agent learns from :meth:`observe` (the trainer runs a training phase for it).
    learns: ClassVar[bool] = False

    def __init__(self, n_stations: int, rng: np.random.Generator) -> None:
        self.n_stations = check_int("n_stations", n_stations, minimum=1)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng={rng!r}: must be a numpy.random.Generator (derive it from the run seed)")
        self.rng = rng
        self.episode = self.new_episode(rng)  # the episode act() decides for

    # ------------------------------------------------------------------ construction
    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """Constructor arguments this agent reads off an environment (beyond ``n_stations``).

        Agents whose behaviour depends on the environment's settings (charging points, observation
        scaling) override this; :func:`evcd.agents.make_agent_for_env` uses it.
        """
        del env
        return {}

    @classmethod
    def option_names(cls) -> list[str]:
        """The options the constructor takes beyond ``n_stations`` and ``rng`` (for the registry's
        check of unknown options)."""
        return list(inspect.signature(cls.__init__).parameters)[3:]

    @classmethod
    def from_env(cls, env: Any, rng: np.random.Generator, **kwargs: Any) -> Self:
        """This agent for ``env`` (its number of stations and :meth:`env_kwargs`), plus ``kwargs``."""
        return cls(int(env.action_space.n), rng, **{**cls.env_kwargs(env), **kwargs})

    # ------------------------------------------------------------------ acting
    def new_episode(self, rng: np.random.Generator) -> EpisodeState:
        """The state of a new episode drawing from ``rng`` (the episode's own generator, so that an
        episode does not depend on the ones played before it)."""
        return EpisodeState(rng)

    @abstractmethod
    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The stations for ``k`` episodes due at the same time.

        Args:
            obs: their observations ``[D, N, Z]``, shape ``(k, 3m)``.
            episodes: each episode's state (from :meth:`new_episode`), updated in place.
            explore: whether a learning agent may explore (training); rules ignore it.

        Returns:
            ``k`` station indices (int64).
        """

    def begin_episode(self, rng: np.random.Generator | None = None) -> EpisodeState:
        """Start an episode for :meth:`act` (call after every ``env.reset()``), drawing from ``rng``
        (default: the agent's own generator)."""
        self.episode = self.new_episode(self.rng if rng is None else rng)
        return self.episode

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station to drive to in the current episode (:meth:`begin_episode`): :meth:`decide` on
        that one episode."""
        return int(self.decide(np.asarray(obs)[None], [self.episode], explore)[0])

    # ------------------------------------------------------------------ learning
    def observe(self, transition: Transition, episode: EpisodeState | None = None) -> None:  # noqa: B027
        """Learning hook, called after every step of ``episode`` (default: the current one) while
        training; the rules ignore it."""

    def stats(self) -> dict[str, float]:
        """Learning statistics for logs (cumulative counters and current schedules); none here."""
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_stations={self.n_stations})"
