"""Episode runners: the one interface through which training and evaluation reach episodes.

    runner = SingleEnvRunner(ChargingNavEnv(evs=400))
    rows = runner.run(specs, agent, explore=True, learn=True, on_episode=log_row)
    runner.close()

A runner plays the episodes named by :class:`EpisodeSpec`\\ s (the reset seed and the agent's
per-episode generator) with an agent, exploring or not, and, when ``learn`` is set, hands the agent
every transition (:meth:`Policy.observe`). It returns one :class:`EpisodeRow` per spec, in the order
of the specs, and calls ``on_episode`` as each episode ends. The loops above it (the trainer,
:func:`evcd.evaluate.evaluate`) never touch an environment, so a runner that plays many episodes in
one simulation (co-simulated targets) plugs in behind this interface without changing them or the
agents. Such a runner may keep several episodes in flight at once; what it must guarantee is that
the same specs, agent state and settings give the same rows and the same sequence of ``observe``
calls.

The environment layer does not import agents: a runner talks to anything with the :class:`Policy`
methods.
"""

from __future__ import annotations

import itertools
import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, Self

import gymnasium
import numpy as np

log = logging.getLogger(__name__)


class Transition(NamedTuple):
    """One environment step, as a learning agent sees it.

    ``terminated`` and ``truncated`` are kept apart: a time-limit end (truncation) still bootstraps
    from ``next_obs``, a charge start (termination) does not.
    """

    obs: np.ndarray
    action: int
    reward: float
    next_obs: np.ndarray
    terminated: bool
    truncated: bool


@dataclass(frozen=True)
class EpisodeSpec:
    """Which episode to play.

    Attributes:
        index: the episode's number in its run (the ``episode`` column of the rows).
        reset_seed: the ``env.reset`` seed: the target (departure, origin, battery) and its day.
        agent_seed: seeds the generator handed to the agent's ``begin_episode`` (exploration).
        options: ``env.reset`` options fixing parts of the target (``departure``, ``origin``, ...;
            tests and hand-made cases), or ``None``.
    """

    index: int
    reset_seed: int
    agent_seed: np.random.SeedSequence
    options: Mapping[str, Any] | None = None

    def agent_rng(self) -> np.random.Generator:
        """A fresh generator for the agent's draws in this episode."""
        return np.random.default_rng(self.agent_seed)


