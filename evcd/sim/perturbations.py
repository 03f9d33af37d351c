"""A day that is not calm: its perturbations, drawn from the day's own seed.

    p = Perturbations.from_value({"outages": {"per_day": 3, "minutes": [30, 180], "points": 1}})
    outages = p.outages_of(stations, demand_seed=101)     # the same for every agent and every run

A day's events are drawn from its demand seed in a stream of their own (so a perturbed day has the
same demand as the calm one, and one kind's draws do not move another's), and are part of the day's
description: its cache key (:class:`~evcd.sim.snapshots.DaySpec`), its snapshots and every episode
played in it.

Kinds (settings under their name; a kind left out does not happen):

- ``outages`` (:mod:`evcd.sim.outages`): a Poisson number of outages per day, mean ``per_day``;
  each at a station drawn with probability proportional to its charging points, ``points`` of them
  out (at most the station's), starting uniformly in ``start_window`` (s of day), lasting
  uniformly ``minutes`` (the issue's 30-180 min by default). Overlapping outages at one station
  that would take out more points than it has are dropped (the later one), so a station with one
  point is closed at most once at a time.

- ``incidents`` (:class:`~evcd.sim.road_events.Incident`): a Poisson number per day, mean
  ``per_day``; each on an edge drawn in proportion to its lanes x length (its share of the
  vehicle-km the district can carry) among the roads with a speed limit of at least
  ``min_speed_kmh`` (no service roads or car-park lanes), starting at an hour drawn from the day's
  demand profile (incidents happen where and when the traffic is) inside ``start_window``, lasting
  uniformly ``minutes`` (15-60), closing up to ``lanes_closed`` lanes (from the kerb, those that may be:
  :func:`~evcd.sim.road_events.closable_lanes`) and passing
  the scene at ``pass_speed_kmh``.
- ``rain`` (:class:`~evcd.sim.road_events.Rain`): with probability ``chance`` one spell on the day,
  starting uniformly in ``start_window``, lasting uniformly ``hours``. Its defaults are heavy
  rain: speeds 7% lower (rain of any intensity lowered freeway operating speeds by 3-6.5% in
  Smith et al. 2004, Hampton Roads; very heavy rain by 8.4% in Purdue's connected-vehicle study,
  *Vehicles* 5(1), 2023) and headways 1.4 times as long, which with the speed cuts a lane's
  capacity at 50 km/h by 22% (SUMO's defaults: 5 m cars, 2.5 m gaps, 1 s headway): heavy rain
  cut capacity by 25-30% in Smith et al. and by 20% on average over 26 studies (Prevedouros and
  Kongsil 2003).
- ``roadworks`` (:class:`~evcd.sim.road_events.RoadWork`): a Poisson number of sites, mean
  ``per_day``, on edges drawn as the incidents', held all day at ``speed_kmh`` with
  up to ``lanes_closed`` lanes closed (as the incidents').
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sumolib

from evcd.scenario.demand import DAY
from evcd.scenario.stations_file import Station
from evcd.sim.outages import Outage, check_outages
from evcd.sim.road_events import Incident, Rain, RoadEvents, RoadWork, check_road_events, closable_lanes
from evcd.utils.validation import check_int, check_real

#: Every kind of perturbation.
KINDS = ("incidents", "rain", "outages", "roadworks")
#: The stream of each kind's draws, beside the day's demand seed.
_STREAMS = {"outages": 1, "incidents": 2, "rain": 3, "roadworks": 4}


@dataclass(frozen=True)
class OutageSettings:
    """How charger outages are drawn (module docstring)."""

    per_day: float = 2.0
    minutes: tuple[float, float] = (30.0, 180.0)
    points: int = 1
    start_window: tuple[float, float] = (0.0, float(DAY))

    def __post_init__(self) -> None:
        check_real("perturbations.outages.per_day", self.per_day, low=0.0, high=100.0)
        check_int("perturbations.outages.points", self.points, minimum=1)
        minutes = _range("perturbations.outages.minutes", self.minutes, 1.0, 24 * 60, "minutes")
        object.__setattr__(self, "minutes", minutes)
        object.__setattr__(
            self, "start_window", _window("perturbations.outages.start_window", self.start_window)
        )


def _window(name: str, value: Any) -> tuple[float, float]:
    s0, s1 = _pair(name, value)
    if not 0.0 <= s0 < s1 <= DAY:
        raise ValueError(f"{name}={list(value)}: need 0 <= start < end <= {DAY} (s of day)")
    return s0, s1


def _range(name: str, value: Any, low: float, high: float, unit: str) -> tuple[float, float]:
    lo, hi = _pair(name, value)
    if not low <= lo <= hi <= high:
        raise ValueError(f"{name}={list(value)}: need {low:g} <= low <= high <= {high:g} ({unit})")
    return lo, hi


@dataclass(frozen=True)
class IncidentSettings:
    """How incidents are drawn (module docstring)."""

    per_day: float = 4.0
    minutes: tuple[float, float] = (15.0, 60.0)
    lanes_closed: int = 1
    pass_speed_kmh: float = 10.0
    min_speed_kmh: float = 40.0
    start_window: tuple[float, float] = (0.0, float(DAY))

    def __post_init__(self) -> None:
        check_real("perturbations.incidents.per_day", self.per_day, low=0.0, high=100.0)
        check_int("perturbations.incidents.lanes_closed", self.lanes_closed, minimum=0)
        check_real("perturbations.incidents.pass_speed_kmh", self.pass_speed_kmh, low=1.0, high=130.0)
        check_real("perturbations.incidents.min_speed_kmh", self.min_speed_kmh, low=0.0, high=130.0)
        minutes = _range("perturbations.incidents.minutes", self.minutes, 1.0, 24 * 60, "minutes")
        object.__setattr__(self, "minutes", minutes)
        object.__setattr__(
            self, "start_window", _window("perturbations.incidents.start_window", self.start_window)
        )


@dataclass(frozen=True)
class RainSettings:
    """How a day's rain is drawn (module docstring)."""

    chance: float = 0.5
    hours: tuple[float, float] = (1.0, 3.0)
    speed_factor: float = 0.93
    headway_factor: float = 1.4
    start_window: tuple[float, float] = (0.0, float(DAY))

    def __post_init__(self) -> None:
        check_real("perturbations.rain.chance", self.chance, low=0.0, high=1.0)
        check_real("perturbations.rain.speed_factor", self.speed_factor, low=0.1, high=1.0)
        check_real("perturbations.rain.headway_factor", self.headway_factor, low=1.0, high=5.0)
        object.__setattr__(self, "hours", _range("perturbations.rain.hours", self.hours, 0.05, 24.0, "hours"))
        object.__setattr__(
            self, "start_window", _window("perturbations.rain.start_window", self.start_window)
        )


