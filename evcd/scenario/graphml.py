"""Read an OSMnx GraphML road graph into the roads SUMO will have (the plain XML is written by
:mod:`evcd.scenario.plain_xml`).

OSMnx writes a drive network as GraphML in EPSG:4326: nodes carry ``x`` (lon), ``y`` (lat) and
``highway`` (``traffic_signals`` at signalised intersections); edges carry ``osmid``, ``highway``,
``lanes``, ``maxspeed``, ``oneway``, ``name``, ``geometry`` (WKT ``LINESTRING (lon lat, ...)``) and
``length``. Where OSMnx merged several OSM ways into one edge, attributes become Python-list strings
such as ``"['3', '2']"``.

Conversion rules (the choices are ours; they are documented here because the network depends on them):

- **Road types kept**: the passenger road types in :data:`ROAD_TYPES` plus ``service`` roads
  (``include_service=True``, the default). In Jurong West the service roads (328 of 1,595 edges,
  but only 16 of 366 lane-km) are the aisles and driveways of the HDB car parks where the
  residents' cars stand, i.e. where most trips start and end; without them the network has 467
  junctions instead of 598 and every trip starts on a street. ``include_service=False`` drops them,
  as netconvert's OSM typemap does (it opens ``highway.service`` to delivery vehicles only). Edges
  tagged ``access=no``/``private`` are always dropped.
- **Lanes per direction**: a one-way edge gets the OSM ``lanes`` value. A two-way road is stored by
  OSMnx as two opposite edges that both carry the road's *total* lane count, so each direction gets
  ``ceil(total / 2)``. For a list value (merged ways) the maximum is taken: the merged ways form one
  road between two intersections, and its widest part is what the road was built for.
- **Speed**: OSM ``maxspeed`` in km/h (list: the maximum, as for lanes); unparsable values
  (``"signals"``, ``"none"``) count as missing.
- **Defaults**: a missing or unparsable value takes the road type's default in :data:`ROAD_TYPES`
  (Singapore: 50 km/h unless signed, expressways 90 km/h; lanes per direction on the low side of
  what the tagged roads of that type have in the April 2022 Jurong West data: 3 on primary, 2 on
  secondary/tertiary, 1 on residential, link and service roads, which hold 84% of the missing
  values). Priorities follow netconvert's OSM typemap so that GraphML and ``.osm`` imports give the same
  right of way.
- **Geometry**: the edge's ``geometry`` becomes its ``shape``; one-way edges (mostly one carriageway
  of a dual carriageway, drawn on its own centre line) are spread around the line (``center``),
  two-way edges lie on their side of the shared centre line (``right``, mirrored by ``--lefthand``).
- **Signalised clusters**: OSM tags every node of a large signalised intersection (one per
  carriageway crossing). Signalised nodes linked by a kept edge shorter than
  :data:`SIGNAL_JOIN_DIST` are merged here into one node ``cluster_<ids>`` at their centroid; the
  edges between them are dropped and the others re-attached (ids unchanged). netconvert's own
  ``--junctions.join`` refuses some of these clusters ("parallel incoming" edges), and the chain of
  tiny signalised junctions it leaves behind gridlocks under peak traffic. (Handing netconvert
  ``<join>`` elements instead is broken in 1.28 with ``--lefthand``: the joined junctions get
  y = -2^30 and the network's offset is wrong.)
- **Ids**: edge ``<u>_<v>_<key>`` (OSM node ids and the GraphML multi-edge key), node = OSM node id
  (``cluster_<ids>`` for a merged intersection).
  Output is sorted, so converting the same GraphML twice gives byte-identical files.

Coordinates are written as lon/lat; netconvert projects them (``--proj.utm``) and keeps the
geo-reference in the network's ``<location>``.
"""

from __future__ import annotations

import ast
import logging
import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass, replace
from itertools import pairwise
from pathlib import Path

