"""Network building: GraphML conversion, OSM import, SCC pruning, determinism, bad input.

The fast tests run the real netconvert on a hand-written GraphML and .osm of a few streets; the
tests marked ``slow`` check the committed Jurong West network (and rebuild it when the shared
GraphML is present).
"""

from __future__ import annotations

import gzip
import re
import subprocess
import sys
from collections import deque
from pathlib import Path

import numpy as np
import pytest
import sumolib

from evcd.scenario import network
from evcd.scenario.graphml import (
    RoadEdge,
    RoadNode,
    merge_signal_clusters,
    read_graphml,
    road_edges,
)
from evcd.scenario.netstats import network_summary
from evcd.scenario.network import (
    build_network,
    largest_strongly_connected,
    passenger_successors,
)
from evcd.scenario.plain_xml import write_plain_xml

REPO = Path(__file__).resolve().parents[2]
COMMITTED_NET = REPO / "sumo_net" / "jurong_west" / "net.net.xml.gz"
SHARED_GRAPHML = REPO.parent / "shared" / "data" / "jurong_west.graphml"

LON0, LAT0 = 103.70, 1.34
D = 0.002  # about 220 m

# id -> (lon, lat, highway tag of the node)
NODES = {
    "1": (LON0, LAT0, ""),
    "2": (LON0 + D, LAT0, "traffic_signals"),
    "3": (LON0 + D, LAT0 + D, ""),
    "4": (LON0, LAT0 + D, ""),
    "5": (LON0 + 1.5 * D, LAT0 + 1.5 * D, ""),  # end of the one-way spur
    "6": (LON0 + D, LAT0 - D, ""),  # end of a two-way dead-end street
    "7": (LON0 + 2 * D, LAT0, ""),
}


def edge(u: str, v: str, highway: str, oneway: bool, key: int = 0, **attrs: str) -> tuple:
    return (u, v, key, {"highway": highway, "oneway": str(oneway), "osmid": f"{u}{v}", **attrs})


def two_way(u: str, v: str, highway: str, **attrs: str) -> list[tuple]:
    return [edge(u, v, highway, False, **attrs), edge(v, u, highway, False, **attrs)]


EDGES = [
    # two-way primary, 4 lanes in total -> 2 per direction, 60 km/h
    *two_way("1", "2", "primary", lanes="4", maxspeed="60", name="Test Avenue"),
    # two-way secondary without lanes/maxspeed -> the secondary defaults
    *two_way("2", "3", "secondary"),
    # merged ways: lists -> max 3 lanes in total -> 2 per direction, max 50 km/h
    *two_way("3", "4", "residential", lanes="['3', '2']", maxspeed="['50', '40']"),
    # one-way tertiary, 3 lanes, 40 km/h, with a curved geometry
    edge(
        "4", "1", "tertiary", True, lanes="3", maxspeed="40",
        geometry=f"LINESTRING ({LON0} {LAT0 + D}, {LON0 - 0.0003} {LAT0 + D / 2}, {LON0} {LAT0})",
    ),
    # a two-way dead-end street: the turnaround at its end keeps it
    *two_way("2", "6", "residential", lanes="2"),
    # a two-way street to the east, and a service road beside it
    *two_way("2", "7", "tertiary", lanes="2"),
    *two_way("7", "3", "service"),
    # footway: dropped
    *two_way("2", "4", "footway"),
    # a one-way dead end: nothing leaves node 5, so the SCC pruning must drop it
    edge("3", "5", "residential", True, lanes="1"),
]  # fmt: skip

KEYS = ["highway", "oneway", "osmid", "lanes", "maxspeed", "name", "geometry", "length"]


def write_graphml(path: Path, nodes: dict = NODES, edges: list = EDGES) -> Path:
    """An OSMnx-style GraphML (namespaced, typed keys, multi-edge keys)."""
    lines = [
        "<?xml version='1.0' encoding='utf-8'?>",
        '<graphml xmlns="http://graphml.graphdrawing.org/xmlns">',
        '  <key id="d0" for="node" attr.name="y" attr.type="string" />',
        '  <key id="d1" for="node" attr.name="x" attr.type="string" />',
        '  <key id="d2" for="node" attr.name="highway" attr.type="string" />',
    ]
    lines += [
        f'  <key id="e{i}" for="edge" attr.name="{k}" attr.type="string" />' for i, k in enumerate(KEYS)
    ]
    lines.append('  <graph edgedefault="directed">')
    for nid, (lon, lat, hw) in nodes.items():
        data = f'<data key="d0">{lat}</data><data key="d1">{lon}</data>'
        if hw:
            data += f'<data key="d2">{hw}</data>'
        lines.append(f'    <node id="{nid}">{data}</node>')
    for u, v, key, attrs in edges:
        data = "".join(f'<data key="e{KEYS.index(k)}">{val}</data>' for k, val in attrs.items())
        lines.append(f'    <edge source="{u}" target="{v}" id="{key}">{data}</edge>')
    lines += ["  </graph>", "</graphml>"]
    path.write_text("\n".join(lines) + "\n")
    return path


