"""Read and write a scenario's charging stations (a SUMO additional file).

Each station is an off-road ``parkingArea`` (the car park: EVs that wait do not block the road and
never teleport) and a ``chargingStation`` linked to it through the ``parkingArea`` attribute, so that
SUMO's battery device charges the vehicles parked there. The number of charging points is not a SUMO
concept: it is stored as a ``<param key="chargingPoints">`` and enforced by the simulation's FIFO
controller (:mod:`evcd.sim.charging`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from evcd.utils.atomic import atomic_write_text
from evcd.utils.xml_files import read_xml_root

DEFAULT_POWER_W = 100_000.0
DEFAULT_POINTS = 2
DEFAULT_LOT_CAPACITY = 60
STATION_LENGTH = 20.0


@dataclass(frozen=True)
class Station:
    """One charging station.

    Attributes:
        id: SUMO id of the ``chargingStation``; the car park is ``pa_<id>``.
        name: human-readable name.
        lane: SUMO lane id the car park is attached to (``<edge>_<index>``).
        start_pos: start of the car park along the lane (m).
        end_pos: end of the car park along the lane (m).
        power_w: charging power of each point (W).
        points: number of vehicles that may charge at the same time.
        lot_capacity: parking spaces in the car park (waiting + charging).
        parking_area: SUMO id of the car park; defaults to ``pa_<id>``.
    """

    id: str
    name: str
    lane: str
    start_pos: float
    end_pos: float
    power_w: float = DEFAULT_POWER_W
    points: int = DEFAULT_POINTS
    lot_capacity: int = DEFAULT_LOT_CAPACITY
    parking_area: str = ""

    @property
    def edge(self) -> str:
        """The SUMO edge id of the station's lane."""
        return self.lane.rsplit("_", 1)[0]

    @property
    def mid_pos(self) -> float:
        """Middle of the car park along the lane (m): where station distances are measured to."""
        return (self.start_pos + self.end_pos) / 2

    def __post_init__(self) -> None:
        if not self.parking_area:
            object.__setattr__(self, "parking_area", f"pa_{self.id}")
        if self.points < 1:
            raise ValueError(f"station {self.id!r}: points={self.points} must be >= 1")
        if self.lot_capacity < self.points:
            raise ValueError(
                f"station {self.id!r}: lot_capacity={self.lot_capacity} must be >= points={self.points}"
            )
        if self.power_w <= 0:
            raise ValueError(f"station {self.id!r}: power_w={self.power_w} must be > 0")
        if not self.end_pos > self.start_pos >= 0:
            raise ValueError(
                f"station {self.id!r}: need 0 <= start_pos < end_pos, got {self.start_pos}, {self.end_pos}"
            )


def stations_to_xml(stations: list[Station]) -> str:
    """Serialise stations into the text of a SUMO additional file."""
    root = ET.Element("additional")
    for st in stations:
        common = {
            "lane": st.lane,
            "startPos": f"{st.start_pos:.2f}",
            "endPos": f"{st.end_pos:.2f}",
            "friendlyPos": "true",
            "name": st.name,
        }
        ET.SubElement(
            root,
            "parkingArea",
            id=st.parking_area,
            roadsideCapacity=str(st.lot_capacity),
            onRoad="false",
            **common,
        )
        cs = ET.SubElement(
            root,
            "chargingStation",
            id=st.id,
            power=f"{st.power_w:.0f}",
            efficiency="0.95",
            # one step of plug-in delay: SUMO charges in the very step a vehicle parks, before the
            # FIFO controller can hold it at rate 0; with chargeDelay >= the step length a waiting
            # vehicle never gets energy it is not entitled to (seen in SUMO 1.28)
            chargeDelay="1",
            parkingArea=st.parking_area,
            **common,
        )
        ET.SubElement(cs, "param", key="chargingPoints", value=str(st.points))
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_stations(stations: list[Station], path: str | Path) -> Path:
    """Write ``stations`` to ``path`` atomically (temp file + rename)."""
    return atomic_write_text(path, stations_to_xml(stations))


def read_stations(path: str | Path, points: int | None = None) -> list[Station]:
    """Read the stations of a SUMO additional file.

    Args:
        path: the stations file.
        points: if given, overrides every station's number of charging points.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: the file is not XML, has no charging stations, or a station lacks its car park.
    """
    path = Path(path)
    root = read_xml_root(path, "stations file")
    lots = {pa.get("id"): pa for pa in root.iter("parkingArea")}
    stations = []
    for cs in root.iter("chargingStation"):
        sid = cs.get("id")
        pa_id = cs.get("parkingArea")
        if pa_id not in lots:
            raise ValueError(
                f"stations file {path}: chargingStation {sid!r} must link an off-road parkingArea "
                f"(parkingArea={pa_id!r}; known: {sorted(lots)})"
            )
        lot = lots[pa_id]
        params = {p.get("key"): p.get("value") for p in cs.iter("param")}
        stations.append(
            Station(
                id=sid,
                name=cs.get("name", sid),
                lane=lot.get("lane"),
                start_pos=float(lot.get("startPos", 0.0)),
                end_pos=float(lot.get("endPos", STATION_LENGTH)),
                power_w=float(cs.get("power", DEFAULT_POWER_W)),
                points=points if points is not None else int(params.get("chargingPoints", DEFAULT_POINTS)),
                lot_capacity=int(lot.get("roadsideCapacity", DEFAULT_LOT_CAPACITY)),
                parking_area=pa_id,
            )
        )
    if not stations:
        raise ValueError(f"stations file {path} declares no <chargingStation>")
    return stations
