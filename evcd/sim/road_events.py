"""What happens to a day's roads: incidents, rain and road works (played by :mod:`evcd.sim.road_player`).

    events = RoadEvents(incidents=(Incident("B1C1", start=28_800, end=30_600, lanes=(0,)),))
    check_road_events(events, net)      # the edges and lanes exist; what is closed cuts no turn

- :class:`Incident` (an accident or a breakdown, ``[start, end)``): the edge's lanes ``lanes``
  (indices, 0 the kerb side) closed to every vehicle, and the lanes left open driven at most at
  ``pass_speed`` (m/s; drivers pass the scene slowly). What may be closed (:func:`closable_lanes`):
  never the last lane open to cars, nor a lane whose closing cuts a turn out of the edge or into it
  that no open lane makes, or leaves open lanes on both sides of it (on Jurong West, the kerb lane of
  a 6-lane edge was the only way to a turn; closing the lane beside it stranded the vehicles there;
  closing the only lane a turn enters makes SUMO refuse every route through that turn, "No
  connection between edge ...", while its router still offers them). Both
  measured on SUMO 1.28: a whole edge closed by lane permissions stops the simulation ("has no
  valid route") as soon as a vehicle routed at insertion has no other way, and a lane held at speed
  0 makes the vehicles behind it teleport after ``time_to_teleport``; on Jurong West, closing the
  kerb lane of three edges for a day regardless of their turns stranded the turning vehicles (91
  teleports by 07:00, none on the calm day). A crawl past the scene queues the traffic without
  any of that. Vehicles whose route crosses the edge are rerouted around it when that is quicker
  (:mod:`evcd.sim.road_player`).
- :class:`Rain` (``[start, end)``): every lane's speed limit times ``speed_factor`` and every
  vehicle type's desired time headway (``tau``) times ``headway_factor``.
- :class:`RoadWork` (the whole day): the edge's speed limit at most ``speed`` (m/s) and its lanes
  ``lanes`` closed (as an incident's).

Events are part of a day's description: its cache key (:class:`~evcd.sim.snapshots.DaySpec`), its
snapshots and every episode played in it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import sumolib

from evcd.utils.validation import check_int, check_real

PASSENGER = "passenger"


def _lanes(what: str, lanes: Any) -> tuple[int, ...]:
    try:
        out = tuple(sorted({check_int(f"{what}: lane", i, minimum=0) for i in lanes}))
    except TypeError:
        raise ValueError(f"{what}: lanes={lanes!r} must be a list of lane indices") from None
    return out


def _check_interval(what: str, start: float, end: float) -> None:
    if not (math.isfinite(start) and math.isfinite(end) and 0 <= start < end):
        raise ValueError(f"{what}: start={start!r}, end={end!r} must be finite with 0 <= start < end")


@dataclass(frozen=True)
class Incident:
    """An accident or breakdown on ``edge`` over ``[start, end)`` (module docstring)."""

    edge: str
    start: float
    end: float
    lanes: tuple[int, ...] = ()
    pass_speed: float = 10.0 / 3.6

    def __post_init__(self) -> None:
        _check_interval(f"incident on {self.edge!r}", self.start, self.end)
        object.__setattr__(self, "lanes", _lanes(f"incident on {self.edge!r}", self.lanes))
        check_real(f"incident on {self.edge!r}: pass_speed", self.pass_speed, low=0.1, high=70.0)


@dataclass(frozen=True)
class Rain:
    """A spell of rain over ``[start, end)``: slower driving, longer headways (module docstring)."""

    start: float
    end: float
    speed_factor: float = 0.93
    headway_factor: float = 1.4

    def __post_init__(self) -> None:
        _check_interval("rain", self.start, self.end)
        check_real("rain: speed_factor", self.speed_factor, low=0.1, high=1.0)
        check_real("rain: headway_factor", self.headway_factor, low=1.0, high=5.0)


@dataclass(frozen=True)
class RoadWork:
    """Road works on ``edge`` all day: a speed limit and closed lanes (module docstring)."""

    edge: str
    speed: float = 30.0 / 3.6
    lanes: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        check_real(f"road works on {self.edge!r}: speed", self.speed, low=0.1, high=70.0)
        object.__setattr__(self, "lanes", _lanes(f"road works on {self.edge!r}", self.lanes))


@dataclass(frozen=True)
class RoadEvents:
    """Everything that happens to one day's roads (empty: a calm day)."""

    incidents: tuple[Incident, ...] = ()
    rain: tuple[Rain, ...] = ()
    roadworks: tuple[RoadWork, ...] = ()

    @property
    def empty(self) -> bool:
        """Whether nothing happens."""
        return not (self.incidents or self.rain or self.roadworks)

    def to_dict(self) -> dict[str, list[dict[str, Any]]]:
        """JSON-serialisable form (a day's cache key, :meth:`from_dict` reads it back)."""
        return {
            f.name: [dataclasses.asdict(e) for e in getattr(self, f.name)] for f in dataclasses.fields(self)
        }

    @classmethod
    def from_dict(cls, value: Mapping[str, Any]) -> RoadEvents:
        """From :meth:`to_dict`'s form (or a hand-written one: lists of each event's fields)."""
        kinds = {"incidents": Incident, "rain": Rain, "roadworks": RoadWork}
        unknown = sorted(set(value) - set(kinds))
        if unknown:
            raise ValueError(f"road events: unknown kind {unknown[0]!r}; the kinds: {', '.join(kinds)}")
        return cls(**{k: tuple(kinds[k](**e) for e in value.get(k, ())) for k in kinds})

    def change_times(self) -> list[float]:
        """Every time something starts or ends (sorted; road works hold all day)."""
        times = {t for e in (*self.incidents, *self.rain) for t in (e.start, e.end)}
        return sorted(times)


