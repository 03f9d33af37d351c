"""SumoDriver against real SUMO: life cycle, one libsumo simulation per process, stepping, snapshots."""

from __future__ import annotations

from pathlib import Path

import pytest

from evcd.sim.driver import SumoDriver


@pytest.fixture
def routes(tmp_path: Path) -> Path:
    """Ten cars on a loop of the small grid, one every 5 s."""
    cars = "\n".join(
        f'<vehicle id="c{i}" type="car" depart="{5 * i}"><route edges="A0A1 A1B1 B1C1 C1D1 D1D0"/></vehicle>'
        for i in range(10)
    )
    path = tmp_path / "cars.rou.xml"
    path.write_text(f"<routes>\n{cars}\n</routes>\n", encoding="utf-8")
    return path


@pytest.fixture
def driver(small_scenario, routes) -> SumoDriver:
    return SumoDriver(small_scenario.net_file, small_scenario.additional_files, [routes], seed=3)


def positions(api) -> dict[str, tuple[str, float]]:
    vehicle = api.vehicle
    return {v: (vehicle.getLaneID(v), round(vehicle.getLanePosition(v), 6)) for v in vehicle.getIDList()}


def test_command_line_is_built_from_the_arguments(small_scenario, routes):
    d = SumoDriver(
        small_scenario.net_file,
        small_scenario.additional_files,
        [routes],
        seed=42,
        begin=10,
        end=500,
        step_length=0.5,
        time_to_teleport=-1,
        warnings=False,
        extra_args=["--tripinfo-output", "x.xml"],
    )
    cmd = d.command()
    assert Path(cmd[0]).name == "sumo"
    opts = dict(zip(cmd[1::2], cmd[2::2], strict=False))
    assert opts["--seed"] == "42" and opts["--begin"] == "10" and opts["--end"] == "500"
    assert opts["--step-length"] == "0.5" and opts["--time-to-teleport"] == "-1"
    assert opts["--additional-files"] == ",".join(map(str, small_scenario.additional_files))
    assert "--no-warnings" in cmd and cmd[-2:] == ["--tripinfo-output", "x.xml"]
    assert not d.running


def test_step_time_and_listeners(driver):
    calls: list[float] = []

    def listener(api, now):
        calls.append(now)

    with driver:
        assert driver.time == 0
        assert driver.step() == 1.0
        driver.add_listener(listener)
        assert driver.step(until=5) == 5.0
        assert calls == [2.0, 3.0, 4.0, 5.0]  # once per step, after it, with its time
        driver.step(until=5)  # already there: no step
        assert calls[-1] == 5.0 and len(calls) == 4
        driver.remove_listener(listener)
        assert driver.step(until=30) == 30.0  # without listeners: one SUMO call
        assert len(calls) == 4
        assert len(driver.api.vehicle.getIDList()) > 0


def test_context_manager_closes_after_an_exception(driver, small_scenario, routes):
    with pytest.raises(ZeroDivisionError), driver:
        driver.step()
        _ = 1 / 0
    assert not driver.running and SumoDriver.active() is None
    with pytest.raises(RuntimeError, match="not running"):
        _ = driver.api
    # the process can run a new simulation afterwards, and the closed driver can start again
    with SumoDriver(small_scenario.net_file, [small_scenario.vtypes_file], [routes], seed=1) as other:
        assert other.step(until=3) == 3.0
    with driver:
        assert driver.time == 0


def test_only_one_libsumo_simulation_per_process(driver, small_scenario, routes):
    with driver:
        driver.step(until=20)
        before = positions(driver.api)
        second = SumoDriver(small_scenario.net_file, [small_scenario.vtypes_file], [routes], seed=1)
        with pytest.raises(RuntimeError, match="already running"):
            second.start()
        with pytest.raises(RuntimeError, match="already running"):
            driver.start()
        assert SumoDriver.active() is driver
        assert positions(driver.api) == before  # the first simulation was not replaced
        assert driver.step() == 21.0
    assert not second.running


def test_missing_and_broken_inputs_give_clear_errors(small_scenario, routes, tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.net\.xml"):
        SumoDriver(tmp_path / "nope.net.xml", seed=0).start()
    # a <net> without <location> would crash SUMO 1.28 (segfault): refused before SUMO sees it
    no_location = tmp_path / "empty.net.xml"
    no_location.write_text("<net><edge id='x'/></net>", encoding="utf-8")
    with pytest.raises(RuntimeError, match="not a SUMO network"):
        SumoDriver(no_location, seed=0).start()
    truncated = tmp_path / "truncated.net.xml"
    truncated.write_bytes(small_scenario.net_file.read_bytes()[:5000])
    with pytest.raises(RuntimeError, match=r"(?s)SUMO failed to start: .*truncated\.net\.xml"):
        SumoDriver(truncated, seed=0).start()
    bad_route = tmp_path / "bad.rou.xml"
    bad_route.write_text('<routes><vehicle id="v" depart="0"><route edges="nowhere"/></vehicle></routes>')
    with pytest.raises(RuntimeError, match="nowhere"):
        SumoDriver(small_scenario.net_file, route_files=[bad_route], seed=0).start()
    assert SumoDriver.active() is None
    with SumoDriver(small_scenario.net_file, [small_scenario.vtypes_file], [routes], seed=0) as d:
        assert d.step() == 1.0  # a failed start leaves nothing behind
    with pytest.raises(ValueError):
        SumoDriver(small_scenario.net_file, seed=0, step_length=0)


def test_save_and_load_state_round_trip(driver, tmp_path):
    state = tmp_path / "snap" / "t40.xml"
    state.parent.mkdir()
    with driver:
        driver.step(until=40)
        assert driver.save_state(state) == state
        assert [p.name for p in state.parent.iterdir()] == ["t40.xml"]  # no temp file left behind
        driver.step(until=70)
        at_70 = positions(driver.api)
        assert at_70
        assert driver.load_state(state) == 40.0
        assert driver.time == 40.0
        driver.step(until=70)
        assert positions(driver.api) == at_70
        with pytest.raises(FileNotFoundError):
            driver.load_state(tmp_path / "missing.xml")


def test_compressed_state_by_suffix(driver, tmp_path):
    with driver:
        driver.step(until=30)
        at_30 = positions(driver.api)
        path = driver.save_state(tmp_path / "t30.xml.gz")
        assert path.read_bytes()[:2] == b"\x1f\x8b"  # gzip
        driver.step(until=50)
        driver.load_state(path)
        assert positions(driver.api) == at_30


def test_traci_backend_has_the_same_api(small_scenario, routes):
    with SumoDriver(
        small_scenario.net_file, small_scenario.additional_files, [routes], seed=3, use_traci=True
    ) as d:
        assert SumoDriver.active() is None  # TraCI runs SUMO in a child process
        d.step(until=20)
        over_traci = positions(d.api)
    with SumoDriver(small_scenario.net_file, small_scenario.additional_files, [routes], seed=3) as d:
        d.step(until=20)
        assert positions(d.api) == over_traci  # same seed, same simulation
