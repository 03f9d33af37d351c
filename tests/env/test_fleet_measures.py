"""The fleet's episode measures, on hand-built outcomes and station records."""

from __future__ import annotations

import math

import pytest

from evcd.env.fleet.measures import measure
from evcd.env.fleet.trips import ChargingTrip
from evcd.sim.charge_record import ChargeRecord


def outcome(vid: str, depart: float, station: int, reason: str = "charging", travel: float = 100.0,
            wait: float = 0.0) -> dict:  # fmt: skip
    return {"vehicle": vid, "departure": depart, "station": station, "reason": reason,
            "travel_time": travel, "queue_wait": wait}  # fmt: skip


def test_guided_and_all_travel_times_waits_and_truncations() -> None:
    candidates = [ChargingTrip("g1", 1000.0, 0), ChargingTrip("g2", 1010.0, 0), ChargingTrip("b1", 1020.0, 1),
                  ChargingTrip("b2", 1030.0, 1)]  # fmt: skip
    records = [
        ChargeRecord("g1", "cs1", 1100.0, 0.1, 0.8, start_time=1100.0),
        ChargeRecord("g2", "cs2", 1200.0, 0.1, 0.8, start_time=None, release_time=1250.0),  # left the queue
        ChargeRecord("g2", "cs1", 1400.0, 0.1, 0.8, start_time=1500.0),
        ChargeRecord("b1", "cs2", 1300.0, 0.1, 0.8, start_time=1320.0),
        ChargeRecord("x", "cs2", 900.0, 0.1, 0.8, start_time=950.0),  # departed before the window
    ]  # b2 never started charging
    outcomes = [outcome("g1", 1000.0, 0, travel=100.0), outcome("g2", 1010.0, 0, travel=490.0, wait=150.0),
                outcome("g3", 1040.0, 1, reason="stuck", travel=600.0, wait=0.0)]  # fmt: skip
    m = measure(outcomes, candidates, records, window_start=900.0)
    assert (m.guided, m.guided_charged, m.truncated) == (3, 2, 1)
    assert m.guided_travel == pytest.approx((100.0 + 490.0) / 2)
    assert m.guided_travel_censored == pytest.approx((100.0 + 490.0 + 600.0) / 3)  # g3 at its truncation
    assert m.queue_wait == pytest.approx(150.0 / 3)
    assert m.all_evs == 4 and m.all_unfinished == 1
    assert m.all_travel == pytest.approx((100.0 + 490.0 + 300.0) / 3)  # g2 counts from its charge start
    assert math.isnan(m.herding)  # no 10-minute bin holds 4 guided EVs


def test_herding_is_the_largest_share_of_one_bin_at_one_station() -> None:
    first = [outcome(f"a{i}", 100.0 + i, 0) for i in range(4)]  # bin 0: all four at station 0
    second = [outcome(f"b{i}", 700.0 + i, i % 2) for i in range(4)]  # bin 1: two and two
    assert measure(first + second, [], [], window_start=0.0).herding == 1.0
    assert measure(second, [], [], window_start=0.0).herding == 0.5
    three = [outcome(f"c{i}", 100.0 + i, 0) for i in range(3)]
    assert math.isnan(measure(three, [], [], window_start=0.0).herding)
