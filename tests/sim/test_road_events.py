"""Incidents, rain and road works (:mod:`evcd.sim.road_events`, :mod:`evcd.sim.road_player`) against
real SUMO on small networks built in the test: what each does to the traffic, that a loaded state
gets the roads of its time, and bad input."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest
import sumolib

from evcd.sim.driver import SUMO_ERRORS, SumoDriver
from evcd.sim.road_events import Incident, Rain, RoadEvents, RoadWork, check_road_events, closable_lanes
from evcd.sim.road_player import RoadPlayer, attach
from evcd.utils.sumo_tools import run_tool

FREE = 13.89  # m/s, every edge's speed limit


@pytest.fixture(scope="module")
def line_net(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three 1-lane edges in a row, 500 m each: ``a`` then ``b`` then ``c``, the only route."""
    root = tmp_path_factory.mktemp("line")
    (root / "n.nod.xml").write_text(
        '<nodes><node id="0" x="0" y="0"/><node id="1" x="500" y="0"/>'
        '<node id="2" x="1000" y="0"/><node id="3" x="1500" y="0"/></nodes>'
    )
    (root / "e.edg.xml").write_text(
        "<edges>"
        + "".join(
            f'<edge id="{e}" from="{i}" to="{i + 1}" numLanes="1" speed="{FREE}"/>'
            for i, e in enumerate("abc")
        )
        + "</edges>"
    )
    net = root / "line.net.xml"
    run_tool(
        "netconvert", ["-n", root / "n.nod.xml", "-e", root / "e.edg.xml", "-o", net, "--no-turnarounds"]
    )
    return net


