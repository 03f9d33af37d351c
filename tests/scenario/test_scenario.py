"""Scenario folders: any folder of the right shape loads; anything else is a clear, early error."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from evcd.scenario.scenario import STATIONS_FILE, VTYPES_FILE, load_scenario
from evcd.scenario.stations_file import read_stations, write_stations


@pytest.fixture
def scenario_copy(grid_env_dir: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(grid_env_dir, dst)
    return dst


def test_loads_and_overrides_points(grid_env_dir):
    sc = load_scenario(grid_env_dir)
    assert len(sc.stations) == 3 and all(s.points == 2 for s in sc.stations)
    assert sc.additional_files == [
        grid_env_dir.resolve() / VTYPES_FILE,
        grid_env_dir.resolve() / STATIONS_FILE,
    ]
    assert all(s.points == 4 for s in load_scenario(grid_env_dir, charging_points=4).stations)


def test_stations_file_round_trip(grid_env_dir, tmp_path):
    stations = read_stations(grid_env_dir / STATIONS_FILE)
    write_stations(stations, tmp_path / "s.add.xml")
    assert read_stations(tmp_path / "s.add.xml") == stations


def test_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_scenario(tmp_path / "nowhere")


def test_missing_stations_file(scenario_copy):
    (scenario_copy / STATIONS_FILE).unlink()
    with pytest.raises(FileNotFoundError, match=STATIONS_FILE):
        load_scenario(scenario_copy)


def test_malformed_stations_file(scenario_copy):
    (scenario_copy / STATIONS_FILE).write_text("<additional><chargingStation id='x'")
    with pytest.raises(ValueError, match="malformed XML"):
        load_scenario(scenario_copy)


def test_station_without_car_park(scenario_copy):
    (scenario_copy / STATIONS_FILE).write_text(
        '<additional><chargingStation id="x" lane="a_0" startPos="0" endPos="9"/></additional>'
    )
    with pytest.raises(ValueError, match="parkingArea"):
        load_scenario(scenario_copy)


def test_station_on_an_edge_not_in_the_network(scenario_copy):
    stations = read_stations(scenario_copy / STATIONS_FILE)
    write_stations([replace(stations[0], lane="ghost_edge_0"), *stations[1:]], scenario_copy / STATIONS_FILE)
    with pytest.raises(ValueError, match="ghost_edge"):
        load_scenario(scenario_copy)


def test_two_networks_are_ambiguous(scenario_copy):
    shutil.copy(scenario_copy / "grid.net.xml", scenario_copy / "other.net.xml")
    with pytest.raises(ValueError, match="exactly one"):
        load_scenario(scenario_copy)


def test_bad_charging_points(grid_env_dir):
    with pytest.raises(ValueError, match="charging_points=0"):
        load_scenario(grid_env_dir, charging_points=0)