OSM = """<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="hand">
  <node id="1" lat="1.3400" lon="103.7000"/>
  <node id="2" lat="1.3400" lon="103.7020"><tag k="highway" v="traffic_signals"/></node>
  <node id="3" lat="1.3400" lon="103.7040"/>
  <node id="4" lat="1.3420" lon="103.7020"/>
  <node id="5" lat="1.3380" lon="103.7020"/>
  <node id="6" lat="1.3420" lon="103.7040"/>
  <node id="7" lat="1.3430" lon="103.7000"/>
  <node id="8" lat="1.3410" lon="103.7000"/>
  <way id="100"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="primary"/>
    <tag k="lanes" v="4"/><tag k="maxspeed" v="60"/></way>
  <way id="101"><nd ref="5"/><nd ref="2"/><nd ref="4"/><tag k="highway" v="residential"/></way>
  <way id="102"><nd ref="4"/><nd ref="6"/><nd ref="3"/><tag k="highway" v="tertiary"/></way>
  <way id="103"><nd ref="1"/><nd ref="5"/><tag k="highway" v="residential"/></way>
  <way id="104"><nd ref="2"/><nd ref="7"/><tag k="highway" v="footway"/></way>
  <way id="105"><nd ref="4"/><nd ref="8"/><tag k="highway" v="residential"/><tag k="oneway" v="yes"/></way>
  <way id="106"><nd ref="6"/><nd ref="7"/><tag k="highway" v="service"/></way>
</osm>
"""


def strongly_connected(net: sumolib.net.Net) -> bool:
    """Naive check, independent of the builder: BFS forward and backward from one edge reach all."""
    succ = passenger_successors(net)
    pred: dict[str, list[str]] = {e: [] for e in succ}
    for e, outs in succ.items():
        for o in outs:
            pred[o].append(e)

    def reach(start: str, graph: dict[str, list[str]]) -> set[str]:
        seen, todo = {start}, deque([start])
        while todo:
            for nxt in graph[todo.popleft()]:
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    start = min(succ)
    return reach(start, succ) == set(succ) == reach(start, pred)


