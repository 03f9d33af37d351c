"""One day (00:00-24:00) of background traffic, generated from a seed.

Conventional cars and EVs drive between random origin-destination edges. Departure times follow an
hourly profile with a morning and an evening peak. A share of the EVs need to charge: they drive to
the station *nearest by road* from their origin, park in its car park, queue (FIFO, see
:mod:`evcd.sim.charging`), charge to a target state of charge, then drive on to their destination.

The result is a SUMO route file of ``<trip>`` elements (SUMO routes each trip at insertion), sorted by
departure time. Nothing here starts SUMO.
"""

from __future__ import annotations

import gzip
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import sumolib

from evcd.scenario.routing import RoadGraph
from evcd.scenario.stations_file import Station
from evcd.scenario.vtypes import CAR_TYPE, EV_TYPE
from evcd.utils.atomic import atomic_write_bytes

log = logging.getLogger(__name__)

DAY = 86_400

#: Relative departures per hour of day (00-23): night trough, 08:00 and 18:00 peaks.
#: Shaped after typical urban weekday traffic counts; only the shape matters, it is normalised.
DEFAULT_HOURLY_PROFILE: tuple[float, ...] = (
    0.8, 0.5, 0.4, 0.4, 0.6, 1.5, 3.5, 6.5, 8.0, 6.0, 4.8, 4.8,
    5.2, 5.0, 4.8, 5.0, 6.0, 7.8, 8.2, 6.5, 4.8, 3.8, 2.8, 1.6,
)  # fmt: skip

#: Vehicle parameters read by the charging controller.
TARGET_SOC_PARAM = "evcd.targetSoc"