from evcd.utils.xml_files import read_xml_root

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RoadType:
    """Defaults for one OSM ``highway`` value.

    Attributes:
        priority: SUMO edge priority (right of way at unsignalised junctions), as in netconvert's
            ``osmNetconvert.typ.xml``.
        lanes: lanes per direction when OSM gives none.
        speed_kmh: speed limit when OSM gives none.
    """

    priority: int
    lanes: int
    speed_kmh: float


#: Passenger road types kept by default and their defaults (see the module docstring).
ROAD_TYPES: dict[str, RoadType] = {
    "motorway": RoadType(14, 3, 90.0),
    "trunk": RoadType(13, 3, 70.0),
    "primary": RoadType(12, 3, 60.0),
    "secondary": RoadType(11, 2, 60.0),
    "tertiary": RoadType(10, 2, 50.0),
    "motorway_link": RoadType(9, 1, 50.0),
    "trunk_link": RoadType(8, 1, 50.0),
    "primary_link": RoadType(7, 1, 50.0),
    "secondary_link": RoadType(6, 1, 50.0),
    "tertiary_link": RoadType(5, 1, 50.0),
    "unclassified": RoadType(4, 1, 50.0),
    "residential": RoadType(3, 1, 50.0),
    "living_street": RoadType(2, 1, 20.0),
}
#: ``service`` roads, kept only with ``include_service=True``.
SERVICE_TYPE = RoadType(1, 1, 20.0)

#: signalised nodes closer than this along a road (m) are one intersection (see module docstring).
SIGNAL_JOIN_DIST = 20.0

_NO_ACCESS = {"no", "private"}
_EARTH_RADIUS = 6_371_008.8


@dataclass(frozen=True)
class RoadNode:
    """A GraphML node: OSM id, position (WGS84) and whether OSM marks it signalised."""

    id: str
    lon: float
    lat: float
    signals: bool


@dataclass(frozen=True)
class RoadEdge:
    """A directed road edge ready for SUMO.

    Attributes:
        id: ``<u>_<v>_<key>``.
        from_node, to_node: OSM node ids.
        highway: OSM road type (a key of :data:`ROAD_TYPES` or ``service``).
        lanes: lanes in this direction.
        speed: speed limit (m/s).
        oneway: the OSM way is one-way.
        name: street name ("" if none).
        osmid: OSM way id(s) as written in the GraphML.
        length: length along the geometry (m), from OSMnx's ``length``.
        shape: (lon, lat) points from ``from_node`` to ``to_node``; empty for a straight edge.
    """

    id: str
    from_node: str
    to_node: str
    highway: str
    lanes: int
    speed: float
    oneway: bool
    name: str
    osmid: str
    length: float
    shape: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class RoadGraph:
    """The raw content of a GraphML file: node and edge attribute dictionaries."""

    nodes: dict[str, dict[str, str]]
    edges: list[tuple[str, str, str, dict[str, str]]]


def read_graphml(path: str | Path) -> RoadGraph:
    """Parse an OSMnx GraphML file into attribute dictionaries.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: the file is not well-formed XML, not GraphML, has no nodes or edges, a node
            without valid ``x``/``y``, or an edge naming an unknown node. The message names the file.
    """
    path = Path(path)
    root = read_xml_root(path, "GraphML file")
    if _local(root.tag) != "graphml":
        raise ValueError(f"{path}: not a GraphML file (root element <{_local(root.tag)}>)")
    ns = root.tag[: root.tag.index("}") + 1] if root.tag.startswith("{") else ""
    keys = {k.get("id"): k.get("attr.name") for k in root.findall(f"{ns}key")}
    graph = root.find(f"{ns}graph")
    if graph is None:
        raise ValueError(f"{path}: GraphML without a <graph> element")

    def attrs(elem: ET.Element) -> dict[str, str]:
        return {keys.get(d.get("key"), d.get("key")): (d.text or "") for d in elem.findall(f"{ns}data")}

    nodes = {n.get("id"): attrs(n) for n in graph.findall(f"{ns}node")}
    edges = [
        (e.get("source"), e.get("target"), e.get("id") or "0", attrs(e)) for e in graph.findall(f"{ns}edge")
    ]
    if not nodes:
        raise ValueError(f"{path}: GraphML has no nodes")
    if not edges:
        raise ValueError(f"{path}: GraphML has no edges")
    for nid, a in nodes.items():
        try:
            float(a["x"]), float(a["y"])
        except (KeyError, ValueError) as err:
            raise ValueError(f"{path}: node {nid!r} lacks numeric x/y (lon/lat) attributes") from err
    for u, v, _, _ in edges:
        for end in (u, v):
            if end not in nodes:
                raise ValueError(f"{path}: edge {u}->{v} names unknown node {end!r}")
    return RoadGraph(nodes=nodes, edges=edges)


