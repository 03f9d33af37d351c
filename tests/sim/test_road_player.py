"""The road player's rerouting around an incident, on a real SUMO (8 x 8 grid)."""

from __future__ import annotations

import multiprocessing
from typing import Any

import libsumo
import pytest

from evcd.scenario.scenario import load_scenario
from evcd.sim.road_events import Incident, RoadEvents
from evcd.sim.road_player import RoadPlayer
from tests.conftest import make_grid_scenario

pytestmark = pytest.mark.slow  # every test here takes seconds


def _incident_with_a_stop_off_the_route(root: str) -> dict[str, Any]:
    """In a child process (a libsumo crash must not take pytest with it): vehicle ``off`` gets its
    stop moved off its route (``rerouteParkingArea`` from a junction keeps the old route, what a
    refused re-route of a fleet EV leaves behind), ``plain`` has no stop; then an incident closes an
    edge both still have to cross and the player's reroute round runs."""
    scenario = load_scenario(root)
    here, there = scenario.stations[0], scenario.stations[-1]
    net = scenario.net
    edge = net.getEdge(here.edge)
    src = next(e for e in edge.getFromNode().getIncoming() if e.getFromNode() != edge.getToNode())
    dst = next(e for e in edge.getToNode().getOutgoing() if e.getToNode() != edge.getFromNode())
    route = [src.getID(), here.edge, dst.getID()]
    libsumo.start([
        "sumo", "-n", str(scenario.net_file), "-a", f"{scenario.stations_file},{scenario.vtypes_file}",
        "--no-step-log", "--no-warnings", "--seed", "0",
    ])  # fmt: skip
    try:
        api = libsumo
        api.route.add("r", route)
        api.vehicle.add("off", "r")
        api.vehicle.setParkingAreaStop("off", here.parking_area, duration=60)
        api.vehicle.add("plain", "r", depart="1")
        while not api.vehicle.getRoadID("off").startswith(":"):
            api.simulationStep()
        api.vehicle.rerouteParkingArea("off", there.parking_area)
        stop_lane = api.vehicle.getStops("off", 1)[0].lane
        left = api.vehicle.getRoute("off")[api.vehicle.getRouteIndex("off") :]
        now = api.simulation.getTime()
        events = RoadEvents(incidents=(Incident(dst.getID(), now + 1.0, now + 600.0, (), 2.0),))
        player = RoadPlayer(events, api)
        player.sync(api, now)
        api.simulationStep()
        player(api, api.simulation.getTime())  # the incident starts: a reroute round
        return {
            "stop_off_route": stop_lane.rpartition("_")[0] not in left,
            "reroutes": player.reroutes,
            "skipped": player.skipped,
            "running": sorted(api.vehicle.getIDList()),
        }
    finally:
        libsumo.close()


def _in_child(send: Any, root: str) -> None:
    send.send(_incident_with_a_stop_off_the_route(root))
    send.close()


def test_a_vehicle_whose_next_stop_is_off_its_route_is_not_rerouted(tmp_path):
    """libsumo 1.28 crashes (segmentation fault) rerouting a vehicle whose next stop is off its route;
    the perturbed fleet met one (a refused re-route of a guided EV). The player leaves it alone and
    reroutes the others."""
    root = make_grid_scenario(tmp_path / "grid")
    ctx = multiprocessing.get_context("spawn")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_in_child, args=(send, str(root)))
    child.start()
    send.close()
    try:
        out = receive.recv() if receive.poll(120) else None
    except EOFError:  # the child died before it could answer
        out = None
    child.join(30)
    assert child.exitcode == 0, f"the child process died (exit code {child.exitcode}): libsumo crashed"
    assert out["stop_off_route"], "the setup did not leave the stop off the route (SUMO changed?)"
    assert out["skipped"] == 1 and out["reroutes"] == 1, out
    assert out["running"] == ["off", "plain"]