@dataclass(frozen=True)
class RoadworkSettings:
    """How a day's road works are drawn (module docstring)."""

    per_day: float = 3.0
    speed_kmh: float = 30.0
    lanes_closed: int = 1
    min_speed_kmh: float = 40.0

    def __post_init__(self) -> None:
        check_real("perturbations.roadworks.per_day", self.per_day, low=0.0, high=100.0)
        check_real("perturbations.roadworks.speed_kmh", self.speed_kmh, low=1.0, high=130.0)
        check_int("perturbations.roadworks.lanes_closed", self.lanes_closed, minimum=0)
        check_real("perturbations.roadworks.min_speed_kmh", self.min_speed_kmh, low=0.0, high=130.0)


#: Each kind's settings class.
SETTINGS: dict[str, type] = {
    "outages": OutageSettings,
    "incidents": IncidentSettings,
    "rain": RainSettings,
    "roadworks": RoadworkSettings,
}


@dataclass(frozen=True)
class Perturbations:
    """The perturbations of every day of an environment (``None`` for a kind: it does not happen)."""

    outages: OutageSettings | None = None
    incidents: IncidentSettings | None = None
    rain: RainSettings | None = None
    roadworks: RoadworkSettings | None = None

    @classmethod
    def from_value(cls, value: Perturbations | Mapping[str, Any] | None) -> Perturbations:
        """From a mapping of kind -> settings (a Hydra block), ``None`` (calm) or an instance.

        Raises:
            ValueError: an unknown kind (the message lists them) or setting, or a bad value.
        """
        if value is None or isinstance(value, Perturbations):
            return value or cls()
        if not isinstance(value, Mapping):
            raise ValueError(f"perturbations={value!r}: must be a mapping of kind -> settings, or None")
        unknown = sorted(set(value) - set(KINDS))
        if unknown:
            raise ValueError(f"perturbations: unknown kind {unknown[0]!r}; the kinds: {', '.join(KINDS)}")
        return cls(**{kind: _settings(kind, v) for kind, v in value.items()})

    @property
    def calm(self) -> bool:
        """Whether no kind happens."""
        return all(getattr(self, kind) is None for kind in KINDS)

    @property
    def on_roads(self) -> bool:
        """Whether a kind that changes the roads happens (incidents, rain, road works)."""
        return any(getattr(self, kind) is not None for kind in ("incidents", "rain", "roadworks"))

    def roads_of(
        self,
        net: sumolib.net.Net,
        hourly_profile: Sequence[float],
        demand_seed: int,
        keep_open: Collection[str] = (),
    ) -> RoadEvents:
        """The incidents, rain and road works of the day of ``demand_seed`` on ``net`` (module
        docstring); ``hourly_profile``: the day's 24 relative departures per hour; ``keep_open``: lanes
        never closed (the stations' car parks)."""
        incidents: list[Incident] = []
        if (inc := self.incidents) is not None and inc.per_day > 0:
            rng = np.random.default_rng([int(demand_seed), _STREAMS["incidents"]])
            edges, p = _exposure(net, inc.min_speed_kmh)
            for _ in range(int(rng.poisson(inc.per_day))):
                edge = edges[int(rng.choice(len(edges), p=p))]
                start = _start_by_profile(rng, hourly_profile, inc.start_window)
                end = min(float(DAY), start + round(float(rng.uniform(*inc.minutes)) * 60.0))
                closed = closable_lanes(net, edge, inc.lanes_closed, keep_open=keep_open)
                incidents.append(
                    Incident(edge, start, max(end, start + 1.0), closed, inc.pass_speed_kmh / 3.6)
                )
        rain: list[Rain] = []
        if (r := self.rain) is not None:
            rng = np.random.default_rng([int(demand_seed), _STREAMS["rain"]])
            wet, start, hours = rng.random() < r.chance, rng.uniform(*r.start_window), rng.uniform(*r.hours)
            if wet:
                s0 = float(math.floor(start))
                rain.append(
                    Rain(s0, min(float(DAY), s0 + round(hours * 3600.0)), r.speed_factor, r.headway_factor)
                )
        works: list[RoadWork] = []
        if (w := self.roadworks) is not None and w.per_day > 0:
            rng = np.random.default_rng([int(demand_seed), _STREAMS["roadworks"]])
            edges, p = _exposure(net, w.min_speed_kmh)
            sites = sorted(
                {edges[int(rng.choice(len(edges), p=p))] for _ in range(int(rng.poisson(w.per_day)))}
            )
            works = [
                RoadWork(e, w.speed_kmh / 3.6, closable_lanes(net, e, w.lanes_closed, keep_open=keep_open))
                for e in sites
            ]
        events = RoadEvents(
            tuple(sorted(incidents, key=lambda e: (e.start, e.edge))), tuple(rain), tuple(works)
        )
        return check_road_events(events, net, keep_open)

    def outages_of(self, stations: Sequence[Station], demand_seed: int) -> tuple[Outage, ...]:
        """The charger outages of the day of ``demand_seed`` (sorted by start; none when calm)."""
        s = self.outages
        if s is None or s.per_day == 0:
            return ()
        rng = np.random.default_rng([int(demand_seed), _STREAMS["outages"]])
        weights = np.array([st.points for st in stations], dtype=np.float64)
        kept: list[Outage] = []
        for _ in range(int(rng.poisson(s.per_day))):
            st = stations[int(rng.choice(len(stations), p=weights / weights.sum()))]
            start = float(math.floor(rng.uniform(*s.start_window)))
            minutes = float(rng.uniform(*s.minutes))
            end = min(float(DAY), start + round(minutes * 60.0))
            outage = Outage(st.id, min(s.points, st.points), start, max(end, start + 1.0))
            try:  # drop an outage that would take out more points than the station has
                check_outages([*kept, outage], stations)
            except ValueError:
                continue
            kept.append(outage)
        return check_outages(kept, stations)