class Policy(Protocol):
    """What a runner needs of an agent (:class:`evcd.agents.Agent` has it)."""

    name: str

    def begin_episode(self, rng: np.random.Generator | None = None) -> None:
        """Forget the previous episode; draw from ``rng`` during this one."""

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station to drive to."""

    def observe(self, transition: Transition) -> None:
        """Learn from one transition."""


@dataclass(frozen=True)
class EpisodeRow:
    """One played episode (a row of ``episodes.csv``).

    Attributes:
        episode: index in the run (0-based).
        seed: the ``env.reset`` seed (reproduces the target and the background day).
        departure: the target's departure (s of day).
        origin: the target's origin edge.
        day: the background day's demand seed.
        choices: the action of every slot, joined by ``-`` (e.g. ``"2-2-4"``).
        station: the station index the target ended at (last choice).
        station_id: that station's id.
        travel_time: seconds from departure to the start of charging (to the end if truncated).
        queue_wait: seconds the target waited in car parks.
        reason: why the episode ended (``"charging"`` or a truncation reason of the env).
        truncated: the episode ended without charging.
        episode_return: sum of the rewards.
        wall_s: wall-clock seconds of the episode (reset and learning included).
        switches: how often the choice of station changed after the first decision.
    """

    episode: int
    seed: int
    departure: float
    origin: str
    day: int
    choices: str
    station: int
    station_id: str
    travel_time: float
    queue_wait: float
    reason: str
    truncated: bool
    episode_return: float
    wall_s: float
    switches: int = 0

    @property
    def steps(self) -> int:
        """Decisions (transitions) in the episode."""
        return len(self.choices.split("-")) if self.choices else 0


EpisodeCallback = Callable[[EpisodeRow], None]


class EpisodeRunner(ABC):
    """Plays episodes given by specs (see the module docstring). Close it (or use ``with``)."""

    @property
    @abstractmethod
    def n_stations(self) -> int:
        """Number of stations (actions)."""

    @abstractmethod
    def run(
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: EpisodeCallback | None = None,
    ) -> list[EpisodeRow]:
        """Play ``specs`` with ``agent``; one row per spec, in order.

        Args:
            specs: the episodes.
            agent: the dispatcher.
            explore: let the agent explore (``act(obs, explore=True)``).
            learn: call ``agent.observe`` with every transition.
            on_episode: called with each row as its episode ends.
        """

    def prepare(self) -> None:  # noqa: B027  (optional hook)
        """Build whatever the episodes need (day snapshots) now rather than inside the first one."""

    def close(self) -> None:  # noqa: B027  (optional hook)
        """Release the simulation (idempotent)."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SingleEnvRunner(EpisodeRunner):
    """Episodes one after another in one environment (a :class:`~evcd.env.ChargingNavEnv`, or any
    Gymnasium env with a ``Discrete`` action space whose final ``info`` has the keys of
    :class:`EpisodeRow`: ``departure``, ``travel_time``, ``queue_wait``, ``reason``, ...).

    Args:
        env: the environment; the runner closes it in :meth:`close`.
    """

    def __init__(self, env: gymnasium.Env) -> None:
        self.env = env

    @property
    def n_stations(self) -> int:
        """The environment's number of actions."""
        return int(self.env.action_space.n)

    def prepare(self) -> None:
        """The environment's ``prepare`` (day snapshots), if it has one."""
        prepare = getattr(self.env.unwrapped, "prepare", None)
        if prepare is not None:
            prepare()

    def close(self) -> None:
        """Close the environment."""
        self.env.close()

    def run(
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: EpisodeCallback | None = None,
    ) -> list[EpisodeRow]:
        """Play ``specs`` in order (see :meth:`EpisodeRunner.run`)."""
        rows = []
        for spec in specs:
            row = self.episode(spec, agent, explore=explore, learn=learn)
            rows.append(row)
            if on_episode is not None:
                on_episode(row)
        return rows

    def episode(self, spec: EpisodeSpec, agent: Policy, *, explore: bool, learn: bool) -> EpisodeRow:
        """Play one episode to its end; return its row."""
        t0 = time.perf_counter()
        obs, info = self.env.reset(seed=spec.reset_seed, options=spec.options)
        agent.begin_episode(spec.agent_rng())
        choices: list[int] = []
        total = 0.0
        terminated = truncated = False
        while not (terminated or truncated):
            action = agent.act(obs, explore=explore)
            choices.append(action)
            next_obs, reward, terminated, truncated, info = self.env.step(action)
            if learn:
                agent.observe(Transition(obs, action, float(reward), next_obs, terminated, truncated))
            obs = next_obs
            total += float(reward)
        return row_from_info(
            spec, info, choices, total, truncated and not terminated, time.perf_counter() - t0
        )


def row_from_info(
    spec: EpisodeSpec,
    info: dict[str, Any],
    choices: Sequence[int],
    total: float,
    truncated: bool,
    wall_s: float,
) -> EpisodeRow:
    """The :class:`EpisodeRow` of an episode from its final ``info``."""
    switches = info.get("switches")
    if switches is None:
        switches = sum(a != b for a, b in itertools.pairwise(choices))
    return EpisodeRow(
        episode=spec.index,
        seed=spec.reset_seed,
        departure=float(info["departure"]),
        origin=str(info.get("origin", "")),
        day=int(info.get("day", -1)),
        choices="-".join(map(str, choices)),
        station=-1 if info.get("station") is None else int(info["station"]),
        station_id=str(info.get("station_id", "")),
        travel_time=float(info["travel_time"]),
        queue_wait=float(info["queue_wait"]),
        reason=str(info["reason"]),
        truncated=bool(truncated),
        episode_return=float(total),
        wall_s=float(wall_s),
        switches=int(switches),
    )
