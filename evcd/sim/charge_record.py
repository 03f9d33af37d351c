"""What happened at a station: one record per visit of one vehicle (kept by
:class:`~evcd.sim.charging.ChargingController`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import StrEnum
from typing import Any


class Outcome(StrEnum):
    """How a vehicle's visit at a station ended."""

    CHARGED = "charged"  # reached its target SoC and was resumed by the controller
    RELEASED = "released"  # released by the caller (:meth:`ChargingController.release`)
    LEFT = "left"  # its parking stop ended by other means (duration over, rerouted)
    VANISHED = "vanished"  # it disappeared from the car park (removed from the simulation)


@dataclass
class ChargeRecord:
    """One visit of one vehicle at one station (times in simulation seconds, SoC in 0..1).

    ``start_time`` is when the vehicle got a charging point (SUMO's battery starts charging one
    step later when the station's ``chargeDelay`` is one step). ``release_time`` is when the visit
    ended, whatever the ``outcome``; both stay ``None`` while it lasts.
    """

    vehicle: str
    station: str
    arrival_time: float
    soc_arrival: float
    target_soc: float
    hold: bool = False
    start_time: float | None = None
    soc_start: float | None = None
    release_time: float | None = None
    soc_release: float | None = None
    outcome: Outcome | None = None

    @property
    def queue_wait(self) -> float | None:
        """Seconds between joining the queue and getting a point."""
        return None if self.start_time is None else self.start_time - self.arrival_time

    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-serialisable form."""
        d = dataclasses.asdict(self)
        d["outcome"] = None if self.outcome is None else str(self.outcome)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ChargeRecord:
        """Inverse of :meth:`to_dict`."""
        d = dict(d)
        d["outcome"] = None if d.get("outcome") is None else Outcome(d["outcome"])
        return cls(**d)
