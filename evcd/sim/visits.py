"""The live bookkeeping of :class:`~evcd.sim.charging.ChargingController`: each vehicle's visit at a
station and each station's queue, points and car park (plain data: its state is saved with a
simulation snapshot)."""

from __future__ import annotations

from dataclasses import dataclass, field

from evcd.scenario.stations_file import Station


@dataclass
class Visit:
    """Live bookkeeping of a vehicle at a station."""

    record: int  # index into ChargingController._records
    capacity: float  # Wh
    rate: str  # its maximumChargeRate as SUMO reported it on arrival, restored when it charges
    zeroed: bool = False  # its maximumChargeRate is currently 0 (held)
    read_time: float = 0.0  # when its charge was last read (while charging) ...
    read_soc: float = 0.0  # ... and what it was
    next_read: float = 0.0  # do not read its charge before this time


@dataclass
class StationState:
    """Live bookkeeping of a station: its queue, the vehicles charging, its car park."""

    station: Station
    queue: list[str] = field(default_factory=list)  # waiting, FIFO order
    charging: list[str] = field(default_factory=list)  # holding a point, in start order
    lot: set[str] = field(default_factory=set)  # every vehicle parked in the car park that we know
    leaving: set[str] = field(default_factory=set)  # in ``lot``, parking over, not yet driven out
