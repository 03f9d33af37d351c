"""Charging points out of service (:mod:`evcd.sim.outages`) against real SUMO on the small grid:
the queue a hand-computed FIFO predicts, what happens to a vehicle whose point fails, bad input."""

from __future__ import annotations

import pytest

from evcd.sim.charging import ChargingController, Outcome
from evcd.sim.outages import Outage, check_outages, points_in_service
from tests.route_xml import write_routes
from tests.sim.test_charging import LEVEL, ev, levels, make_driver, run_until_empty

NAMES = [f"ev{i}" for i in range(4)]


def _records(small_scenario, tmp_path, outages=(), each_step=None):
    routes = write_routes(tmp_path / "r.rou.xml", [ev(v, 4 * i) for i, v in enumerate(NAMES)])
    controller = ChargingController(small_scenario.stations, outages=outages)
    with make_driver(small_scenario, routes) as driver:
        driver.add_listener(controller.update)
        step = None if each_step is None else (lambda api, now: each_step(controller, api, now))
        arrived = run_until_empty(driver, each_step=step)
    assert sorted(arrived) == NAMES
    return {r.vehicle: r for r in controller.records}


def test_an_outage_of_one_of_two_points_queues_as_a_one_point_fifo(small_scenario, tmp_path):
    """cs1 has 2 points; with one out for the whole run its queue is a one-server FIFO: each start is
    the later of the vehicle's arrival and the previous vehicle's release, its charge lasting as long
    as it does with both points (measured in a run without the outage)."""
    calm = _records(small_scenario, tmp_path)
    out = _records(small_scenario, tmp_path, [Outage("cs1", 1, 0.0, 10_000.0)])
    duration = {v: calm[v].release_time - calm[v].start_time for v in NAMES}
    free_at = 0.0
    for v in NAMES:  # the hand-computed FIFO with one point
        r = out[v]
        assert r.arrival_time == calm[v].arrival_time and r.outcome is Outcome.CHARGED
        expected = max(r.arrival_time, free_at)
        assert r.start_time == pytest.approx(expected, abs=1.0), v
        assert r.release_time - r.start_time == pytest.approx(duration[v], abs=1.0), v
        free_at = r.release_time
    # the outage lengthened the queue: the waits add up to more than without it
    waits = [sum(rs[v].queue_wait for v in NAMES) for rs in (calm, out)]
    assert waits[1] > waits[0] + sum(duration.values()) / 2


def test_a_vehicle_whose_point_fails_goes_back_to_the_head_of_the_queue(small_scenario, tmp_path):
    """Both points busy, then one fails: the vehicle that started last stops charging (its level stays
    flat), is first in the queue, resumes when a point frees, before anyone who arrived later; its
    visit keeps its first start and charges as long in all as without the outage."""
    calm = _records(small_scenario, tmp_path)
    first_two = sorted(NAMES, key=lambda v: calm[v].start_time)[:2]
    later = max(first_two, key=lambda v: calm[v].start_time)
    t0 = calm[later].start_time + 20.0  # both charge now
    t1 = t0 + 60.0
    seen = {"flat_from": None, "head": False, "charging_max": 0}
    prev: dict[str, float] = {}

    def check(controller, api, now):
        if t0 + 1 < now < t1:
            seen["charging_max"] = max(seen["charging_max"], controller.charging("cs1"))
            if controller.queue("cs1")[:1] == (later,):
                seen["head"] = True
                assert controller.status(later) == "waiting"
            if later in prev:
                lvl = float(api.vehicle.getParameter(later, LEVEL))
                if controller.status(later) == "waiting" and now > t0 + 2:
                    assert lvl == pytest.approx(prev[later], abs=1e-9), "charges while its point is out"
        prev.update(levels(api, api.parkingarea.getVehicleIDs("pa_cs1")))

    out = _records(small_scenario, tmp_path, [Outage("cs1", 1, t0, t1)], each_step=check)
    assert seen["head"] and seen["charging_max"] == 1
    r = out[later]
    assert r.start_time == calm[later].start_time  # its first start stands
    assert r.outcome is Outcome.CHARGED
    # it charged as long in all; the interruption (the outage, or until the other point freed) on top
    assert r.release_time - r.start_time > calm[later].release_time - calm[later].start_time + 10.0
    (other,) = [v for v in first_two if v != later]
    point_back = min(t1, out[other].release_time)  # the outage ends, or the other point frees
    assert r.release_time - calm[later].release_time == pytest.approx(point_back - t0, abs=2.0)
    for v in NAMES:  # nobody who arrived later got a point before it had its own back
        if v not in first_two:
            assert out[v].start_time >= point_back - 1.0


def test_no_outage_is_the_calm_controller(small_scenario, tmp_path):
    """An empty outage list changes nothing: the same records, to the digit."""
    a = _records(small_scenario, tmp_path)
    b = _records(small_scenario, tmp_path, [])
    assert [x.to_dict() for x in a.values()] == [x.to_dict() for x in b.values()]


def test_bad_outages_are_refused_by_name(small_scenario):
    stations = small_scenario.stations  # cs1: 2 points, cs2: 1
    with pytest.raises(ValueError, match="'nowhere': no such station"):
        check_outages([Outage("nowhere", 1, 0, 10)], stations)
    with pytest.raises(ValueError, match="'cs2' take 2 points out at t=5 s; it has 1"):
        check_outages([Outage("cs2", 1, 0, 10), Outage("cs2", 1, 5, 20)], stations)
    with pytest.raises(ValueError, match="'cs1' take 3 points out"):
        ChargingController(stations, outages=[Outage("cs1", 3, 0, 10)])
    with pytest.raises(ValueError, match="points=0"):
        Outage("cs1", 0, 0, 10)
    with pytest.raises(ValueError, match="start=20, end=10"):
        Outage("cs1", 1, 20, 10)
    ok = check_outages([Outage("cs2", 1, 10, 20), Outage("cs2", 1, 0, 10)], stations)
    assert [o.start for o in ok] == [0, 10]  # back to back is fine; sorted by start
    assert [points_in_service(2, ok, t) for t in (0, 9.9, 10, 20)] == [1, 1, 1, 2]
