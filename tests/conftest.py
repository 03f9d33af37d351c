"""Shared fixtures: a small real SUMO scenario generated once per test session."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from evcd.scenario.stations_file import Station, write_stations
from evcd.scenario.vtypes import write_vtypes
from evcd.sumo_tools import run_tool


@dataclass(frozen=True)
class SmallScenario:
    """A 4 x 4 left-hand grid (200 m blocks, one lane per direction) with two stations.

    ``cs1`` (2 points) sits on ``B1C1``, ``cs2`` (1 point) on ``C2B2``; ``A1B1 B1C1 C1D1`` drives
    past ``cs1``'s car park.
    """

    root: Path
    net_file: Path
    stations_file: Path
    vtypes_file: Path
    stations: tuple[Station, ...]

    @property
    def additional_files(self) -> list[Path]:
        """Vehicle types first: route files refer to them."""
        return [self.vtypes_file, self.stations_file]


@pytest.fixture(scope="session")
def small_scenario(tmp_path_factory: pytest.TempPathFactory) -> SmallScenario:
    root = tmp_path_factory.mktemp("small_scenario")
    net_file = root / "grid.net.xml"
    run_tool(
        "netgenerate",
        ["--grid", "--grid.number", 4, "--grid.length", 200, "--lefthand", "-o", net_file],
    )
    stations = (
        Station(id="cs1", name="one", lane="B1C1_0", start_pos=60.0, end_pos=100.0, points=2),
        Station(id="cs2", name="two", lane="C2B2_0", start_pos=60.0, end_pos=100.0, points=1),
    )
    stations_file = write_stations(list(stations), root / "stations.add.xml")
    vtypes_file = write_vtypes(root / "vtypes.add.xml")
    return SmallScenario(root, net_file, stations_file, vtypes_file, stations)


@pytest.fixture(scope="session", autouse=True)
def _isolated_snapshot_cache(tmp_path_factory: pytest.TempPathFactory):
    """Day snapshots built by tests (and the scripts they start) go to a temporary cache, never ~/.cache."""
    patch = pytest.MonkeyPatch()
    patch.setenv("EVCD_CACHE", str(tmp_path_factory.mktemp("evcd_cache")))
    yield
    patch.undo()