@pytest.fixture(scope="module")
def tiny_graphml(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_graphml(tmp_path_factory.mktemp("graphml") / "tiny.graphml")


@pytest.fixture(scope="module")
def tiny_net_file(tiny_graphml: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_network(tmp_path_factory.mktemp("net"), graphml=tiny_graphml)


@pytest.fixture(scope="module")
def tiny_net(tiny_net_file: Path) -> sumolib.net.Net:
    return sumolib.net.readNet(str(tiny_net_file))


# ---------------------------------------------------------------- GraphML -> SUMO network


def test_network_is_lefthand_and_geo_referenced(tiny_net_file, tiny_net):
    summary = network_summary(tiny_net_file)
    assert summary["lefthand"] is True
    assert tiny_net.hasGeoProj()
    # all junctions within the input's few hundred metres (a broken offset would put some km away)
    xmin, ymin, xmax, ymax = summary["bounds"]
    assert xmax - xmin < 1000 and ymax - ymin < 1000
    assert summary["geo_bounds"] == pytest.approx([LON0 - 0.0003, LAT0 - D, LON0 + 2 * D, LAT0 + 1.5 * D])


def test_lanes_and_speeds_follow_osm_and_defaults(tiny_net):
    def lanes_speed(edge_id: str) -> tuple[int, float]:
        e = tiny_net.getEdge(edge_id)
        return e.getLaneNumber(), round(e.getSpeed() * 3.6)

    assert lanes_speed("1_2_0") == (2, 60)  # two-way, 4 in total
    assert lanes_speed("2_1_0") == (2, 60)
    assert lanes_speed("2_3_0") == (2, 60)  # secondary defaults
    assert lanes_speed("3_4_0") == (2, 50)  # lists: max 3 in total, max 50 km/h
    assert lanes_speed("4_1_0") == (3, 40)  # one-way: the OSM value
    assert lanes_speed("7_3_0") == (1, 20)  # service defaults
    assert tiny_net.getEdge("1_2_0").getType() == "highway.primary"


def test_footway_and_spur_are_removed_dead_end_street_kept(tiny_net):
    ids = {e.getID() for e in tiny_net.getEdges()}
    assert not any(i.startswith(("2_4_", "4_2_")) for i in ids)  # footway
    assert "3_5_0" not in ids  # one-way dead end
    assert {"2_6_0", "6_2_0"} <= ids  # two-way dead end: turnaround
    assert {"7_3_0", "3_7_0"} <= ids  # service road kept by default


def test_every_edge_reaches_every_other_edge(tiny_net):
    assert strongly_connected(tiny_net)


def test_signal_node_becomes_traffic_light(tiny_net):
    assert [tls.getID() for tls in tiny_net.getTrafficLights()] == ["2"]


def test_edge_geometry_is_kept(tiny_net):
    # the one-way 4 -> 1 bends about 33 m west of the straight line
    xs = [x for x, _ in tiny_net.getEdge("4_1_0").getShape()]
    x_node = tiny_net.getNode("1").getCoord()[0]
    assert min(xs) < x_node - 25


def test_building_twice_gives_identical_bytes(tiny_graphml, tiny_net_file, tmp_path):
    again = build_network(tmp_path / "again", graphml=tiny_graphml)
    assert again.read_bytes() == tiny_net_file.read_bytes()
    assert b"generated on" not in gzip.decompress(again.read_bytes())


def test_without_service_roads(tiny_graphml, tmp_path):
    net = sumolib.net.readNet(str(build_network(tmp_path, graphml=tiny_graphml, include_service=False)))
    assert not any(e.getType() == "highway.service" for e in net.getEdges())
    assert strongly_connected(net)


# ---------------------------------------------------------------- conversion rules (no netconvert)


def test_road_edges_rules(tiny_graphml):
    edges = {e.id: e for e in road_edges(read_graphml(tiny_graphml))}
    assert "2_4_0" not in edges
    assert edges["3_4_0"].lanes == 2 and edges["3_4_0"].speed == pytest.approx(50 / 3.6)
    assert edges["4_1_0"].shape[1] == pytest.approx((LON0 - 0.0003, LAT0 + D / 2))
    assert edges["1_2_0"].name == "Test Avenue" and edges["1_2_0"].osmid == "12"
    assert edges["1_2_0"].length == pytest.approx(222.6, abs=0.5)  # haversine, no OSMnx length
    assert list(edges) == sorted(edges)
    without = {e.id for e in road_edges(read_graphml(tiny_graphml), include_service=False)}
    assert "7_3_0" not in without and "1_2_0" in without


def test_plain_xml_is_deterministic(tiny_graphml, tmp_path):
    a = write_plain_xml(tiny_graphml, tmp_path / "a")
    b = write_plain_xml(tiny_graphml, tmp_path / "b")
    assert [p.read_bytes() for p in a] == [p.read_bytes() for p in b]


def test_signal_clusters_are_merged():
    # a dual-carriageway crossing: four signalised nodes 10 m apart, one plain node far away
    step = 10 / 111_320
    nodes = [
        RoadNode("a", LON0, LAT0, True),
        RoadNode("b", LON0 + step, LAT0, True),
        RoadNode("c", LON0 + step, LAT0 + step, True),
        RoadNode("d", LON0, LAT0 + step, True),
        RoadNode("far", LON0 + 0.01, LAT0, False),
    ]

    def e(u: str, v: str, length: float) -> RoadEdge:
        return RoadEdge(f"{u}_{v}_0", u, v, "primary", 2, 16.7, True, "", "", length, ())

    edges = [e("a", "b", 10), e("b", "c", 10), e("c", "d", 10), e("d", "a", 10), e("far", "a", 1000)]
    edges.append(RoadEdge("b_far_0", "b", "far", "primary", 2, 16.7, True, "", "", 1000, ((0, 0), (1, 1))))
    new_nodes, new_edges = merge_signal_clusters(nodes, edges)
    assert [n.id for n in new_nodes] == ["cluster_a_b_c_d", "far"]
    assert new_nodes[0].signals and new_nodes[0].lon == pytest.approx(LON0 + step / 2)
    assert [(x.id, x.from_node, x.to_node) for x in new_edges] == [
        ("far_a_0", "far", "cluster_a_b_c_d"),
        ("b_far_0", "cluster_a_b_c_d", "far"),
    ]
    assert new_edges[1].shape[0] == (new_nodes[0].lon, new_nodes[0].lat)
    # nodes farther apart than the threshold stay apart
    assert merge_signal_clusters(nodes, edges, max_length=5) == (nodes, edges)


# ---------------------------------------------------------------- strongly connected components


def naive_largest_scc(succ: dict[str, list[str]]) -> set[str]:
    def reach(start: str) -> set[str]:
        seen, todo = {start}, [start]
        while todo:
            for nxt in succ[todo.pop()]:
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    reach_of = {n: reach(n) for n in succ}
    comps = {frozenset(m for m in reach_of[n] if n in reach_of[m]) for n in succ}
    return set(min(comps, key=lambda c: (-len(c), min(c))))


@pytest.mark.parametrize("seed", range(40))
def test_scc_matches_naive(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    p = float(rng.uniform(0.01, 0.15))
    names = [f"e{i:02d}" for i in range(n)]
    succ = {a: [b for b in names if rng.random() < p] for a in names}
    assert largest_strongly_connected(succ) == naive_largest_scc(succ)


def test_scc_deep_chain_does_not_recurse():
    n = 20_000  # far beyond Python's recursion limit
    succ = {f"{i:05d}": [f"{(i + 1) % n:05d}"] for i in range(n)}
    assert len(largest_strongly_connected(succ)) == n


# ---------------------------------------------------------------- OSM extract


def test_osm_extract(tmp_path):
    osm = tmp_path / "town.osm"
    osm.write_text(OSM)
    net_file = build_network(tmp_path / "out", osm=osm)
    net = sumolib.net.readNet(str(net_file))
    assert network_summary(net_file)["lefthand"] is True
    assert all(e.allows("passenger") for e in net.getEdges())
    ids = {e.getID().lstrip("-").split("#")[0] for e in net.getEdges()}
    assert "104" not in ids and "105" not in ids  # footway, one-way dead end
    assert "106" in ids  # service road, reopened to cars
    assert strongly_connected(net)
    assert [t.getID() for t in net.getTrafficLights()] == ["2"]
    assert build_network(tmp_path / "again", osm=osm).read_bytes() == net_file.read_bytes()
    without = sumolib.net.readNet(str(build_network(tmp_path / "no_service", osm=osm, include_service=False)))
    assert "106" not in {e.getID().lstrip("-").split("#")[0] for e in without.getEdges()}


# ---------------------------------------------------------------- bad input, before netconvert


@pytest.fixture
def no_netconvert(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("netconvert must not run on bad input")

    monkeypatch.setattr(network, "run_tool", fail)


def test_missing_file(tmp_path, no_netconvert):
    missing = tmp_path / "nope.graphml"
    with pytest.raises(FileNotFoundError, match=re.escape(str(missing))):
        build_network(tmp_path, graphml=missing)
    with pytest.raises(FileNotFoundError, match=r"nope\.osm"):
        build_network(tmp_path, osm=tmp_path / "nope.osm")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("<graphml><graph>", "malformed XML"),
        ("<osm></osm>", "not a GraphML"),
        ('<graphml xmlns="http://graphml.graphdrawing.org/xmlns"></graphml>', "without a <graph>"),
        ("", "malformed XML"),
    ],
)
def test_malformed_graphml(tmp_path, no_netconvert, text, match):
    bad = tmp_path / "bad.graphml"
    bad.write_text(text)
    with pytest.raises(ValueError, match=match) as err:
        build_network(tmp_path / "out", graphml=bad)
    assert "bad.graphml" in str(err.value)


def test_graphml_without_edges_or_roads(tmp_path, no_netconvert):
    with pytest.raises(ValueError, match="no edges"):
        build_network(tmp_path, graphml=write_graphml(tmp_path / "nodes.graphml", edges=[]))
    with pytest.raises(ValueError, match="no nodes"):
        build_network(tmp_path, graphml=write_graphml(tmp_path / "empty.graphml", nodes={}, edges=[]))
    unknown = [edge("1", "99", "primary", True)]
    with pytest.raises(ValueError, match="unknown node '99'"):
        build_network(tmp_path, graphml=write_graphml(tmp_path / "dangling.graphml", edges=unknown))
    footways = two_way("1", "2", "footway")
    with pytest.raises(ValueError, match="no passenger-road edges"):
        build_network(tmp_path, graphml=write_graphml(tmp_path / "foot.graphml", edges=footways))


def test_node_without_coordinates(tmp_path, no_netconvert):
    nodes = dict(NODES, bad=("x", LAT0, ""))
    with pytest.raises(ValueError, match="node 'bad'"):
        build_network(tmp_path, graphml=write_graphml(tmp_path / "coords.graphml", nodes=nodes))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("<osm><node", "malformed XML"),
        ("<graphml/>", "not an OSM"),
        ("<osm><node id='1'/></osm>", "no <way>"),
    ],
)
def test_malformed_osm(tmp_path, no_netconvert, text, match):
    bad = tmp_path / "bad.osm"
    bad.write_text(text)
    with pytest.raises(ValueError, match=match):
        build_network(tmp_path / "out", osm=bad)


