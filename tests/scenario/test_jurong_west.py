"""The committed Jurong West scenario: five 100 kW stations, spaced by road, and a real window of its day."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.report.scenario import station_distance_matrix
from evcd.scenario.demand import DemandConfig, generate_demand, write_demand
from evcd.scenario.scenario import JURONG_WEST, load_scenario
from evcd.sim.day import simulate_day

pytestmark = pytest.mark.slow

#: Jurong Point mall (1 Jurong West Central 2), whose public car park hosts EV chargers.
JURONG_POINT = (103.7063, 1.3397)


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(JURONG_WEST)


def test_five_stations_of_100_kw(scenario):
    assert len(scenario.stations) == 5
    assert all(s.power_w == 100_000 and s.points == 2 for s in scenario.stations)
    assert all(s.lot_capacity > 10 * s.points for s in scenario.stations)


def test_every_pair_is_at_least_1_5_km_apart_by_road(scenario):
    d = station_distance_matrix(scenario)
    off = d[~np.eye(len(d), dtype=bool)]
    assert off.min() >= 1500.0, d.round()


def test_one_station_sits_at_jurong_point(scenario):
    net = scenario.net
    x, y = net.convertLonLat2XY(*JURONG_POINT)
    st = scenario.stations[0]
    shape = np.asarray(net.getLane(st.lane).getShape())
    assert "Jurong Point" in st.name
    assert np.min(np.hypot(shape[:, 0] - x, shape[:, 1] - y)) < 300.0


def test_a_morning_window_runs_with_queues_and_no_teleported_ev(scenario, tmp_path):
    cfg = DemandConfig(evs=400)
    demand = generate_demand(scenario.net, list(scenario.stations), cfg, seed=0)
    routes = write_demand(demand, tmp_path / "day.rou.xml.gz")
    day = simulate_day(scenario, routes, seed=0, begin=7 * 3600, end=7 * 3600 + 900, progress=False)
    t = day.traffic
    assert t.departed > 200 and t.arrived > 50
    assert max(t.running) > 100
    assert not [v for v in t.teleported_ids if v.startswith("ev")]
    arrived = [c for c in day.charges if c.station]
    assert arrived, "no EV reached a station in 15 peak minutes"
    assert all(c.start_time is None or c.start_time >= c.arrival_time for c in arrived)
