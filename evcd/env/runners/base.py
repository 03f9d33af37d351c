"""Episode runners: the one interface through which training and evaluation reach episodes.

    runner = make_runner(ChargingNavEnv(evs=400), engine="batched")     # or "single"
    rows = runner.run(specs, agent, explore=True, learn=True, on_episode=log_row)
    runner.close()

A runner plays the episodes named by :class:`EpisodeSpec`\\ s (the reset seed and the agent's
per-episode generator) with an agent, exploring or not, and, when ``learn`` is set, hands the agent
every transition with its episode's state (:meth:`Policy.observe`) and then the episode's end
(:meth:`Policy.end_episode`); an episode whose target could no longer be observed
(:data:`~evcd.env.episode_rules.UNOBSERVED`) ends without a last transition. It returns one
:class:`EpisodeRow` per spec, in the order of the specs, and calls ``on_episode`` as each episode
ends. The loops above it (:mod:`evcd.loops`) never touch an environment, so a runner that plays
many episodes in one simulation (the batched engine) plugs in behind this interface without
changing them or the agents. Such a runner may keep
several episodes in flight at once; what it must guarantee is that the same specs, agent state and
settings give the same rows and the same sequence of ``observe`` and ``end_episode`` calls.

The environment layer does not import agents: a runner talks to anything with the :class:`Policy`
methods, which keep each episode's state apart (:meth:`Policy.new_episode`), so that one agent can
decide for several episodes at once.
"""

from __future__ import annotations

import dataclasses
import itertools
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, Self

import numpy as np

from evcd.env.transition import Transition


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

    def new_episode(self, rng: np.random.Generator) -> Any:
        """The state of a new episode (its generator, and whatever the agent keeps per episode)."""

    def decide(self, obs: np.ndarray, episodes: Sequence[Any], explore: bool = False) -> np.ndarray:
        """The stations of ``k`` episodes due at the same time: observations ``(k, 3m)`` and each
        episode's state (from :meth:`new_episode`, updated in place)."""

    def observe(self, transition: Transition, episode: Any) -> None:
        """Learn from one transition of the episode whose state is ``episode``."""

    def end_episode(self, episode: Any) -> None:
        """The episode whose state is ``episode`` ended (after its last :meth:`observe`)."""


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

    def row(self) -> dict[str, Any]:
        """The row's fields as plain values (a line of ``episodes.csv``, an entry of ``results.json``)."""
        return dataclasses.asdict(self)

    def charts(self) -> dict[str, float]:
        """What a training curve shows of the episode (TensorBoard ``charts/<key>``)."""
        return {"travel_time": self.travel_time, "episodic_return": self.episode_return,
                "queue_wait": self.queue_wait, "switches": float(self.switches),
                "truncated": float(self.truncated)}  # fmt: skip


EpisodeCallback = Callable[[EpisodeRow], None]


class EpisodeRunner(ABC):
    """Plays episodes given by specs (see the module docstring). Close it (or use ``with``)."""

    #: The task its episodes belong to: ``"single"`` (rows are :class:`EpisodeRow`) or ``"fleet"``
    #: (:class:`~evcd.env.runners.fleet.FleetEpisode`); the loops summarise and write rows by it
    #: (:mod:`evcd.loops.tasks`).
    task: ClassVar[str] = "single"

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


class EnvRunner(EpisodeRunner):
    """A runner over one environment (``self.env``): its stations are the actions, its ``prepare``
    (day snapshots), if it has one, prepares the runner, and closing the runner closes it.

    Args:
        env: the environment (a Gymnasium env, or the fleet's PettingZoo one).
    """

    def __init__(self, env: Any) -> None:
        self.env = env

    @property
    def n_stations(self) -> int:
        """The environment's number of stations (actions)."""
        return len(self.env.unwrapped.stations)

    def prepare(self) -> None:
        """The environment's ``prepare`` (its days' snapshots), if it has one."""
        prepare = getattr(self.env.unwrapped, "prepare", None)
        if prepare is not None:
            prepare()

    def close(self) -> None:
        """Close the environment (idempotent)."""
        self.env.close()


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