def test_both_or_neither_source(tmp_path, tiny_graphml, no_netconvert):
    with pytest.raises(ValueError, match="both"):
        build_network(tmp_path, graphml=tiny_graphml, osm=tiny_graphml)
    with pytest.raises(ValueError, match="neither"):
        build_network(tmp_path)


def test_network_summary_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope"):
        network_summary(tmp_path / "nope.net.xml")
    other = tmp_path / "other.xml"
    other.write_text("<routes/>")
    with pytest.raises(ValueError, match="not a SUMO network"):
        network_summary(other)


# ---------------------------------------------------------------- the command line


def run_script(*args: str) -> subprocess.CompletedProcess:
    script = REPO / "scripts" / "build_network.py"
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, timeout=120)


def test_script_builds_and_summarises(tiny_graphml, tmp_path):
    proc = run_script("--graphml", str(tiny_graphml), "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    assert "junctions" in last and "lane-km" in last and "traffic lights" in last and "left-hand" in last
    assert (tmp_path / "net.net.xml.gz").is_file()


@pytest.mark.slow
def test_script_refuses_to_replace_a_scenario_network_without_force(tiny_graphml, tmp_path):
    scenario = tmp_path / "scenario"
    assert run_script("--graphml", str(tiny_graphml), "--out", str(scenario)).returncode == 0
    net = scenario / "net.net.xml.gz"  # the network a stations file was placed on
    (scenario / "stations.add.xml").write_text("<additional/>")
    before = net.stat().st_mtime_ns, net.read_bytes()
    proc = run_script("--graphml", str(tiny_graphml), "--no-service", "--out", str(scenario))
    assert proc.returncode == 2 and "already holds a network" in proc.stdout and "--force" in proc.stdout
    assert (net.stat().st_mtime_ns, net.read_bytes()) == before
    forced = run_script("--graphml", str(tiny_graphml), "--no-service", "--out", str(scenario), "--force")
    assert forced.returncode == 0 and net.read_bytes() != before[1]


def test_script_bad_input_is_exit_2_without_traceback(tmp_path):
    proc = run_script("--graphml", str(tmp_path / "missing.graphml"), "--out", str(tmp_path))
    assert proc.returncode == 2
    assert "missing.graphml" in proc.stdout and "Traceback" not in proc.stdout + proc.stderr


# ---------------------------------------------------------------- the committed Jurong West network


@pytest.fixture(scope="module")
def jurong_west() -> sumolib.net.Net:
    return sumolib.net.readNet(str(COMMITTED_NET))


@pytest.mark.slow
def test_committed_network_size_and_side():
    summary = network_summary(COMMITTED_NET)
    assert summary["junctions"] >= 500
    assert summary["lefthand"] is True
    assert summary["traffic_lights"] > 50
    xmin, ymin, xmax, ymax = summary["bounds"]
    assert 4000 < xmax - xmin < 8000 and 3000 < ymax - ymin < 6000  # Jurong West is ~6 x 4 km


@pytest.mark.slow
def test_committed_network_is_strongly_connected(jurong_west):
    assert strongly_connected(jurong_west)


@pytest.mark.slow
def test_rebuild_is_identical(tmp_path):
    if not SHARED_GRAPHML.is_file():
        pytest.skip(f"{SHARED_GRAPHML} not present")
    rebuilt = build_network(tmp_path, graphml=SHARED_GRAPHML)
    assert rebuilt.read_bytes() == COMMITTED_NET.read_bytes()
