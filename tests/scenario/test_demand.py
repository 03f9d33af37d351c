"""A day of demand: reproducible from a seed, shaped by the profile, EVs sent to the nearest station."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.scenario.demand import (
    CAR_TYPE,
    EV_TYPE,
    DemandConfig,
    demand_to_xml,
    generate_demand,
    write_demand,
)
from evcd.scenario.placement import place_stations
from evcd.scenario.routing import RoadGraph

SMALL = DemandConfig(cars_per_day=600, evs=200, charging_share=0.5, min_trip_m=500.0)


@pytest.fixture(scope="module")
def stations(grid_net):
    return place_stations(grid_net, 3, 700.0, np.random.default_rng(0))


def test_same_seed_same_day_other_seed_other_day(grid_net, stations, tmp_path):
    a = write_demand(generate_demand(grid_net, stations, SMALL, seed=7), tmp_path / "a.rou.xml.gz")
    b = write_demand(generate_demand(grid_net, stations, SMALL, seed=7), tmp_path / "b.rou.xml.gz")
    c = write_demand(generate_demand(grid_net, stations, SMALL, seed=8), tmp_path / "c.rou.xml.gz")
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()


def test_more_evs_only_adds_evs(grid_net, stations):
    """The 300-EV day is the 200-EV day plus 100 EVs: queues can only be compared this way."""
    from dataclasses import replace

    small = {t.id: t for t in generate_demand(grid_net, stations, SMALL, seed=5).trips}
    big = {t.id: t for t in generate_demand(grid_net, stations, replace(SMALL, evs=300), seed=5).trips}
    assert set(small) < set(big)
    assert all(big[k] == v for k, v in small.items())
    assert sum(1 for k in big if k.startswith("ev")) == 300


def test_counts_order_and_trip_length(grid_net, stations):
    demand = generate_demand(grid_net, stations, SMALL, seed=1)
    types = [t.type for t in demand.trips]
    assert types.count(CAR_TYPE) == 600 and types.count(EV_TYPE) == 200
    departs = [t.depart for t in demand.trips]
    assert departs == sorted(departs) and departs[0] >= 0 and departs[-1] < 86_400
    assert 60 <= len(demand.charging_trips) <= 140  # share 0.5 of 200, binomial spread
    assert all(t.type == EV_TYPE for t in demand.charging_trips)
    for t in demand.trips[:100]:
        a = np.asarray(grid_net.getEdge(t.origin).getShape()).mean(axis=0)
        b = np.asarray(grid_net.getEdge(t.destination).getShape()).mean(axis=0)
        assert np.hypot(*(a - b)) >= SMALL.min_trip_m


def test_departures_have_morning_and_evening_peaks(grid_net, stations):
    cfg = DemandConfig(cars_per_day=5000, evs=0, min_trip_m=0.0)
    hours = np.array([t.depart // 3600 for t in generate_demand(grid_net, stations, cfg, seed=2).trips])
    counts = np.bincount(hours.astype(int), minlength=24)
    night = counts[1:5].mean()
    assert counts[7:10].mean() > 5 * night
    assert counts[17:20].mean() > 5 * night
    assert counts[7:10].mean() > counts[11:15].mean()


def test_charging_evs_go_to_the_nearest_station_by_road(grid_net, stations):
    demand = generate_demand(grid_net, stations, SMALL, seed=3)
    by_lot = {s.parking_area: s for s in stations}
    for t in demand.charging_trips[:15]:
        origin = grid_net.getEdge(t.origin)
        costs = {}
        for s in stations:
            # independent: sumolib's router, origin start to the car park's middle
            _route, cost = grid_net.getShortestPath(origin, grid_net.getEdge(s.edge))
            costs[s.parking_area] = (
                cost - grid_net.getEdge(s.edge).getLength() + (s.start_pos + s.end_pos) / 2
            )
        assert costs[t.station] == pytest.approx(min(costs.values()))
        assert by_lot[t.station].edge in RoadGraph.from_net(grid_net)
        assert t.soc < t.target_soc


def test_route_file_carries_stop_and_battery(grid_net, stations):
    demand = generate_demand(grid_net, stations, SMALL, seed=4)
    xml = demand_to_xml(demand)
    charging = demand.charging_trips[0]
    assert f'parkingArea="{charging.station}"' in xml
    assert 'parking="true"' in xml
    assert "device.battery.chargeLevel" in xml and "evcd.targetSoc" in xml


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"evs": -1}, "evs=-1"),
        ({"cars_per_day": -5}, "cars_per_day=-5"),
        ({"charging_share": 1.5}, "charging_share=1.5"),
        ({"hourly_profile": (1.0,) * 23}, "hourly_profile"),
        ({"soc_charging": (0.5, 0.95)}, "soc_charging"),
    ],
)
def test_bad_config_is_a_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DemandConfig(**kwargs)


def test_station_off_the_network_is_a_clear_error(grid_net, stations):
    from dataclasses import replace

    bad = [replace(stations[0], lane="nowhere_0"), *stations[1:]]
    with pytest.raises(ValueError, match="nowhere"):
        generate_demand(grid_net, bad, SMALL, seed=0)
