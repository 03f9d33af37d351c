"""OccupancyTimeline: vehicles at each station over time from visit records, hand-computed on a toy day,
and on a real SUMO day against the controller's own queues in the day cache's snapshots."""

from __future__ import annotations

import json

import numpy as np
import pytest

from evcd.forecast import OccupancyTimeline, OracleForecaster
from evcd.scenario.demand import DemandConfig
from evcd.scenario.scenario import load_scenario
from evcd.sim.charge_record import ChargeRecord, Outcome
from evcd.sim.snapshots import DayCache, DaySpec

# (station, arrival, release): read at t = 1000, so the visit arriving at 1200 is not known yet and the
# one released at 1500 is still there at 1000
VISITS = [
    ("a", 100, 400),
    ("a", 200, 300),
    ("a", 250, None),
    ("b", 500, 700),
    ("b", 900, 1500),
    ("a", 1200, None),
]
TIMES = [0, 100, 199, 200, 250, 299, 300, 400, 600, 700, 950, 1000]
#: a: 1 from 100, 2 from 200, 3 from 250, 2 from 300, 1 from 400; b: 1 in [500, 700), 1 from 900
EXPECTED = [[0, 0], [1, 0], [1, 0], [2, 0], [3, 0], [3, 0], [2, 0], [1, 0], [1, 1], [1, 0], [1, 1], [1, 1]]


def record(station: str, arrival: float, release: float | None) -> ChargeRecord:
    outcome = None if release is None else Outcome.CHARGED
    return ChargeRecord(
        f"v{arrival}", station, float(arrival), 0.2, 0.8, release_time=release, outcome=outcome
    )


def toy() -> OccupancyTimeline:
    return OccupancyTimeline.from_records([record(*v) for v in VISITS], ["a", "b"], known_until=1000.0)


def test_the_count_at_chosen_times_follows_arrivals_inclusive_and_releases_exclusive():
    timeline = toy()
    assert timeline.stations == ("a", "b") and timeline.known_until == 1000.0
    counts = timeline.at(TIMES)
    assert counts.dtype == np.int64 and counts.shape == (len(TIMES), 2)
    assert counts.tolist() == EXPECTED
    assert timeline.at(250.0).tolist() == [3, 0] and timeline.at(250.0).shape == (2,)
    assert timeline.at(-5.0).tolist() == [0, 0]


def test_records_as_dicts_give_the_same_timeline_as_the_records():
    dicts = [record(*v).to_dict() for v in VISITS]
    timeline = OccupancyTimeline.from_records(dicts, ("a", "b"), 1000.0)
    assert timeline.at(TIMES).tolist() == EXPECTED
    mixed = OccupancyTimeline.from_records(
        [*dicts[:3], *(record(*v) for v in VISITS[3:])], ("a", "b"), 1000.0
    )
    assert mixed.at(TIMES).tolist() == EXPECTED


def test_a_time_after_known_until_is_refused_unless_clipped():
    timeline = toy()
    with pytest.raises(ValueError, match=r"time 1001 is after known_until=1000: the future is unknown"):
        timeline.at(1001.0)
    with pytest.raises(ValueError, match="after known_until"):
        timeline.at([500.0, 5000.0])
    assert timeline.at([500.0, 5000.0], clip=True).tolist() == [[1, 1], [1, 1]]  # 5000: the value at 1000
    with pytest.raises(ValueError, match="must be finite"):
        timeline.at(float("nan"))


def test_at_each_reads_one_time_per_station():
    timeline = toy()
    assert timeline.at_each([250.0, 600.0]).tolist() == [3, 1]
    assert timeline.at_each([[250.0, 600.0], [450.0, 800.0]]).tolist() == [[3, 1], [1, 0]]
    assert timeline.at_each([[2000.0, 2000.0]], clip=True).tolist() == [[1, 1]]
    with pytest.raises(ValueError, match="must end in the number of stations"):
        timeline.at_each([250.0])


def test_truncated_is_the_day_as_known_then():
    timeline = toy()
    then = timeline.truncated(250.0)
    assert then.known_until == 250.0
    assert then.at([0.0, 100.0, 200.0, 250.0]).tolist() == [[0, 0], [1, 0], [2, 0], [3, 0]]
    with pytest.raises(ValueError, match="the future is unknown"):
        then.at(300.0)
    assert then.at(300.0, clip=True).tolist() == [3, 0]  # the release at 300 is not known at 250
    with pytest.raises(ValueError, match="known_until=2000"):
        timeline.truncated(2000.0)


