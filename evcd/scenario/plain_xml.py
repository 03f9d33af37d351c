"""SUMO plain XML (nodes, edges, types) from an OSMnx GraphML road graph (:mod:`evcd.scenario.graphml`
says which roads are kept and how). Output is sorted, so converting the same GraphML twice gives
byte-identical files.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

from evcd.scenario.graphml import (
    ROAD_TYPES,
    SERVICE_TYPE,
    RoadEdge,
    RoadNode,
    RoadType,
    merge_signal_clusters,
    read_graphml,
    road_edges,
    road_node,
)

log = logging.getLogger(__name__)


def write_plain_xml(
    graphml: str | Path, prefix: str | Path, *, include_service: bool = True
) -> tuple[Path, Path, Path]:
    """Convert ``graphml`` to SUMO plain XML ``<prefix>.nod.xml``, ``.edg.xml`` and ``.typ.xml``.

    Returns the three paths. Raises like :func:`read_graphml`, and ``ValueError`` when no passenger
    road is left.
    """
    graph = read_graphml(graphml)
    edges = road_edges(graph, include_service=include_service)
    if not edges:
        raise ValueError(f"{graphml}: no passenger-road edges (road types {sorted(ROAD_TYPES)})")
    used = sorted({e.from_node for e in edges} | {e.to_node for e in edges})
    nodes = [road_node(nid, graph.nodes[nid]) for nid in used]
    nodes, edges = merge_signal_clusters(nodes, edges)
    prefix = Path(prefix)
    paths = (Path(f"{prefix}.nod.xml"), Path(f"{prefix}.edg.xml"), Path(f"{prefix}.typ.xml"))
    write_xml(nodes_xml(nodes), paths[0])
    write_xml(edges_xml(edges), paths[1])
    types = dict(ROAD_TYPES, service=SERVICE_TYPE) if include_service else ROAD_TYPES
    write_xml(types_xml(types), paths[2])
    log.info(
        "plain XML: %d nodes (%d signalised), %d edges",
        len(nodes),
        sum(n.signals for n in nodes),
        len(edges),
    )
    return paths


def nodes_xml(nodes: Iterable[RoadNode]) -> ET.Element:
    """``<nodes>``: one ``<node>`` per road node, lon/lat, ``traffic_light`` where signalised."""
    root = ET.Element("nodes")
    for n in nodes:
        el = ET.SubElement(root, "node", id=n.id, x=_fmt(n.lon), y=_fmt(n.lat))
        if n.signals:
            el.set("type", "traffic_light")
    return root


def edges_xml(edges: Iterable[RoadEdge]) -> ET.Element:
    """``<edges>``: one ``<edge>`` per road edge (type, lanes, speed, name, spread, shape, OSM id)."""
    root = ET.Element("edges")
    for e in edges:
        el = ET.SubElement(root, "edge", id=e.id)
        el.set("from", e.from_node)
        el.set("to", e.to_node)
        el.set("type", f"highway.{e.highway}")
        el.set("numLanes", str(e.lanes))
        el.set("speed", f"{e.speed:.2f}")
        if e.name:
            el.set("name", e.name)
        el.set("spreadType", "center" if e.oneway else "right")
        if e.shape:
            el.set("shape", " ".join(f"{_fmt(x)},{_fmt(y)}" for x, y in e.shape))
        if e.osmid:
            ET.SubElement(el, "param", key="osmid", value=e.osmid)
    return root


def types_xml(types: dict[str, RoadType]) -> ET.Element:
    """``<types>``: the road types' priority, lanes and speed, highest priority first."""
    root = ET.Element("types")
    for name, t in sorted(types.items(), key=lambda kv: -kv[1].priority):
        ET.SubElement(
            root,
            "type",
            id=f"highway.{name}",
            priority=str(t.priority),
            numLanes=str(t.lanes),
            speed=f"{t.speed_kmh / 3.6:.2f}",
        )
    return root


def write_xml(root: ET.Element, path: Path) -> None:
    """Write ``root`` indented, with an XML declaration (byte-identical for the same input)."""
    ET.indent(root, space="    ")
    ET.ElementTree(root).write(path, encoding="UTF-8", xml_declaration=True)


def _fmt(value: float) -> str:
    return f"{value:.7f}"
