"""Charging points out of service for a while: a station's FIFO serves fewer points.

    outages = check_outages([Outage("cs1", points=1, start=28_800, end=36_000)], stations)
    controller = ChargingController(stations, outages=outages)

During an outage of ``k`` points a station of ``p`` points charges at most ``p - k`` vehicles. When
it begins while more vehicles charge than points remain in service, the ones that started last stop
(their charge rate set to 0, as a waiting vehicle's) and go back to the head of the queue, the
earliest of them first, ahead of everybody who arrived later: the driver whose point failed keeps
their turn. They resume when a point is free again; their visit keeps its first ``start_time`` (an
interruption is not a second charge start). Outages are part of the day's description (given to
the controller, not kept in its state).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from evcd.scenario.stations_file import Station


@dataclass(frozen=True)
class Outage:
    """``points`` charging points of station ``station`` out of service over ``[start, end)``
    (simulation seconds)."""

    station: str
    points: int
    start: float
    end: float

    def __post_init__(self) -> None:
        if isinstance(self.points, bool) or not isinstance(self.points, int) or self.points < 1:
            raise ValueError(f"outage at {self.station}: points={self.points!r} must be an integer >= 1")
        if not (math.isfinite(self.start) and math.isfinite(self.end) and 0 <= self.start < self.end):
            raise ValueError(
                f"outage at {self.station}: start={self.start!r}, end={self.end!r} must be "
                "finite with 0 <= start < end"
            )

    def active(self, time: float) -> bool:
        """Whether the points are out at ``time``."""
        return self.start <= time < self.end


def check_outages(outages: Iterable[Outage], stations: Sequence[Station]) -> tuple[Outage, ...]:
    """``outages``, checked against the ``stations``, sorted by start.

    Raises:
        ValueError: an outage at a station that does not exist, or outages that at some time take
            more points out of a station than it has (the message names the station, the time and
            its points).
    """
    points = {st.id: st.points for st in stations}
    checked = tuple(sorted(outages, key=lambda o: (o.start, o.station, o.end, o.points)))
    for o in checked:
        if not isinstance(o, Outage):
            raise ValueError(f"{o!r}: outages must be evcd.sim.outages.Outage")
        if o.station not in points:
            raise ValueError(
                f"outage at station {o.station!r}: no such station (stations: {', '.join(points)})"
            )
    for sid, total in points.items():
        mine = [o for o in checked if o.station == sid]
        for o in mine:  # the most points out at once are out at some outage's start
            out = sum(p.points for p in mine if p.active(o.start))
            if out > total:
                raise ValueError(
                    f"outages at station {sid!r} take {out} points out at t={o.start:g} s; it has {total}"
                )
    return checked


def points_in_service(points: int, outages: Sequence[Outage], time: float) -> int:
    """A station's points in service at ``time``: its ``points`` less those of its active ``outages``."""
    return points - sum(o.points for o in outages if o.active(time))