def check_road_events(
    events: RoadEvents, net: sumolib.net.Net, keep_open: Collection[str] = ()
) -> RoadEvents:
    """``events`` if every incident and road work is on a drivable edge of ``net`` and closes only
    lanes :func:`closable_lanes` allows (never one of ``keep_open``: the lanes of the stations' car
    parks), and rain spells do not overlap.

    Raises:
        ValueError: naming the event and what is allowed.
    """
    for e in (*events.incidents, *events.roadworks):
        kind = "incident" if isinstance(e, Incident) else "road works"
        if not net.hasEdge(e.edge) or not net.getEdge(e.edge).allows(PASSENGER):
            raise ValueError(f"{kind} on edge {e.edge!r}: no such drivable edge in the network")
        lanes = net.getEdge(e.edge).getLaneNumber()
        if any(i >= lanes for i in e.lanes):
            raise ValueError(f"{kind} on edge {e.edge!r}: lanes={list(e.lanes)}; it has lanes 0-{lanes - 1}")
        held = sorted(i for i in e.lanes if f"{e.edge}_{i}" in keep_open)
        if held:
            raise ValueError(
                f"{kind} on edge {e.edge!r}: lane {held[0]} holds a station's car park (its EVs must stop "
                "there): it stays open"
            )
        allowed = closable_lanes(net, e.edge, len(e.lanes), order=e.lanes)
        if allowed != e.lanes:
            raise ValueError(
                f"{kind} on edge {e.edge!r}: closing lanes {list(e.lanes)} would leave no lane open to cars "
                f"or cut a turn into or out of it that no open lane makes (vehicles turning there would be "
                f"stranded); closable: "
                f"{list(closable_lanes(net, e.edge, lanes, keep_open=keep_open))}"
            )
    spells = sorted(events.rain, key=lambda r: r.start)
    for a, b in itertools.pairwise(spells):
        if b.start < a.end:
            raise ValueError(f"rain spells [{a.start}, {a.end}) and [{b.start}, {b.end}) overlap")
    return events


def closable_lanes(
    net: sumolib.net.Net,
    edge: str,
    most: int,
    order: Sequence[int] | None = None,
    keep_open: Collection[str] = (),
) -> tuple[int, ...]:
    """Up to ``most`` lanes of ``edge`` that may be closed together, tried in ``order`` (default: from
    the kerb, lane 0, outwards): a lane is closed when it is not in ``keep_open`` (lane ids: the
    stations' car parks, where their EVs must stop; SUMO stops the simulation otherwise, measured),
    the lanes left open to cars are side by side (none is cut off from the others: vehicles cannot
    change lanes across a closed one), still reach every edge the edge's car lanes reach (no turn out
    of it is cut), and are still entered from every edge whose cars turn into it (no turn into it is
    cut: SUMO treats a turn whose every lane is closed as gone, refuses routes through it and strands
    the vehicles already on them)."""
    this = net.getEdge(edge)
    lanes = this.getLanes()
    cars = [i for i, lane in enumerate(lanes) if lane.allows(PASSENGER)]
    entered: dict[int, set[str]] = {i: set() for i in cars}  # lane -> the edges whose cars turn into it
    for src, connections in this.getIncoming().items():
        for c in connections:
            if c.getFromLane().allows(PASSENGER) and c.getToLane().getIndex() in entered:
                entered[c.getToLane().getIndex()].add(src.getID())

    def reach(open_lanes: Iterable[int]) -> set[str]:
        return {c.getTo().getID() for i in open_lanes for c in lanes[i].getOutgoing()}

    def entry(open_lanes: Iterable[int]) -> set[str]:
        return set().union(*(entered[i] for i in open_lanes))

    every, everyone = reach(cars), entry(cars)
    closed: list[int] = []
    for i in order if order is not None else range(len(lanes)):
        if len(closed) == most:
            break
        if f"{edge}_{i}" in keep_open:
            continue
        rest = [j for j in cars if j != i and j not in closed]
        if rest and rest[-1] - rest[0] + 1 == len(rest) and reach(rest) == every and entry(rest) == everyone:
            closed.append(i)
    return tuple(sorted(closed))
