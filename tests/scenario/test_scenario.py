"""Scenario folders: any folder of the right shape loads; anything else is a clear, early error."""

from __future__ import annotations

import gzip
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from evcd.scenario.scenario import STATIONS_FILE, VTYPES_FILE, load_scenario
from evcd.scenario.stations_file import read_stations, write_stations
from tests.conftest import run_script


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


def damage(scenario: Path, how: str) -> Path:
    """Replace the scenario's network by a damaged ``.net.xml.gz``: truncated, or valid gzip of broken XML."""
    plain = scenario / "grid.net.xml"
    if how == "truncated":
        data = gzip.compress(plain.read_bytes())[:3000]
    else:
        data = gzip.compress(b'<net version="1.20"><location netOffset="0,0"/><edge id="a"')
    plain.unlink()
    net = scenario / "grid.net.xml.gz"
    net.write_bytes(data)
    return net


@pytest.mark.slow
@pytest.mark.parametrize("how", ["truncated", "broken-xml"])
def test_a_damaged_network_is_named_not_a_traceback(scenario_copy, tmp_path, how):
    net = damage(scenario_copy, how)
    with pytest.raises(ValueError, match=rf"{net} is damaged or not a SUMO network .*build_network"):
        load_scenario(scenario_copy)
    for script, args in (("place_stations.py", [scenario_copy, "--k", "2", "--force"]),
                         ("evaluate.py", ["agent=greedy", f"scenario.path={scenario_copy}", "evs=30",
                                          f"hydra.run.dir={tmp_path / 'run'}"])):  # fmt: skip
        proc = run_script(script, *map(str, args))
        out = proc.stdout + proc.stderr
        assert proc.returncode == 2 and "is damaged or not a SUMO network" in out, out[-2000:]
        assert "Traceback" not in out
    assert not (tmp_path / "run").exists()  # the refused evaluation left no directory
