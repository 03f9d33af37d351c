"""Summary figures of a SUMO network: size, traffic lights, driving side and extent."""

from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import sumolib


def network_summary(net_file: str | Path) -> dict[str, Any]:
    """Describe a SUMO network (``.net.xml`` or ``.net.xml.gz``).

    Returns:
        A dict with ``junctions`` (non-internal junctions), ``edges`` (non-internal edges),
        ``lane_km`` (total length of their lanes, km), ``traffic_lights`` (signal programs),
        ``lefthand`` (the ``<net lefthand="true">`` flag), ``bounds`` (``[xmin, ymin, xmax, ymax]``
        in network metres) and ``geo_bounds`` (``[lon_min, lat_min, lon_max, lat_max]``, or
        ``None`` when the network has no geo-reference).

    Raises:
        FileNotFoundError: ``net_file`` does not exist.
        ValueError: ``net_file`` is not a SUMO network.
    """
    net_file = Path(net_file)
    if not net_file.is_file():
        raise FileNotFoundError(f"network file not found: {net_file}")
    root_attrs, location = _head(net_file)
    net = sumolib.net.readNet(str(net_file))
    edges = net.getEdges(withInternal=False)
    lane_m = sum(lane.getLength() for edge in edges for lane in edge.getLanes())
    xmin, ymin, xmax, ymax = net.getBoundary()
    has_geo = location.get("projParameter", "!") != "!" and bool(location.get("origBoundary"))
    return {
        "junctions": sum(1 for node in net.getNodes() if node.getType() != "internal"),
        "edges": len(edges),
        "lane_km": round(lane_m / 1000.0, 3),
        "traffic_lights": len(net.getTrafficLights()),
        "lefthand": root_attrs.get("lefthand", "false").lower() == "true",
        "bounds": [round(v, 2) for v in (xmin, ymin, xmax, ymax)],
        "geo_bounds": [float(v) for v in location["origBoundary"].split(",")] if has_geo else None,
    }


def format_summary(summary: dict[str, Any]) -> str:
    """One line for logs and READMEs, e.g. ``612 junctions, 1253 edges, 640.1 lane-km, ...``."""
    side = "left-hand" if summary["lefthand"] else "right-hand"
    return (
        f"{summary['junctions']} junctions, {summary['edges']} edges, "
        f"{summary['lane_km']:.1f} lane-km, {summary['traffic_lights']} traffic lights, {side} traffic"
    )


def _head(net_file: Path) -> tuple[dict[str, str], dict[str, str]]:
    """Attributes of the root ``<net>`` and of ``<location>``, read without parsing the whole file."""
    opener = gzip.open if net_file.suffix == ".gz" else open
    root: dict[str, str] | None = None
    try:
        with opener(net_file, "rb") as fh:
            for _, elem in ET.iterparse(fh, events=("start",)):
                if root is None:
                    if elem.tag != "net":
                        raise ValueError(f"{net_file}: not a SUMO network (root element <{elem.tag}>)")
                    root = dict(elem.attrib)
                elif elem.tag == "location":
                    return root, dict(elem.attrib)
                else:  # <location> comes first in a network written by netconvert
                    return root, {}
    except (ET.ParseError, OSError, EOFError) as err:
        raise ValueError(f"{net_file}: not a readable SUMO network ({err})") from err
    if root is None:
        raise ValueError(f"{net_file}: empty file")
    return root, {}