def road_edges(graph: RoadGraph, *, include_service: bool = True) -> list[RoadEdge]:
    """Select the passenger roads of ``graph`` and resolve lanes, speed and shape (sorted by id)."""
    types = dict(ROAD_TYPES)
    if include_service:
        types["service"] = SERVICE_TYPE
    out: list[RoadEdge] = []
    dropped = 0
    for u, v, key, a in graph.edges:
        highway = _pick_highway(a.get("highway", ""), types)
        if highway is None or a.get("access", "") in _NO_ACCESS:
            dropped += 1
            continue
        default = types[highway]
        oneway = a.get("oneway", "False").strip().lower() in {"true", "1", "yes"}
        total = _max_number(a.get("lanes"))
        if total is None or total < 1:
            lanes = default.lanes
        else:
            lanes = int(total) if oneway else math.ceil(total / 2)
        kmh = _max_number(a.get("maxspeed"))
        speed = (kmh if kmh and kmh > 0 else default.speed_kmh) / 3.6
        shape = _parse_linestring(a.get("geometry", ""))
        out.append(
            RoadEdge(
                id=f"{u}_{v}_{key}",
                from_node=u,
                to_node=v,
                highway=highway,
                lanes=max(1, lanes),
                speed=speed,
                oneway=oneway,
                name="; ".join(_as_list(a.get("name", ""))),
                osmid=a.get("osmid", ""),
                length=_edge_length(a, shape, graph.nodes[u], graph.nodes[v]),
                shape=shape,
            )
        )
    log.info("GraphML: kept %d passenger-road edges, dropped %d", len(out), dropped)
    return sorted(out, key=lambda e: e.id)


def signal_clusters(
    nodes: Iterable[RoadNode], edges: Iterable[RoadEdge], max_length: float = SIGNAL_JOIN_DIST
) -> list[list[str]]:
    """Groups of signalised nodes linked by edges shorter than ``max_length`` (sorted, size >= 2)."""
    signalised = {n.id for n in nodes if n.signals}
    parent = {nid: nid for nid in signalised}

    def find(x: str) -> str:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for e in edges:
        if e.from_node in signalised and e.to_node in signalised and e.length < max_length:
            a, b = sorted((find(e.from_node), find(e.to_node)))
            parent[b] = a
    groups: dict[str, list[str]] = {}
    for nid in sorted(signalised):
        groups.setdefault(find(nid), []).append(nid)
    return sorted(g for g in groups.values() if len(g) > 1)