@dataclass(frozen=True)
class DemandConfig:
    """Everything that shapes a day of background demand (all documented in ``conf/scenario``).

    Attributes:
        cars_per_day: conventional cars departing over the day.
        evs: background EVs departing over the day.
        charging_share: fraction of EVs that need to charge on this trip.
        min_trip_m: minimum straight-line distance between origin and destination (m).
        hourly_profile: 24 relative weights of departures per hour.
        battery_wh: range of battery capacities (Wh), uniform.
        soc_charging: range of initial state of charge of EVs that need to charge.
        soc_other: range of initial state of charge of EVs that do not.
        target_soc: range of the state of charge at which a charging EV leaves.
        speed_factor_dev: spread of the drivers' speed factors (normal around 1, clipped to
            1 +- 2 dev). Drawn here, per vehicle, rather than by SUMO (``speedDev``): SUMO does not
            restore its random generators from a saved state, our seed does not need it to.
    """

    cars_per_day: int = 20_000
    evs: int = 400
    charging_share: float = 0.4
    min_trip_m: float = 1_000.0
    hourly_profile: tuple[float, ...] = DEFAULT_HOURLY_PROFILE
    battery_wh: tuple[float, float] = (40_000.0, 80_000.0)
    soc_charging: tuple[float, float] = (0.10, 0.30)
    soc_other: tuple[float, float] = (0.40, 0.90)
    target_soc: tuple[float, float] = (0.75, 0.90)
    speed_factor_dev: float = 0.1

    def __post_init__(self) -> None:
        if self.cars_per_day < 0:
            raise ValueError(f"cars_per_day={self.cars_per_day}: must be >= 0")
        if self.evs < 0:
            raise ValueError(f"evs={self.evs}: must be >= 0")
        if not 0.0 <= self.charging_share <= 1.0:
            raise ValueError(f"charging_share={self.charging_share}: must be in [0, 1]")
        if not 0 <= self.speed_factor_dev < 0.5:
            raise ValueError(f"speed_factor_dev={self.speed_factor_dev}: must be in [0, 0.5)")
        if self.min_trip_m < 0:
            raise ValueError(f"min_trip_m={self.min_trip_m}: must be >= 0")
        prof = np.asarray(self.hourly_profile, dtype=float)
        if prof.shape != (24,) or (prof < 0).any() or prof.sum() <= 0:
            raise ValueError(f"hourly_profile must be 24 non-negative weights, got {self.hourly_profile}")
        for name in ("battery_wh", "soc_charging", "soc_other", "target_soc"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi or (name != "battery_wh" and hi > 1):
                raise ValueError(f"{name}={(lo, hi)}: need 0 <= low <= high (<= 1 for a state of charge)")
        if self.soc_charging[1] >= self.target_soc[0]:
            raise ValueError(f"soc_charging={self.soc_charging} must lie below target_soc={self.target_soc}")


@dataclass(frozen=True)
class Trip:
    """One background vehicle."""

    id: str
    type: str
    depart: float
    origin: str
    destination: str
    speed_factor: float = 1.0
    station: str | None = None  # parking area of the station to charge at, if any
    battery_wh: float | None = None
    soc: float | None = None
    target_soc: float | None = None


@dataclass
class Demand:
    """A day of trips, sorted by departure."""

    trips: list[Trip]
    config: DemandConfig
    seed: int
    meta: dict = field(default_factory=dict)

    @property
    def charging_trips(self) -> list[Trip]:
        """Trips of EVs that stop to charge."""
        return [t for t in self.trips if t.station is not None]


class InverseCdf:
    """Inverse-CDF sampling of an index from fixed weights (one uniform draw per sample)."""

    def __init__(self, weights: np.ndarray) -> None:
        cdf = np.cumsum(np.asarray(weights, dtype=float))
        self.cdf = cdf / cdf[-1]

    def draw(self, rng: np.random.Generator) -> int:
        """An index ``i`` drawn with probability proportional to ``weights[i]``."""
        return int(min(np.searchsorted(self.cdf, rng.random(), side="right"), len(self.cdf) - 1))


def ev_id(index: int) -> str:
    """The SUMO id of a generated day's EV number ``index`` (``0 <= index < evs``, the same on every
    day: a day's vehicles are ``ev0`` .. ``ev{evs-1}``)."""
    return f"ev{index}"


def vehicle_rng(seed: int, kind: int, index: int) -> np.random.Generator:
    """The random stream of one vehicle: independent of how many others there are.

    So the day with 400 EVs holds the day with 300 EVs (same cars, same first 300 EVs) plus 100 more:
    raising ``evs`` adds load and changes nothing else.
    """
    return np.random.default_rng([seed, kind, index])


class OdSampler:
    """Draws origin-destination edges, weighted by lane length, at least ``min_trip_m`` apart."""

    def __init__(self, net: sumolib.net.Net, graph: RoadGraph, min_trip_m: float) -> None:
        # trips start and end on edges where a car can be inserted and leave: not too short, not ramps
        self.edges = [
            e
            for e in graph.edge_ids
            if net.getEdge(e).getLength() > 20 and net.getEdge(e).getFunction() == ""
        ]
        if len(self.edges) < 2:
            raise ValueError("the network has fewer than two edges usable as trip origins")
        lane_len = np.array([net.getEdge(e).getLength() * net.getEdge(e).getLaneNumber() for e in self.edges])
        self.cdf = InverseCdf(lane_len)
        self.xy = np.array([_midpoint(net.getEdge(e)) for e in self.edges])
        self.min_trip_m = min_trip_m
        extent = float(np.hypot(*np.ptp(self.xy, axis=0)))
        if extent < 2 * min_trip_m:
            # keeps the redraw loop short: most pairs must be able to satisfy the minimum
            raise ValueError(f"min_trip_m={min_trip_m} is too long for a network {extent:.0f} m across")

    def draw(self, rng: np.random.Generator) -> tuple[str, str]:
        """One origin and destination."""
        o = self.cdf.draw(rng)
        while True:
            d = self.cdf.draw(rng)
            if np.hypot(*(self.xy[o] - self.xy[d])) >= self.min_trip_m:
                return self.edges[o], self.edges[d]


def _midpoint(edge: sumolib.net.edge.Edge) -> tuple[float, float]:
    shape = np.asarray(edge.getShape())
    return tuple(shape.mean(axis=0))


def nearest_station_by_road(graph: RoadGraph, stations: list[Station], origins: list[str]) -> list[Station]:
    """For each origin edge, the station with the shortest driving distance to its car park."""
    dist = np.stack([graph.distances_to(s.edge) + s.mid_pos for s in stations])  # (stations, edges)
    idx = np.argmin(dist[:, [graph.index[o] for o in origins]], axis=0)
    return [stations[i] for i in idx]


def generate_demand(net: sumolib.net.Net, stations: list[Station], config: DemandConfig, seed: int) -> Demand:
    """Generate one day of trips from ``seed`` (same seed and inputs, same trips).

    Every vehicle draws from its own stream (:func:`vehicle_rng`), so days are nested in ``evs`` and
    ``cars_per_day``.
    """
    graph = RoadGraph.from_net(net)
    for st in stations:
        if st.edge not in graph:
            raise ValueError(f"station {st.id!r} sits on edge {st.edge!r}, which is not a drivable edge")
    sampler = OdSampler(net, graph, config.min_trip_m)
    hours = InverseCdf(np.asarray(config.hourly_profile))
    trips: list[Trip] = []

    def depart(rng: np.random.Generator) -> float:
        return float(np.floor((hours.draw(rng) + rng.random()) * 3600.0))

    def speed_factor(rng: np.random.Generator) -> float:
        dev = config.speed_factor_dev
        return round(float(np.clip(1.0 + dev * rng.standard_normal(), 1 - 2 * dev, 1 + 2 * dev)), 3)

    for i in range(config.cars_per_day):
        rng = vehicle_rng(seed, 0, i)
        t = depart(rng)
        trips.append(Trip(f"car{i}", CAR_TYPE, t, *sampler.draw(rng), speed_factor=speed_factor(rng)))

    evs = []
    for i in range(config.evs):
        rng = vehicle_rng(seed, 1, i)
        t = depart(rng)
        origin, dest = sampler.draw(rng)
        charges = bool(rng.random() < config.charging_share)
        cap = rng.uniform(*config.battery_wh)
        soc = rng.uniform(*(config.soc_charging if charges else config.soc_other))
        target = rng.uniform(*config.target_soc)
        evs.append((i, t, origin, dest, charges, cap, soc, target, speed_factor(rng)))
    charging = [e for e in evs if e[4]]
    nearest = nearest_station_by_road(graph, stations, [e[2] for e in charging]) if charging else []
    station_of = {e[0]: st.parking_area for e, st in zip(charging, nearest, strict=True)}
    for i, t, origin, dest, charges, cap, soc, target, sf in evs:
        trips.append(
            Trip(
                ev_id(i), EV_TYPE, t, origin, dest,
                speed_factor=sf,
                station=station_of.get(i),
                battery_wh=round(float(cap), 1),
                soc=round(float(soc), 4),
                target_soc=round(float(target), 4) if charges else None,
            )
        )  # fmt: skip
    n_charging = len(charging)
    trips.sort(key=lambda t: (t.depart, t.id))
    log.info(
        "demand seed=%d: %d cars, %d EVs (%d charging)", seed, config.cars_per_day, config.evs, n_charging
    )
    return Demand(trips, config, seed)


def demand_to_xml(demand: Demand, stop_duration: float = 10 * DAY) -> str:
    """Serialise a day of trips into the text of a SUMO route file.

    EVs that charge get a parking stop at their station's car park with a duration far beyond the
    day: the charging controller releases them (``vehicle.resume``) once charged.
    """
    root = ET.Element("routes")
    for t in demand.trips:
        el = ET.SubElement(
            root,
            "trip",
            id=t.id,
            type=t.type,
            depart=f"{t.depart:.0f}",
            departLane="best",
            departSpeed="max",
            speedFactor=f"{t.speed_factor:.3f}",
            **{"from": t.origin, "to": t.destination},
        )
        if t.station is not None:
            ET.SubElement(el, "stop", parkingArea=t.station, duration=f"{stop_duration:.0f}", parking="true")
        if t.type == EV_TYPE:
            capacity = t.battery_wh
            ET.SubElement(el, "param", key="device.battery.capacity", value=f"{capacity:.1f}")
            ET.SubElement(el, "param", key="device.battery.chargeLevel", value=f"{capacity * t.soc:.1f}")
            if t.target_soc is not None:
                ET.SubElement(el, "param", key=TARGET_SOC_PARAM, value=f"{t.target_soc:.4f}")
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_demand(demand: Demand, path: str | Path) -> Path:
    """Write the route file atomically; ``.gz`` paths are gzipped (with a fixed mtime)."""
    path = Path(path)
    data = demand_to_xml(demand).encode("utf-8")
    if path.suffix == ".gz":
        data = gzip.compress(data, mtime=0)
    return atomic_write_bytes(path, data)