@pytest.fixture(scope="module")
def grid_net(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 x 3 grid of 2-lane streets, 400 m long: many ways from one side to the other. netgenerate
    turns right into a street's kerb lane only, so no lane of its grid can close without cutting a
    turn in; here the right turn from B1A1 enters both lanes of A1A2, whose kerb lane may close."""
    root = tmp_path_factory.mktemp("grid")
    run_tool(
        "netgenerate",
        ["--grid", "--grid.number", 3, "--grid.length", 400, "--default.lanenumber", 2,
         "--default.speed", FREE, "-o", root / "plain.net.xml"],
    )  # fmt: skip
    (root / "turn.con.xml").write_text(
        '<connections><connection from="B1A1" to="A1A2" fromLane="0" toLane="1"/></connections>'
    )
    net = root / "grid.net.xml"
    run_tool("netconvert", ["-s", root / "plain.net.xml", "-x", root / "turn.con.xml", "-o", net])
    return net


def _net(path: Path) -> sumolib.net.Net:
    return sumolib.net.readNet(str(path))


def _flow(path: Path, src: str, dst: str, period: float, end: float = 1500.0) -> Path:
    path.write_text(
        '<routes><vType id="car" accel="2.6" decel="4.5" sigma="0" speedDev="0"/>'
        f'<flow id="f" type="car" begin="0" end="{end}" period="{period}" from="{src}" to="{dst}" '
        'departSpeed="max"/></routes>'
    )
    return path


def _run(net: Path, routes: Path, events: RoadEvents, until: float = 4000.0, probe=None) -> dict:
    """Run the demand to its end with ``events`` played; per vehicle: departure and arrival, the
    edges it drove; plus the player and the mean speed of the moving traffic."""
    depart: dict[str, float] = {}
    arrive: dict[str, float] = {}
    speeds: list[float] = []
    with SumoDriver(net, (), [routes], seed=0, warnings=False) as driver:
        player = attach(driver, events)
        api = driver.api
        while api.simulation.getMinExpectedNumber() > 0 and driver.time < until:
            driver.step()
            now = driver.time
            depart.update({v: now for v in api.simulation.getDepartedIDList()})
            arrive.update({v: now for v in api.simulation.getArrivedIDList()})
            ids = api.vehicle.getIDList()
            if ids and int(now) % 10 == 0:
                speeds.append(statistics.mean(api.vehicle.getSpeed(v) for v in ids))
            if probe is not None:
                probe(api, now)
        teleports = api.simulation.getStartingTeleportNumber()
    return {
        "depart": depart,
        "arrive": arrive,
        "player": player,
        "speed": statistics.mean(speeds),
        "tp": teleports,
    }


def test_an_incident_on_the_only_route_slows_those_who_cross_it_by_the_crawl(line_net, tmp_path):
    """One vehicle a minute on the only route; an incident on ``b`` from 300 to 1200 s with a pass
    speed of 10 km/h: the vehicles reaching ``b`` during it take ~500 m / 2.78 m/s instead of
    500 / 13.89 (36 s), i.e. ~144 s longer; those before and after are not delayed."""
    routes = _flow(tmp_path / "r.rou.xml", "a", "c", period=60.0)
    calm = _run(line_net, routes, RoadEvents())
    inc = Incident("b", 300.0, 1200.0, pass_speed=10 / 3.6)
    hit = _run(line_net, routes, RoadEvents(incidents=(inc,)))
    assert sorted(hit["arrive"]) == sorted(calm["arrive"]) and hit["tp"] == 0
    extra = 500.0 / inc.pass_speed - 500.0 / FREE
    delays = {
        v: (hit["arrive"][v] - hit["depart"][v]) - (calm["arrive"][v] - calm["depart"][v])
        for v in calm["arrive"]
    }
    reach_b = {v: calm["depart"][v] + 500.0 / FREE for v in calm["arrive"]}  # when each reaches b, calm
    during = [v for v in delays if inc.start + 5 < reach_b[v] < inc.end - extra]
    outside = [v for v in delays if reach_b[v] < inc.start - 40 or reach_b[v] > inc.end + 40]
    assert len(during) >= 10 and len(outside) >= 5
    for v in during:
        assert delays[v] == pytest.approx(extra, rel=0.15), v
    assert all(abs(delays[v]) <= 2.0 for v in outside)


def test_vehicles_with_an_alternative_go_around_an_incident(grid_net, tmp_path):
    """A flow whose shortest way crosses B1C1; with an incident there (passed at 5 km/h) the
    vehicles routed through it are rerouted, none of those departing during
    the incident crosses it, and they arrive sooner than by crawling through."""
    routes = _flow(tmp_path / "r.rou.xml", "A1B1", "C1C2", period=10.0)
    crossed: dict[str, set[str]] = {"B1C1": set()}

    def probe(api, now):
        if 400 <= now < 1200:
            crossed["B1C1"].update(api.edge.getLastStepVehicleIDs("B1C1"))

    calm = _run(grid_net, routes, RoadEvents())
    inc = RoadEvents(incidents=(Incident("B1C1", 300.0, 1200.0, pass_speed=5 / 3.6),))
    hit = _run(grid_net, routes, inc, probe=probe)
    assert hit["player"].reroutes >= 1 and hit["tp"] == 0
    departed_during = {v for v, t in hit["depart"].items() if 400 <= t < 1100}
    assert departed_during and not (crossed["B1C1"] & departed_during)
    tt = [hit["arrive"][v] - hit["depart"][v] for v in departed_during]
    crawl = 400.0 / (5 / 3.6) - 400.0 / FREE  # what crossing would have cost on top of the calm trip
    calm_tt = statistics.mean(calm["arrive"][v] - calm["depart"][v] for v in departed_during)
    assert statistics.mean(tt) < calm_tt + crawl / 2


def test_closed_lanes_carry_nobody_and_road_works_cap_the_speed(grid_net, tmp_path):
    """Road works on A1A2 with its kerb lane closed (lane 1 makes every turn out of it lane 0 makes,
    and every turn into it enters lane 1 too): nobody drives lane 0, nobody drives faster than the
    works' limit, nobody is stranded."""
    routes = _flow(tmp_path / "r.rou.xml", "A0A1", "A2B2", period=3.0)
    seen = {"closed": 0, "fastest": 0.0}

    def probe(api, now):
        if 400 <= now < 1200:
            seen["closed"] += api.lane.getLastStepVehicleNumber("A1A2_0")
            seen["fastest"] = max(
                [seen["fastest"], *map(api.vehicle.getSpeed, api.edge.getLastStepVehicleIDs("A1A2"))]
            )

    works = check_road_events(RoadEvents(roadworks=(RoadWork("A1A2", 30 / 3.6, lanes=(0,)),)), _net(grid_net))
    run = _run(grid_net, routes, works, probe=probe)
    assert run["tp"] == 0 and seen["closed"] == 0 and len(run["arrive"]) == 500
    assert 0 < seen["fastest"] <= 30 / 3.6 + 0.01


def test_a_closure_keeps_every_turn_into_its_edge(grid_net, tmp_path):
    """Why :func:`closable_lanes` keeps the turns in: on netgenerate's grid the right turn from B1A1
    enters A1A2's kerb lane only; with that lane closed SUMO refuses a route through the turn
    ("No connection between edge 'B1A1' and edge 'A1A2'") while its router still offers it, so that
    closure is refused. Where the turn also enters lane 1 (``grid_net``), the lane may close and the
    same route is taken."""
    plain = grid_net.parent / "plain.net.xml"
    assert closable_lanes(_net(plain), "A1A2", 2) == () and closable_lanes(_net(grid_net), "A1A2", 2) == (0,)
    with pytest.raises(ValueError, match="cut a turn into or out of it"):
        check_road_events(RoadEvents(roadworks=(RoadWork("A1A2", lanes=(0,)),)), _net(plain))
    routes = tmp_path / "v.rou.xml"
    routes.write_text(
        '<routes><vType id="car" sigma="0"/><vehicle id="v" type="car" depart="200" departSpeed="max">'
        '<route edges="C1B1 B1A1 A1A0"/></vehicle></routes>'
    )
    through = ["C1B1", "B1A1", "A1A2", "A2B2"]
    incident = RoadEvents(incidents=(Incident("A1A2", 100.0, 400.0, lanes=(0,), pass_speed=5 / 3.6),))
    for net, refused in ((plain, True), (grid_net, False)):
        with SumoDriver(net, (), [routes], seed=0, warnings=False) as driver:
            attach(driver, incident)
            driver.step(until=205.0)
            api = driver.api
            assert api.vehicle.getRoadID("v") == "C1B1"
            assert list(api.simulation.findRoute("C1B1", "A2B2", "car").edges) == through
            if refused:
                with pytest.raises(SUMO_ERRORS, match="No connection between edge 'B1A1' and edge 'A1A2'"):
                    api.vehicle.setRoute("v", through)
            else:
                api.vehicle.setRoute("v", through)
                assert list(api.vehicle.getRoute("v")) == through


def test_rain_slows_the_mean_speed_by_about_its_factor(line_net, tmp_path):
    """Free-flowing traffic (one vehicle every 20 s) on the straight road: the mean speed falls by the
    speed factor, to within 3 %."""
    routes = _flow(tmp_path / "r.rou.xml", "a", "c", period=20.0)
    calm = _run(line_net, routes, RoadEvents())
    wet = _run(line_net, routes, RoadEvents(rain=(Rain(0.0, 5000.0, speed_factor=0.7, headway_factor=1.4),)))
    assert wet["speed"] / calm["speed"] == pytest.approx(0.7, abs=0.03)


def test_a_loaded_state_gets_the_roads_of_its_time(grid_net, tmp_path):
    """States saved during and after an incident and rain, loaded into a run that played neither
    (and one that played both): each lane's limit, permissions and the headway are those of the
    state's time, whatever the running simulation had."""
    routes = _flow(tmp_path / "r.rou.xml", "A1B1", "C1C2", period=10.0)
    events = RoadEvents(
        incidents=(Incident("A1A2", 300.0, 900.0, lanes=(0,), pass_speed=5 / 3.6),),
        rain=(Rain(200.0, 700.0, speed_factor=0.8, headway_factor=1.5),),
    )

    def look(api):
        return (
            api.lane.getMaxSpeed("A1A2_1"), api.lane.getMaxSpeed("A0A1_0"),
            "passenger" in api.lane.getAllowed("A1A2_0"), api.vehicletype.getTau("car"),
        )  # fmt: skip

    seen = {}
    with SumoDriver(grid_net, (), [routes], seed=0, warnings=False) as driver:
        attach(driver, events)
        for t in (500.0, 1000.0):
            driver.step(until=t)
            seen[t] = look(driver.api)
            driver.save_state(tmp_path / f"s{int(t)}.xml.gz")
    assert seen[500.0] == pytest.approx((5 / 3.6, 0.8 * FREE, False, 1.5))
    assert seen[1000.0] == pytest.approx((FREE, FREE, True, 1.0))
    with SumoDriver(grid_net, (), [routes], seed=0, warnings=False) as driver:
        player = RoadPlayer(events, driver.api)
        player.sync(driver.api, 0.0)
        for t in (500.0, 1000.0, 500.0):  # forward, then back to a time the incident and rain hold
            driver.load_state(tmp_path / f"s{int(t)}.xml.gz")
            player.sync(driver.api, driver.time)
            assert look(driver.api) == pytest.approx(seen[t]), t


def test_bad_road_events_are_refused_by_name(grid_net, line_net):
    grid, line = _net(grid_net), _net(line_net)
    with pytest.raises(ValueError, match="incident on edge 'x': no such drivable edge"):
        check_road_events(RoadEvents(incidents=(Incident("x", 0.0, 60.0),)), grid)
    with pytest.raises(ValueError, match=r"lanes=\[2\]; it has lanes 0-1"):
        check_road_events(RoadEvents(incidents=(Incident("A1A2", 0.0, 60.0, lanes=(2,)),)), grid)
    for net, edge, lanes in ((line, "a", (0,)), (grid, "A1A2", (0, 1)), (grid, "B1C1", (0,))):
        with pytest.raises(
            ValueError, match=r"road works on edge .* would leave no lane open to cars or cut a turn"
        ):
            check_road_events(RoadEvents(roadworks=(RoadWork(edge, lanes=lanes),)), net)
    assert closable_lanes(grid, "B1C1", 2) == () and closable_lanes(grid, "A1A2", 2) == (0,)
    with pytest.raises(ValueError, match=r"rain spells .* overlap"):
        check_road_events(RoadEvents(rain=(Rain(0.0, 100.0), Rain(50.0, 200.0))), grid)
    with pytest.raises(ValueError, match=r"start=60\.0, end=60\.0"):
        Incident("a", 60.0, 60.0)
    with pytest.raises(ValueError, match="speed_factor"):
        Rain(0.0, 10.0, speed_factor=1.5)
    with pytest.raises(ValueError, match="lanes=5 must be a list"):
        RoadWork("a", lanes=5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown kind 'snow'"):
        RoadEvents.from_dict({"snow": []})
    events = RoadEvents(incidents=(Incident("b", 0.0, 60.0, lanes=(1,)),), rain=(Rain(10.0, 20.0),))
    assert RoadEvents.from_dict(events.to_dict()) == events


def test_rain_headways_follow_types_made_during_it_and_skip_types_a_load_removed(line_net, tmp_path):
    """A type copied during rain (from a type whose headway the rain lengthened) gets its own back
    when the rain ends; a state loaded from before the copy, which lacks the copy, syncs without
    touching it (SUMO: 'Vehicle type ... is not known', met in the batched engine)."""
    routes = _flow(tmp_path / "r.rou.xml", "a", "c", period=60.0)
    events = RoadEvents(rain=(Rain(100.0, 200.0, headway_factor=1.5),))
    with SumoDriver(line_net, (), [routes], seed=0, warnings=False) as driver:
        player = attach(driver, events)
        api = driver.api
        driver.step(until=50.0)
        state = driver.save_state(tmp_path / "s50.xml.gz")
        driver.step(until=150.0)
        assert api.vehicletype.getTau("car") == pytest.approx(1.5)
        api.vehicletype.copy("car", "copy")
        driver.step(until=250.0)
        assert api.vehicletype.getTau("copy") == pytest.approx(1.0) and api.vehicletype.getTau("car") == 1.0
        driver.step(until=260.0)
        driver.load_state(state)
        assert player is not None
        player.sync(api, driver.time)  # 'copy' may be gone: no error
        assert api.vehicletype.getTau("car") == pytest.approx(1.0)
