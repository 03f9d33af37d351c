"""Small real networks for the scenario tests, generated with netgenerate."""

from __future__ import annotations

from pathlib import Path

import pytest
import sumolib

from evcd.sumo_tools import run_tool


def make_grid(path: Path, number: int = 8, length: float = 250.0) -> Path:
    """A left-hand grid network with 2-lane streets."""
    run_tool(
        "netgenerate",
        [
            "--grid", "--grid.number", number, "--grid.length", length,
            "--default.lanenumber", 2, "--default.speed", 13.89,
            "--lefthand", "--no-turnarounds", "false", "-o", path,
        ],
    )  # fmt: skip
    return path


@pytest.fixture(scope="session")
def grid_net_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 x 8 grid, 250 m blocks (1.75 km across)."""
    return make_grid(tmp_path_factory.mktemp("grid") / "grid.net.xml")


@pytest.fixture(scope="session")
def grid_net(grid_net_file: Path) -> sumolib.net.Net:
    """The grid read with sumolib."""
    return sumolib.net.readNet(str(grid_net_file))


def make_grid_scenario(folder: Path, k: int = 3, spacing: float = 700.0) -> Path:
    """A complete scenario folder on an 8 x 8 grid: network, stations, vehicle types."""
    import numpy as np

    from evcd.scenario.placement import place_stations
    from evcd.scenario.scenario import STATIONS_FILE, VTYPES_FILE
    from evcd.scenario.stations_file import write_stations
    from evcd.scenario.vtypes import write_vtypes

    folder.mkdir(parents=True, exist_ok=True)
    net_file = make_grid(folder / "grid.net.xml")
    net = sumolib.net.readNet(str(net_file))
    write_stations(place_stations(net, k, spacing, np.random.default_rng(0)), folder / STATIONS_FILE)
    write_vtypes(folder / VTYPES_FILE)
    return folder


@pytest.fixture(scope="session")
def grid_scenario_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A scenario folder on the grid with 3 stations (do not modify: shared by the session)."""
    return make_grid_scenario(tmp_path_factory.mktemp("grid_scenario"))