def merge_signal_clusters(
    nodes: list[RoadNode], edges: list[RoadEdge], max_length: float = SIGNAL_JOIN_DIST
) -> tuple[list[RoadNode], list[RoadEdge]]:
    """Merge each :func:`signal_clusters` group into one signalised node at its centroid.

    Edges with both ends in one group are dropped; the others keep their id and are re-attached,
    with the shape's end point moved onto the merged node. Nodes come back sorted by id, edges in
    their input order.
    """
    by_id = {n.id: n for n in nodes}
    merged: dict[str, RoadNode] = {}
    for group in signal_clusters(nodes, edges, max_length):
        node = RoadNode(
            id="cluster_" + "_".join(group),
            lon=sum(by_id[g].lon for g in group) / len(group),
            lat=sum(by_id[g].lat for g in group) / len(group),
            signals=True,
        )
        merged.update((g, node) for g in group)
    if not merged:
        return nodes, edges
    out_edges = []
    for e in edges:
        u, v = merged.get(e.from_node), merged.get(e.to_node)
        if u is not None and u is v:
            continue  # inside the intersection
        shape = list(e.shape)
        if u is not None and shape:
            shape[0] = (u.lon, u.lat)
        if v is not None and shape:
            shape[-1] = (v.lon, v.lat)
        out_edges.append(
            replace(
                e, from_node=u.id if u else e.from_node, to_node=v.id if v else e.to_node, shape=tuple(shape)
            )
        )
    used = {e.from_node for e in out_edges} | {e.to_node for e in out_edges}
    out_nodes = {n.id: n for n in nodes if n.id not in merged} | {n.id: n for n in merged.values()}
    log.info(
        "merged %d signalised nodes into %d intersections, dropped %d edges inside them",
        len(merged),
        len(set(map(id, merged.values()))),
        len(edges) - len(out_edges),
    )
    return [out_nodes[k] for k in sorted(used)], out_edges


def road_node(nid: str, a: dict[str, str]) -> RoadNode:
    """The road node of GraphML node ``nid`` with attributes ``a``."""
    return RoadNode(nid, float(a["x"]), float(a["y"]), "traffic_signals" in _as_list(a.get("highway", "")))


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _as_list(text: str | None) -> list[str]:
    """``"a"`` -> ``["a"]``; ``"['a', 'b']"`` (OSMnx merged ways) -> ``["a", "b"]``; empty -> ``[]``."""
    text = (text or "").strip()
    if not text:
        return []
    if text.startswith("["):
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            return [text]
        return [str(v).strip() for v in value] if isinstance(value, list | tuple) else [str(value)]
    return [text]


def _max_number(text: str | None) -> float | None:
    """Largest number among the (list) values; OSM units such as ``"50 km/h"`` are tolerated."""
    numbers = []
    for item in _as_list(text):
        for token in item.replace(";", " ").split():
            try:
                numbers.append(float(token))
            except ValueError:
                continue
    return max(numbers) if numbers else None


def _pick_highway(text: str, types: dict[str, RoadType]) -> str | None:
    """The kept road type of an edge; for merged ways the most important kept type."""
    kept = [h for h in _as_list(text) if h in types]
    return max(kept, key=lambda h: types[h].priority) if kept else None


def _edge_length(
    a: dict[str, str], shape: tuple[tuple[float, float], ...], u: dict[str, str], v: dict[str, str]
) -> float:
    """OSMnx's ``length`` (m), else the great-circle length of the shape or the straight line."""
    given = _max_number(a.get("length"))
    if given is not None and given >= 0:
        return given
    points = shape or ((float(u["x"]), float(u["y"])), (float(v["x"]), float(v["y"])))
    return sum(_haversine(p, q) for p, q in pairwise(points))


def _haversine(p: tuple[float, float], q: tuple[float, float]) -> float:
    lon1, lat1, lon2, lat2 = map(math.radians, (*p, *q))
    h = math.sin((lat2 - lat1) / 2) ** 2 + math.cos(lat1) * math.cos(lat2) * math.sin((lon2 - lon1) / 2) ** 2
    return 2 * _EARTH_RADIUS * math.asin(math.sqrt(h))


def _parse_linestring(wkt: str) -> tuple[tuple[float, float], ...]:
    wkt = wkt.strip()
    if not wkt.upper().startswith("LINESTRING"):
        return ()
    body = wkt[wkt.index("(") + 1 : wkt.rindex(")")]
    points = []
    for pair in body.split(","):
        x, y = pair.split()[:2]
        points.append((float(x), float(y)))
    return tuple(points)
