"""One co-simulated target of the batched engine: its phase, position, open slot and record.

A target moves through the phases of :class:`Phase`::

    INSERTING --(SUMO inserts it)--> DRIVING --(parks at its station)--> WAITING --(starts charging)--> DONE
                                        ^                                   |
                                        +--- REENTERING <--(another station)-+

and ends (``DONE``) by the episode's rules (:mod:`evcd.env.episode_rules`) in any phase.
"""

from __future__ import annotations

import enum
import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evcd.env.episode_rules import Motion
from evcd.env.observation import Observation
from evcd.env.runners.base import EpisodeSpec
from evcd.env.runners.ghost import GhostWait
from evcd.env.target import Target, TargetPlan

#: SUMO vehicle type of the co-simulated targets: ``ev`` without a battery device, so the charging
#: controller never queues them (the engine queues them itself, :mod:`evcd.env.runners.ghost`).
TARGET_VTYPE = "evcd_target_ev"


class Phase(enum.Enum):
    """Where a co-simulated target is."""

    INSERTING = "inserting"  # added, waiting for SUMO to insert it
    DRIVING = "driving"
    WAITING = "waiting"  # at its station, beside the queue (not in the simulation)
    REENTERING = "reentering"  # left a queue: added again at the car park, not inserted yet
    DONE = "done"


class TargetIds:
    """SUMO vehicle and route ids of the engine's targets, never reused in a runner's life (SUMO keeps
    the routes of removed vehicles, and a loaded state keeps those of the run it was saved in)."""

    def __init__(self) -> None:
        self._serial = itertools.count()

    def route(self) -> str:
        """A new route id."""
        return f"evcd_batch_route{next(self._serial)}"

    def vehicle(self) -> str:
        """A new vehicle id."""
        return f"evcd_batch_target{next(self._serial)}"


@dataclass
class OpenSlot:
    """The decision slot a target is in: when it began and ends, what it saw and chose."""

    start: float
    end: float
    obs: np.ndarray  # the observation vector the action was chosen on
    action: int


@dataclass
class LiveTarget:
    """One target of a batch, from its departure to the end of its episode.

    Attributes:
        order: its position in the specs (ties are broken by it).
        spec: its episode.
        rng: the episode's generator (origins redrawn after a failed insertion).
        day: the background day (index).
        target: its SUMO vehicle and choice of station.
        agent_state: the agent's state of this episode (``agent.new_episode``).
    """

    order: int
    spec: EpisodeSpec
    rng: np.random.Generator
    day: int
    target: Target
    agent_state: Any = None
    phase: Phase = Phase.INSERTING
    deadline: float = math.inf  # insertion deadline
    tries: int = 1  # origins tried
    obs: Observation | None = None  # the latest observation
    road: str = ""  # where it was last seen: edge, lane position, lane index
    pos: float = 0.0
    lane: int = 0
    motion: Motion = field(default_factory=lambda: Motion(0.0, 0.0))
    slot: OpenSlot | None = None
    choices: list[int] = field(default_factory=list)
    total: float = 0.0  # return so far
    wait: GhostWait | None = None
    visits: list[list[float | None]] = field(default_factory=list)  # [arrival, end] per station visit
    in_sim: bool = False  # its vehicle is in the simulation (removed at the end of the step it ends in)
    on_road: bool = False  # ended this step while on an edge (still counted there until removed)

    @property
    def plan(self) -> TargetPlan:
        """Its departure, origin and battery."""
        return self.target.plan

    @property
    def vid(self) -> str:
        """Its SUMO vehicle id."""
        return self.target.vehicle_id

    @property
    def done(self) -> bool:
        """Its episode has ended."""
        return self.phase is Phase.DONE

    def close_visits(self, now: float) -> list[tuple[float, float]]:
        """End the open station visit at ``now``; every visit as ``(arrival, end)``."""
        for visit in self.visits:
            if visit[1] is None:
                visit[1] = now
        return [(float(a), float(e)) for a, e in self.visits]  # type: ignore[arg-type]
