"""A scenario is a folder: a SUMO network, a stations file and vehicle types.

    my_city/
        net.net.xml.gz      (or any single ``*.net.xml`` / ``*.net.xml.gz``)
        stations.add.xml    charging stations (see :mod:`evcd.scenario.stations_file`)
        vtypes.add.xml      vehicle types ``car`` and ``ev`` (optional: written on demand)

Any folder of that shape works; :func:`load_scenario` checks it before anything is simulated.
"""

from __future__ import annotations

import logging
import xml.sax
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import sumolib

from evcd.scenario.stations_file import Station, read_stations

log = logging.getLogger(__name__)

#: The scenario shipped with evcd.
JURONG_WEST = Path(__file__).resolve().parents[2] / "sumo_net" / "jurong_west"

STATIONS_FILE = "stations.add.xml"
VTYPES_FILE = "vtypes.add.xml"


@dataclass(frozen=True)
class Scenario:
    """A validated scenario folder.

    Attributes:
        root: the folder.
        net_file: the SUMO network.
        stations_file: the SUMO additional file with the charging stations.
        vtypes_file: the SUMO additional file with the vehicle types ``car`` and ``ev``.
        stations: the stations (with the charging points in force).
    """

    root: Path
    net_file: Path
    stations_file: Path
    vtypes_file: Path
    stations: tuple[Station, ...]

    @cached_property
    def net(self) -> sumolib.net.Net:
        """The network, read with sumolib (a second or two for a town; cached)."""
        return read_net(self.net_file)

    @property
    def additional_files(self) -> list[Path]:
        """Files SUMO loads with ``--additional-files`` (vehicle types first)."""
        return [self.vtypes_file, self.stations_file]


def read_net(net_file: str | Path) -> sumolib.net.Net:
    """Read a SUMO network with sumolib.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is damaged or not a SUMO network (a truncated ``.gz``, broken XML, a
            ``<net>`` without its attributes), naming the file and what sumolib found.
    """
    net_file = Path(net_file)
    if not net_file.is_file():
        raise FileNotFoundError(f"SUMO network not found: {net_file}")
    try:
        return sumolib.net.readNet(str(net_file))
    except (OSError, EOFError, KeyError, ValueError, xml.sax.SAXException) as exc:
        raise ValueError(f"{net_file} is damaged or not a SUMO network ({type(exc).__name__}: {exc}); "
                         "build it again with scripts/build_network.py") from exc  # fmt: skip


def find_net_file(root: Path) -> Path:
    """The single network file of a scenario folder."""
    nets = sorted(p for p in root.iterdir() if p.name.endswith((".net.xml", ".net.xml.gz")))
    if len(nets) != 1:
        found = [p.name for p in nets] or "none"
        raise ValueError(f"scenario {root} must hold exactly one *.net.xml[.gz] network, found: {found}")
    return nets[0]


def load_scenario(root: str | Path, charging_points: int | None = None, check_net: bool = True) -> Scenario:
    """Open and validate a scenario folder.

    Args:
        root: the folder.
        charging_points: overrides every station's number of charging points (>= 1).
        check_net: also read the network and check that every station's lane exists in it.

    Raises:
        FileNotFoundError: the folder or its stations file is missing.
        ValueError: malformed stations, a station on a lane the network lacks, bad ``charging_points``.
    """
    root = Path(root).expanduser().resolve()
    if not root.is_dir():
        raise FileNotFoundError(f"scenario folder not found: {root}")
    if charging_points is not None and charging_points < 1:
        raise ValueError(f"charging_points={charging_points}: must be >= 1")
    net_file = find_net_file(root)
    stations_file = root / STATIONS_FILE
    stations = read_stations(stations_file, points=charging_points)
    ids = [s.id for s in stations]
    if len(set(ids)) != len(ids):
        raise ValueError(f"stations file {stations_file} repeats a station id: {ids}")
    vtypes_file = root / VTYPES_FILE
    if not vtypes_file.is_file():
        raise FileNotFoundError(f"scenario {root} lacks its vehicle types file {VTYPES_FILE}")
    scenario = Scenario(root, net_file, stations_file, vtypes_file, tuple(stations))
    if check_net:
        net = scenario.net
        for st in stations:
            if not net.hasEdge(st.edge):
                raise ValueError(
                    f"station {st.id!r} is on lane {st.lane!r}, whose edge is not in {net_file.name}"
                )
            lanes = {lane.getID(): lane for lane in net.getEdge(st.edge).getLanes()}
            if st.lane not in lanes:
                raise ValueError(
                    f"station {st.id!r}: lane {st.lane!r} not in network (edge has {sorted(lanes)})"
                )
            length = lanes[st.lane].getLength()
            if st.end_pos > length + 1e-6:
                raise ValueError(f"station {st.id!r}: endPos={st.end_pos} beyond lane length {length:.1f}")
    return scenario