def _settings(kind: str, value: Any) -> Any:
    """A kind's settings from its Hydra block (``None``: it does not happen)."""
    cls = SETTINGS[kind]
    if value is None or isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise ValueError(f"perturbations.{kind}={value!r}: must be a mapping of its settings")
    known = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(value) - known)
    if bad:
        raise ValueError(f"perturbations.{kind}.{bad[0]}: unknown; known: {', '.join(sorted(known))}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in value.items()})


def _exposure(net: sumolib.net.Net, min_speed_kmh: float) -> tuple[list[str], np.ndarray]:
    """The drivable edges with a speed limit of at least ``min_speed_kmh`` and the probability of
    each, proportional to lanes x length."""
    edges = [
        e for e in net.getEdges() if e.allows("passenger") and e.getSpeed() * 3.6 >= min_speed_kmh - 1e-9
    ]
    if not edges:
        raise ValueError(f"min_speed_kmh={min_speed_kmh}: no drivable edge has a speed limit that high")
    w = np.array([e.getLaneNumber() * e.getLength() for e in edges], dtype=np.float64)
    return [e.getID() for e in edges], w / w.sum()


def _start_by_profile(
    rng: np.random.Generator, profile: Sequence[float], window: tuple[float, float]
) -> float:
    """A start time (whole s) inside ``window`` with density proportional to the hourly ``profile``."""
    hours = np.arange(24)
    overlap = np.clip(
        np.minimum((hours + 1) * 3600.0, window[1]) - np.maximum(hours * 3600.0, window[0]), 0, None
    )
    w = np.asarray(profile, dtype=np.float64) * overlap
    if w.sum() <= 0:  # no demand in the window: uniform in it
        return float(math.floor(rng.uniform(*window)))
    h = int(rng.choice(24, p=w / w.sum()))
    lo, hi = max(h * 3600.0, window[0]), min((h + 1) * 3600.0, window[1])
    return float(math.floor(rng.uniform(lo, hi)))


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r}: must be [low, high]") from None
    return lo, hi
