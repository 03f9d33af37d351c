"""A target that waits at a station beside the charging queue, as if it were its only newcomer.

The batched engine (:mod:`evcd.env.runners.batched`) co-simulates many targets in one simulation; each must
meet the stations as it would were it the only target. So its targets never join the charging
controller's queues (they carry no battery the controller could queue): on arriving at its car park
a target becomes a :class:`GhostWait` and leaves the simulation (waiting targets never fill a car
park). It starts charging at the first step at which

- every background EV that was at the station when it arrived (waiting or charging, in the
  controller's FIFO order ahead of it) has got a point or left the queue, and
- fewer of those EVs than the station's points are still charging,

which is exactly when the FIFO would hand it a point were it queued: EVs that arrive after it are
behind it and cannot take a point before it, and background EVs never see it (it ends its episode
when it starts, never holding a point). ``N`` and ``Z`` therefore count background vehicles only;
the engine adds the target itself to its own station's ``Z`` while it waits, as the single
environment's queue does.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from evcd.sim.charging import ChargingController


@dataclass(frozen=True)
class GhostWait:
    """A target waiting at a station.

    Attributes:
        station: the station's id.
        points: its charging points.
        arrival: when the target arrived (s of day).
        ahead: the background EVs ahead of it (at the station when it arrived).
    """

    station: str
    points: int
    arrival: float
    ahead: frozenset[str]

    @classmethod
    def arrive(
        cls,
        controller: ChargingController,
        station: str,
        points: int,
        time: float,
        behind: Iterable[str] = (),
    ) -> GhostWait:
        """A target arriving at ``station`` at ``time``, after the controller's update of that
        step; ``behind``: vehicles that joined in the same step after it (SUMO's order)."""
        present = set(controller.queue(station)) | set(controller.charging_vehicles(station))
        return cls(station, int(points), float(time), frozenset(present - set(behind)))

    def started(self, controller: ChargingController) -> bool:
        """Whether the target would hold a point now (call after each controller update)."""
        if not self.ahead:
            return True
        if any(v in self.ahead for v in controller.queue(self.station)):
            return False
        busy = sum(v in self.ahead for v in controller.charging_vehicles(self.station))
        return busy < self.points