def test_the_charging_sessions_are_known_up_to_known_until_and_as_of_a_truncation():
    # (station, arrival, start, release) read at 1000: a's session from 300 ended at 700; a's from 650 goes
    # on; b's visit waited from 500 and started at 900; b's start at 1100 is not known yet
    visits = [("a", 100, 300, 700), ("a", 600, 650, None), ("b", 500, 900, 1500), ("b", 950, 1100, None)]
    records = [{**record(s, a, r).to_dict(), "start_time": float(t)} for s, a, t, r in visits]
    records.append(record("a", 800, None).to_dict())  # waiting, never charged
    timeline = OccupancyTimeline.from_records(records, ("a", "b"), 1000.0)
    assert sorted(timeline.charge_durations().tolist()) == [400.0]
    assert [x.tolist() for x in timeline.charging_since(1000.0)] == [[650.0], [900.0]]
    assert [x.tolist() for x in timeline.charging_since(500.0)] == [[300.0], []]
    assert [x.tolist() for x in timeline.arrival_times()] == [[100.0, 600.0, 800.0], [500.0, 950.0]]
    then = timeline.truncated(680.0)  # a's first session still going then, b not started
    assert then.charge_durations().size == 0
    assert [x.tolist() for x in then.charging_since(680.0)] == [[300.0, 650.0], []]
    with pytest.raises(ValueError, match="now=1001"):
        timeline.charging_since(1001.0)
    with pytest.raises(ValueError, match=r"start_time=50\.0 of a visit at 'a': must lie between its arrival"):
        OccupancyTimeline.from_records([{**records[0], "start_time": 50.0}], ("a", "b"), 1000.0)


def test_bad_records_and_stations_are_refused():
    with pytest.raises(ValueError, match=r"station 'c': the timeline's stations are \['a', 'b'\]"):
        OccupancyTimeline.from_records([record("c", 10.0, None)], ["a", "b"], 1000.0)
    with pytest.raises(ValueError, match="must be >= its arrival_time"):
        OccupancyTimeline.from_records([record("a", 10.0, 5.0)], ["a"], 1000.0)
    with pytest.raises(ValueError, match="lacks"):
        OccupancyTimeline.from_records([{"station": "a", "arrival_time": 1.0}], ["a"], 1000.0)
    with pytest.raises(ValueError, match="distinct"):
        OccupancyTimeline.from_records([], ["a", "a"], 1000.0)
    with pytest.raises(ValueError, match="at least one station"):
        OccupancyTimeline.from_records([], [], 1000.0)
    with pytest.raises(ValueError, match="known_until=inf"):
        OccupancyTimeline.from_records([], ["a"], float("inf"))


def test_on_a_real_day_the_timeline_matches_the_controllers_queues(small_scenario, tmp_path):
    """A short SUMO day on the small grid: the timeline built from the 7200 s snapshot's records has,
    at 3600 s, the vehicles queued and charging in the 3600 s snapshot (and at 7200 s those of 7200 s);
    the oracle on it forecasts exactly that."""
    demand = DemandConfig(
        cars_per_day=300, evs=30, charging_share=1.0, min_trip_m=200.0, hourly_profile=(1.0,) + (0.0,) * 23
    )
    spec = DaySpec(load_scenario(small_scenario.root), demand, demand_seed=5)
    early, late = DayCache(spec, tmp_path).ensure([3600.0, 7200.0])
    states = {s.time: json.loads(s.controller.read_text(encoding="utf-8")) for s in (early, late)}
    stations = ["cs1", "cs2"]

    def held(t: float) -> list[int]:
        """Vehicles queued and charging at each station in the snapshot at ``t``."""
        lists = states[t]["stations"]
        return [len(lists[sid]["queue"]) + len(lists[sid]["charging"]) for sid in stations]

    assert set(states[7200.0]["stations"]) == set(stations)
    timeline = OccupancyTimeline.from_records(states[7200.0]["records"], stations, known_until=7200.0)
    assert sum(held(3600.0)) > 0  # the day's EVs are at the stations by then
    assert timeline.at(3600.0).tolist() == held(3600.0)
    assert timeline.at(7200.0).tolist() == held(7200.0)
    for t in (3600.0, 7200.0):  # the sessions in progress are the vehicles on a charging point then
        charging = [len(states[t]["stations"][sid]["charging"]) for sid in stations]
        assert [x.size for x in timeline.charging_since(t)] == charging
    assert timeline.charge_durations().size > 0 and (timeline.charge_durations() > 0).all()
    forecast = OracleForecaster(timeline).forecast(1800.0, [3600.0, 3600.0], timeline.truncated(1800.0))
    assert forecast.dtype == np.float64 and forecast.tolist() == held(3600.0)
