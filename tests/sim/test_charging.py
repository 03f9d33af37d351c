"""The stations' FIFO against real SUMO (libsumo) on the small grid of ``tests/conftest.py``."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from evcd.sim.charging import ChargeRecord, ChargingController, Outcome
from evcd.sim.driver import SumoDriver
from tests import route_xml
from tests.route_xml import write_routes

PAST_CS1 = "A1B1 B1C1 C1D1"  # drives along cs1's edge (B1C1)
PAST_CS2 = "D2C2 C2B2 B2A2"
CAPACITY = 20_000.0  # Wh: small batteries charge in minutes at 100 kW
LEVEL = "device.battery.chargeLevel"
RATE = "device.battery.maximumChargeRate"


def ev(
    vid: str,
    depart: float,
    *,
    soc: float = 0.1,
    lot: str | None = "pa_cs1",
    route: str = PAST_CS1,
    target: float | None = 0.3,
    hold: bool = False,
) -> str:
    return route_xml.ev(vid, depart, route, lot, capacity=CAPACITY, soc=soc, target=target, hold=hold)


def car(vid: str, depart: float, route: str = PAST_CS1, stop: str = "") -> str:
    return route_xml.car(vid, depart, route, stop)


def make_driver(scenario, routes: Path) -> SumoDriver:
    return SumoDriver(scenario.net_file, scenario.additional_files, [routes], seed=1, warnings=False)


def levels(api, vids) -> dict[str, float]:
    return {v: float(api.vehicle.getParameter(v, LEVEL)) for v in vids}


def run_until_empty(driver: SumoDriver, limit: float = 3000.0, each_step=None) -> list[str]:
    """Step until no vehicle is left; fail on any teleport. Returns arrival order."""
    api = driver.api
    arrived: list[str] = []
    while api.simulation.getMinExpectedNumber() > 0:
        assert driver.time < limit, "simulation did not finish"
        driver.step()
        assert api.simulation.getStartingTeleportIDList() == ()
        arrived += api.simulation.getArrivedIDList()
        if each_step is not None:
            each_step(api, driver.time)
    return arrived


def test_fifo_more_evs_than_points(small_scenario, tmp_path):
    names = [f"ev{i}" for i in range(6)]
    routes = write_routes(tmp_path / "r.rou.xml", [ev(v, 4 * i) for i, v in enumerate(names)])
    controller = ChargingController(small_scenario.stations)
    prev: dict[str, float] = {}
    charging_before: set[str] = set()
    waiting_seen: set[str] = set()

    def check(api, now):
        nonlocal prev, charging_before
        assert controller.charging("cs1") <= 2
        assert controller.occupancy("cs1") == controller.charging("cs1") + controller.waiting("cs1")
        parked = api.parkingarea.getVehicleIDs("pa_cs1")
        cur = levels(api, parked)
        gained = {v for v in parked if v in prev and cur[v] > prev[v] + 1e-6}
        # SUMO applies a rate change from the next step: whoever gains held a point one step ago
        assert gained <= charging_before, (now, gained, charging_before)
        assert len(gained) <= 2
        for v in controller.queue("cs1"):
            waiting_seen.add(v)
            if v in prev:
                assert cur[v] == pytest.approx(prev[v], abs=1e-9), f"{v} charges while waiting"
        prev = cur
        charging_before = set(controller.charging_vehicles("cs1"))

    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(controller.update)
        arrived = run_until_empty(driver, each_step=check)

    assert sorted(arrived) == names  # all left the station and reached their destination
    assert len(waiting_seen) >= 3  # the queue really formed
    records = controller.records
    assert [r.vehicle for r in records] == names  # arrival order = departure order here
    starts = [r.start_time for r in records]
    assert starts == sorted(starts)  # charge-start order == arrival order, nobody skips
    for r in records:
        assert r.station == "cs1" and r.outcome is Outcome.CHARGED
        # released in the first step at the target: one step at 95 kW adds 26.4 Wh = 0.13 %
        assert 0.3 <= r.soc_release < 0.3 + 26.4 / CAPACITY
        assert r.soc_start < 0.3
        assert r.soc_start == pytest.approx(r.soc_arrival, abs=1e-9)  # flat while waiting
        assert r.release_time > r.start_time >= r.arrival_time
    # a point passes on in the very step it is freed
    for later in records[2:]:
        assert later.start_time in {r.release_time for r in records}
    assert controller.occupancies() == [0, 0]


def test_waiting_evs_do_not_block_through_traffic(small_scenario, tmp_path):
    def travel_time(vehicles: list[str]) -> tuple[float, int]:
        routes = write_routes(tmp_path / "r.rou.xml", vehicles)
        controller = ChargingController(small_scenario.stations)
        depart: dict[str, float] = {}
        done: dict[str, float] = {}
        max_waiting = 0

        def watch(api, now):
            nonlocal max_waiting
            depart.update(dict.fromkeys(api.simulation.getDepartedIDList(), now))
            done.update(dict.fromkeys(api.simulation.getArrivedIDList(), now))
            if "through" in depart and "through" not in done:
                max_waiting = max(max_waiting, controller.waiting("cs2"))

        with make_driver(small_scenario, routes) as driver:
            driver.add_listener(controller.update)
            driver.add_listener(watch)
            run_until_empty(driver, limit=200.0 if len(vehicles) == 1 else 3000.0)
        return done["through"] - depart["through"], max_waiting

    evs = [ev(f"ev{i}", 3 * i, lot="pa_cs2", route=PAST_CS2) for i in range(5)]
    alone, _ = travel_time([car("through", 60, PAST_CS2)])
    busy, waiting = travel_time([*evs, car("through", 60, PAST_CS2)])
    assert waiting >= 3  # the car passed while the 1-point station had a queue in its car park
    assert busy <= alone + 3.0


def test_hold_flag_and_hold_call(small_scenario, tmp_path):
    vehicles = [
        ev("target", 0, hold=True),
        ev("target2", 0, lot="pa_cs2", route=PAST_CS2, target=0.15),
        ev("e1", 4),
        ev("e2", 8),
    ]  # sorted by departure: SUMO skips vehicles listed out of order
    routes = write_routes(tmp_path / "r.rou.xml", vehicles)
    controller = ChargingController(small_scenario.stations)
    controller.hold("target2")
    started: dict[str, tuple[float, ChargeRecord]] = {}
    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(controller.update)
        api = driver.api
        while driver.time < 900:
            driver.step()
            for rec in controller.started_this_step():
                started[rec.vehicle] = (driver.time, rec)
            parked_now = api.simulation.getParkingStartingVehiclesIDList()
            if "target" in parked_now:  # it got a free point in the step it parked
                assert "target" in [r.vehicle for r in controller.started_this_step()]
        for vid in ("target", "target2"):
            t, rec = started[vid]
            assert rec.hold and rec.start_time == t == rec.arrival_time
            assert controller.status(vid) == "charging"
            assert api.vehicle.isStoppedParking(vid)
            assert float(api.vehicle.getParameter(vid, LEVEL)) == pytest.approx(CAPACITY, rel=1e-3)
        by_id = {r.vehicle: r for r in controller.records}
        assert by_id["e1"].outcome is Outcome.CHARGED
        # target never gives its point back: e2 waits for e1
        assert by_id["e2"].start_time == by_id["e1"].release_time
        done = controller.release(api, "target", driver.time)
        assert done.outcome is Outcome.RELEASED and done.release_time == driver.time
        assert controller.status("target") is None and controller.occupancy("cs1") == 0
        controller.release(api, "target2", driver.time)
        arrived = run_until_empty(driver, limit=2000)
        assert {"target", "target2"} <= set(arrived)


def test_vanishing_vehicles_are_dropped(small_scenario, tmp_path):
    routes = write_routes(tmp_path / "r.rou.xml", [ev(f"ev{i}", 4 * i) for i in range(4)])
    controller = ChargingController(small_scenario.stations)
    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(controller.update)
        while controller.occupancy("cs1") < 4:
            driver.step()
            assert driver.time < 200
        assert controller.queue("cs1") == ("ev2", "ev3")
        driver.api.vehicle.remove("ev2")  # a waiting vehicle
        driver.api.vehicle.remove("ev0")  # a charging one: its point goes to the next in line
        driver.step()
        ended = {r.vehicle: r for r in controller.ended_this_step()}
        assert set(ended) == {"ev0", "ev2"}
        assert all(r.outcome is Outcome.VANISHED for r in ended.values())
        assert controller.charging_vehicles("cs1") == ("ev1", "ev3")
        assert [r.vehicle for r in controller.started_this_step()] == ["ev3"]
        run_until_empty(driver)
    outcomes = {r.vehicle: r.outcome for r in controller.records}
    assert outcomes == {
        "ev0": Outcome.VANISHED,
        "ev1": Outcome.CHARGED,
        "ev2": Outcome.VANISHED,
        "ev3": Outcome.CHARGED,
    }


def test_non_ev_in_car_park_and_stop_that_ends(small_scenario, tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="evcd.sim.charging")
    vehicles = [
        ev("ev0", 0),
        ev("ev1", 2),
        ev("ev2", 4).replace('duration="1000000"', 'duration="30"'),  # gives up waiting after 30 s
        car("parker", 6, stop='<stop parkingArea="pa_cs1" parking="true" duration="20"/>'),
    ]
    routes = write_routes(tmp_path / "r.rou.xml", vehicles)
    controller = ChargingController(small_scenario.stations)
    rates_on_leaving: dict[str, str] = {}

    def on_step(api, now):
        for rec in controller.ended_this_step():
            rates_on_leaving[rec.vehicle] = api.vehicle.getParameter(rec.vehicle, RATE)

    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(controller.update)
        arrived = run_until_empty(driver, each_step=on_step)
    assert sorted(arrived) == ["ev0", "ev1", "ev2", "parker"]
    by_id = {r.vehicle: r for r in controller.records}
    assert set(by_id) == {"ev0", "ev1", "ev2"}  # the car without battery never queued
    assert by_id["ev2"].outcome is Outcome.LEFT and by_id["ev2"].start_time is None
    assert by_id["ev2"].release_time - by_id["ev2"].arrival_time == pytest.approx(30, abs=1.5)
    # the held vehicle drives on with its charge rate given back
    assert float(rates_on_leaving["ev2"]) == pytest.approx(150_000)
    # leaving the car park at the end of a stop is not mistaken for a vanishing or a new arrival
    assert not [r for r in caplog.records if r.name == "evcd.sim.charging" and r.levelname != "DEBUG"]


def test_state_dict_round_trip_plain():
    from evcd.scenario.stations_file import Station

    stations = [Station("a", "a", "e_0", 0, 10, points=1), Station("b", "b", "f_0", 0, 10)]
    c = ChargingController(stations, default_target_soc=0.7, hold=["x"])
    c._records.append(ChargeRecord("v", "a", 1.0, 0.1, 0.7, start_time=2.0, soc_start=0.1))
    c._records.append(
        ChargeRecord("w", "b", 1.0, 0.1, 0.7, release_time=9.0, soc_release=0.1, outcome=Outcome.LEFT)
    )
    state = json.loads(json.dumps(c.state_dict()))
    d = ChargingController(stations)
    d.load_state_dict(state)
    assert d.state_dict() == c.state_dict()
    assert d.records == c.records and d.default_target_soc == 0.7
    with pytest.raises(ValueError, match="stations"):
        ChargingController(stations[:1]).load_state_dict(state)
    with pytest.raises(ValueError, match="version"):
        d.load_state_dict({**state, "version": 99})


def test_state_dict_round_trip_with_sumo_snapshot(small_scenario, tmp_path):
    """Snapshot mid-queue, run on, reload SUMO + controller state: the future repeats exactly."""
    routes = write_routes(tmp_path / "r.rou.xml", [ev(f"ev{i}", 4 * i) for i in range(6)])
    snapshot = tmp_path / "state.xml"
    first = ChargingController(small_scenario.stations)
    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(first.update)
        driver.step(until=120)
        assert first.waiting("cs1") >= 3  # vehicles parked and queued at snapshot time
        driver.save_state(snapshot)
        saved = json.dumps(first.state_dict())
        driver.step(until=400)  # vehicles still parked: exercises the loadState work-around
        at_400 = first.state_dict()
        parked_400 = driver.api.parkingarea.getVehicleIDs("pa_cs1")
        assert parked_400

        driver.remove_listener(first.update)
        second = ChargingController(small_scenario.stations)
        second.load_state_dict(json.loads(saved))
        driver.add_listener(second.update)
        assert driver.load_state(snapshot) == 120
        driver.step(until=400)
        assert second.state_dict() == at_400
        assert driver.api.parkingarea.getVehicleIDs("pa_cs1") == parked_400
        run_until_empty(driver)
    assert [r.outcome for r in second.records] == [Outcome.CHARGED] * 6
