"""What determines one background day, hashed into the key of its cache folder
(:class:`~evcd.sim.snapshots.DayCache`).

The key covers the scenario files, the charging points, the demand (config and seed, or a fixed route
file), SUMO's step length and teleport threshold, the day's perturbations (charger outages, road
events), the versions of SUMO, numpy (which draws the demand) and sumolib (which reads the network),
and the evcd code that generates and drives the day (:data:`_CODE`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import libsumo

import evcd
from evcd.scenario.demand import DemandConfig
from evcd.scenario.scenario import Scenario
from evcd.sim.outages import Outage, check_outages
from evcd.sim.road_events import RoadEvents, check_road_events
from evcd.utils.digest import file_sha256

FORMAT_VERSION = 1
# the modules (each evcd module these import is listed: tests/sim/test_snapshots.py) and the packages
# (numpy draws the demand, sumolib reads the network) that shape a cached day: a change invalidates it
_CODE = ("scenario/demand.py", "scenario/routing.py", "scenario/scenario.py", "scenario/stations_file.py",
         "scenario/vtypes.py", "sim/charge_record.py", "sim/charging.py", "sim/day_spec.py", "sim/driver.py",
         "sim/outages.py", "sim/road_events.py", "sim/road_player.py", "sim/snapshots.py", "sim/stops.py",
         "sim/visits.py", "utils/atomic.py", "utils/digest.py", "utils/sumo_tools.py", "utils/validation.py",
         "utils/xml_files.py")  # fmt: skip
_PACKAGES = ("numpy", "sumolib")


def _code_hash() -> str:
    root = Path(evcd.__file__).parent
    h = hashlib.sha256()
    for rel in _CODE:
        h.update(rel.encode())
        h.update((root / rel).read_bytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class DaySpec:
    """Everything that determines one background day.

    Attributes:
        scenario: the scenario (its stations carry the charging points in force).
        demand: the generated demand's config; ``None`` with ``route_file``.
        demand_seed: the demand's seed; also SUMO's ``--seed`` for the day.
        route_file: a fixed SUMO route file used as the day's demand instead of generating one.
        step_length: SUMO step (s).
        time_to_teleport: SUMO's jam teleport threshold (s).
        outages: the day's charger outages (drawn from its seed: :mod:`evcd.sim.perturbations`), in
            the key only when there are some; ``roads``: its incidents, rain and road works, likewise.
    """

    scenario: Scenario
    demand: DemandConfig | None = None
    demand_seed: int = 0
    route_file: Path | None = None
    step_length: float = 1.0
    time_to_teleport: float = 300.0
    outages: tuple[Outage, ...] = ()
    roads: RoadEvents = dataclasses.field(default_factory=RoadEvents)

    def __post_init__(self) -> None:
        if (self.demand is None) == (self.route_file is None):
            raise ValueError("a DaySpec needs exactly one of demand and route_file")
        object.__setattr__(self, "outages", check_outages(self.outages, self.scenario.stations))
        if not self.roads.empty:
            check_road_events(self.roads, self.scenario.net, {st.lane for st in self.scenario.stations})

    @property
    def sumo_seed(self) -> int:
        """SUMO's ``--seed`` for this day (the day, SUMO's draws included, is what is cached)."""
        return int(self.demand_seed)

    @cached_property
    def fields(self) -> dict[str, Any]:
        """The key's ingredients (JSON-serialisable); hashing the files takes a moment."""
        sc = self.scenario
        demand = None if self.demand is None else dataclasses.asdict(self.demand)
        fields = {
            "format": FORMAT_VERSION,
            "sumo": libsumo.getVersion()[1],
            "packages": {name: importlib.metadata.version(name) for name in _PACKAGES},
            "code": _code_hash(),
            "net": file_sha256(sc.net_file),
            "stations": file_sha256(sc.stations_file),
            "vtypes": file_sha256(sc.vtypes_file),
            "charging_points": [st.points for st in sc.stations],
            "demand": demand,
            "demand_seed": int(self.demand_seed),
            "route_file": None if self.route_file is None else file_sha256(self.route_file),
            "step_length": float(self.step_length),
            "time_to_teleport": float(self.time_to_teleport),
        }
        if self.outages:
            fields["outages"] = [dataclasses.asdict(o) for o in self.outages]
        if not self.roads.empty:
            fields["roads"] = self.roads.to_dict()
        return fields

    @cached_property
    def key(self) -> str:
        """Hex digest naming the day's cache folder."""
        blob = json.dumps(self.fields, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:24]
