"""D, N and Z against independent computations, on a hand-built day with known queues."""

from __future__ import annotations

import numpy as np
import pytest
import sumolib

from evcd.env import TARGET_ID
from tests.env.handmade import TO_CS1, TO_CS2, car, ev

LOOPS = [  # through traffic over the grid while the target drives
    "A0A1 A1A2 A2B2 B2C2 C2D2 D2D3",
    "D0C0 C0C1 C1B1 B1A1 A1A2 A2A3",
    "A3B3 B3C3 C3C2 C2C1 C1C0 C0D0",
    "B0B1 B1B2 B2B3 B3C3 C3D3",
    "D3D2 D2D1 D1C1 C1B1 B1A1",
]


def busy_day() -> list[str]:
    """cs1 (2 points): 1 EV charging. cs2 (1 point): 1 charging + 2 waiting, all held. Cars driving."""
    vehicles = [
        ev("q1", 0, TO_CS2, "pa_cs2", hold=True),
        ev("c1", 2, TO_CS1, "pa_cs1", hold=True),
        ev("q2", 5, TO_CS2, "pa_cs2", hold=True),
        ev("q3", 10, TO_CS2, "pa_cs2", hold=True),
    ]
    vehicles += [car(f"loop{i}", 150 + 7 * i, LOOPS[i % len(LOOPS)]) for i in range(25)]
    return vehicles


def independent_view(api, stations, net: sumolib.net.Net):
    """D, N, Z and routes computed here, not by the environment."""
    road, pos = api.vehicle.getRoadID(TARGET_ID), api.vehicle.getLanePosition(TARGET_ID)
    on_road = {}  # vehicle -> edge, for every vehicle on a road (not parked off-road), target excluded
    for v in api.vehicle.getIDList():
        if v != TARGET_ID and not api.vehicle.isStoppedParking(v):
            on_road[v] = api.vehicle.getRoadID(v)
    d, n, z, routes, d_sumolib = [], [], [], [], []
    for st in stations:
        z.append(api.parkingarea.getVehicleCount(st.parking_area))
        if TARGET_ID in api.parkingarea.getVehicleIDs(st.parking_area):  # it is there
            d.append(0.0)
            routes.append(())
            n.append(0)
            d_sumolib.append(None)
            continue
        stage = api.simulation.findRoute(road, st.edge, vType="ev")
        tail = api.lane.getLength(st.lane) - st.end_pos
        d.append(stage.length - pos - tail)
        routes.append(tuple(stage.edges))
        n.append(sum(1 for e in on_road.values() if e in stage.edges))
        if road.startswith(":"):
            d_sumolib.append(None)
        else:
            path, cost = net.getShortestPath(net.getEdge(road), net.getEdge(st.edge))
            d_sumolib.append((cost - pos - tail, len(path)))
    return np.array(d), np.array(n), np.array(z), routes, d_sumolib


def test_d_n_z_match_independent_computations(make_small_env, small_scenario):
    env = make_small_env(busy_day(), decision_interval=10)
    net = sumolib.net.readNet(str(small_scenario.net_file))
    obs, info = env.reset(seed=0, options={"departure": 200, "origin": "A3B3"})
    api = env.simulation.api
    stations = env.stations
    assert info["departure"] == 200
    seen_traffic = 0
    for step in range(12):
        d, n, z, routes, d_sumolib = independent_view(api, stations, net)
        np.testing.assert_allclose(obs[:2], d, rtol=1e-6)
        np.testing.assert_array_equal(obs[2:4], n)
        np.testing.assert_array_equal(obs[4:], z)
        assert env.last_observation.routes == tuple(routes)
        for sumolib_d, dv in zip(d_sumolib, d, strict=True):  # sumolib leaves junctions out
            if sumolib_d is not None:
                ds, hops = sumolib_d
                assert ds <= dv + 1e-6 and dv - ds < 20.0 * hops
        if step == 0:
            np.testing.assert_array_equal(z, [1, 3])  # the hand-built queues
        seen_traffic += int(n.sum())
        obs, _, terminated, truncated, _ = env.step(1)
        assert not truncated
        if terminated:
            break
        if env.simulation.controller.status(TARGET_ID) is None:  # still driving the measured route:
            cs2 = stations[1]  # SUMO's own distance along the target's route agrees
            along = api.vehicle.getDrivingDistance(TARGET_ID, cs2.edge, cs2.end_pos)
            assert obs[1] == pytest.approx(along, rel=1e-5)
    assert seen_traffic > 0  # N was tested with vehicles on the routes


def test_target_waiting_in_a_car_park(make_small_env):
    env = make_small_env(busy_day(), max_travel_time=1500)
    obs, _ = env.reset(seed=0, options={"departure": 100, "origin": "D2C2", "depart_pos": 20.0})
    for _ in range(10):
        obs, _, terminated, truncated, _ = env.step(1)  # into cs2's queue: its point is held
        assert not (terminated or truncated)
        if env.simulation.controller.status(TARGET_ID) == "waiting":
            break
    assert env.simulation.controller.status(TARGET_ID) == "waiting"
    assert obs[1] == 0.0  # it is at cs2
    assert obs[5] == 4  # and counts among the vehicles there
    assert obs[0] > 0  # cs1 is measured from the car park's edge


def test_loop_back_when_past_the_car_park(make_small_env):
    env = make_small_env(busy_day())
    obs, _ = env.reset(seed=0, options={"departure": 100, "origin": "B1C1", "depart_pos": 150.0})
    route = env.last_observation.routes[0]
    assert route[0] == route[-1] == "B1C1" and len(route) > 2  # round the block
    assert obs[0] > 185.6 - 150.0  # at least to the end of the edge and back
    _, _, terminated, truncated, info = env.step(0)
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(0)
    assert terminated and info["reason"] == "charging" and info["station_id"] == "cs1"


def test_calm_roads_keep_each_route_and_changing_roads_ask_sumo_anew(make_small_env):
    """A calm world keeps each route it found: SUMO plans with fixed weights, so the kept routes are
    the routes SUMO gives later on, with traffic on the roads. A world with road events keeps none:
    a slowed edge changes SUMO's route."""
    env = make_small_env(busy_day(), decision_interval=10)
    assert env.world.static_roads and env.observer.static_routes
    env.reset(seed=0, options={"departure": 200, "origin": "A3B3"})
    terminated = truncated = False
    for _ in range(6):
        if terminated or truncated:
            break
        _, _, terminated, truncated, _ = env.step(1)
    api, observer = env.simulation.api, env.observer
    kept = dict(observer._found)
    assert len(kept) >= 4 and api.vehicle.getIDCount() > 1
    for (src, dst), route in kept.items():
        assert observer._router(api, src, dst) == route
    (src, dst), (_, edges) = next((k, r) for k, r in kept.items() if len(r[1]) > 2)
    middle = next(e for e in edges[1:-1] if not e.startswith(":"))
    for i in range(api.edge.getLaneNumber(middle)):
        api.lane.setMaxSpeed(f"{middle}_{i}", 0.5)
    assert observer._router(api, src, dst)[1] != edges
    rain = {"rain": {"chance": 1.0, "speed_factor": 0.5, "start_window": [0, 60]}}
    wet = make_small_env([], perturbations=rain)
    assert not wet.world.static_roads and not wet.observer.static_routes
