"""Build a SUMO road network (``net.net.xml.gz``) from an OSMnx GraphML or a plain ``.osm`` extract.

The pipeline, in one place:

1. validate the input (missing file, malformed XML, wrong format) before any tool runs;
2. GraphML: convert to plain XML with :mod:`evcd.scenario.graphml` (which also groups the nodes of
   large signalised intersections); ``.osm``: netconvert's own OSM import with SUMO's OSM typemap,
   keeping only edges open to passenger cars;
3. one netconvert run with :data:`NETCONVERT_OPTIONS`;
4. keep only the largest *strongly* connected component of the edge graph, where edge ``a`` leads
   to edge ``b`` when a lane connection open to passenger cars joins them (netconvert's
   ``--keep-edges.components`` only knows weak connectivity). Removing edges can change the
   connections around them, so the pruning is repeated on the pruned network until it is stable;
5. write the result with a deterministic header comment (netconvert's own names the date and the
   temporary paths) inside a gzip member without timestamp, so that two builds are byte-identical.

Why these netconvert options (checked on Jurong West with 2,000 random trips in one hour):

- ``--lefthand``: Singapore drives on the left.
- ``--junctions.join``: OSM draws a dual-carriageway crossing as up to four nodes; unjoined, they
  become chains of tiny junctions that block each other. (For GraphML input the signalised
  clusters are merged beforehand, see :mod:`evcd.scenario.graphml`: without that merge the check
  gave 200-270 teleports with fixed-time signals and 30-50 with actuated ones; with it, none.)
- ``--tls.guess`` / ``--tls.join``: signals from the data plus guessed ones; the signals of one
  intersection run one program.
- ``--tls.default-type actuated``: Singapore's signals are vehicle-actuated (GLIDE). Fixed-time
  programs also gave no teleports in the check, but twice the time loss per trip (199 s vs 105 s).
- ``--ramps.guess`` / ``--roundabouts.guess``: acceleration lanes on the expressway on-ramps and
  right of way in roundabouts, which OSM does not state.
- ``--output.street-names``: names for people reading the network.
"""

from __future__ import annotations

import gzip
import hashlib
import logging
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import sumolib

from evcd.scenario.graphml import read_graphml
from evcd.scenario.plain_xml import write_plain_xml
from evcd.utils.sumo_tools import SUMO_HOME, run_tool

log = logging.getLogger(__name__)

NET_FILE = "net.net.xml.gz"
VCLASS = "passenger"

#: netconvert options of the main build, for both input formats (see the module docstring).
NETCONVERT_OPTIONS: tuple[str, ...] = (
    "--lefthand",
    "--junctions.join",
    "--tls.guess",
    "--tls.join",
    "--tls.default-type",
    "actuated",
    "--ramps.guess",
    "--roundabouts.guess",
    "--output.street-names",
)
#: extra options for a raw ``.osm`` extract: geometry-only nodes, signals tagged on the approaches
#: rather than on the crossing, and ways that cars may not use.
OSM_OPTIONS: tuple[str, ...] = (
    "--geometry.remove",
    "--tls.guess-signals",
    "--tls.discard-simple",
    "--keep-edges.by-vclass",
    VCLASS,
    "--remove-edges.isolated",
)
OSM_TYPEMAP = SUMO_HOME / "data" / "typemap" / "osmNetconvert.typ.xml"
#: netconvert's typemap opens ``highway.service`` to delivery vehicles only; this reopens it to cars.
_OSM_SERVICE_TYPE = (
    '<types>\n    <type id="highway.service" numLanes="1" speed="5.56" priority="1" oneway="false"'
    ' disallow="rail rail_urban rail_electric rail_fast tram ship"/>\n</types>\n'
)
MAX_PRUNE_ROUNDS = 10

_HEADER = re.compile(rb"<!-- generated on .*?-->\s*", re.DOTALL)


def build_network(
    out_dir: str | Path,
    *,
    graphml: str | Path | None = None,
    osm: str | Path | None = None,
    include_service: bool = True,
    extra_options: Sequence[str] = (),
) -> Path:
    """Build ``<out_dir>/net.net.xml.gz`` from exactly one of ``graphml`` or ``osm``.

    Args:
        out_dir: output folder (created if needed).
        graphml: an OSMnx GraphML file (EPSG:4326).
        osm: a plain OpenStreetMap XML extract (``.osm``).
        include_service: keep ``highway=service`` roads (car-park aisles, driveways); see
            :mod:`evcd.scenario.graphml` for why this is the default.
        extra_options: further netconvert options for the main build (after the defaults).

    Returns:
        The path of the network file.

    Raises:
        ValueError: both or neither source given, or the source is malformed (named in the message).
        FileNotFoundError: the source file does not exist.
        RuntimeError: netconvert failed or the pruning did not converge.
    """
    if (graphml is None) == (osm is None):
        got = "both" if graphml is not None else "neither"
        raise ValueError(f"give exactly one of graphml= or osm= (got {got})")
    source = Path(graphml if graphml is not None else osm)
    if graphml is not None:
        read_graphml(source)  # raises before any tool runs
    else:
        check_osm(source)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / NET_FILE
    with tempfile.TemporaryDirectory(prefix="evcd-net-") as tmp:
        work = Path(tmp)
        if graphml is not None:
            nod, edg, typ = write_plain_xml(source, work / "plain", include_service=include_service)
            inputs = ["--node-files", nod, "--edge-files", edg, "--type-files", typ]
            options = ["--proj.utm", *NETCONVERT_OPTIONS, *extra_options]
        else:
            types = [str(OSM_TYPEMAP)]
            if include_service:
                (work / "service.typ.xml").write_text(_OSM_SERVICE_TYPE)
                types.append(str(work / "service.typ.xml"))
            inputs = ["--osm-files", source, "--type-files", ",".join(types)]
            options = [*OSM_OPTIONS, *NETCONVERT_OPTIONS, *extra_options]
        net = work / "round0.net.xml"
        log.info("netconvert: building %s", source)
        run_tool("netconvert", [*inputs, *options, "--output-file", net])
        net, rounds = prune_to_largest_scc(net, work)
        header = _provenance(source, include_service, options, rounds)
        _write_deterministic(net, target, header)
    log.info("wrote %s", target)
    return target


def prune_to_largest_scc(net: Path, work: Path, *, vclass: str = VCLASS) -> tuple[Path, int]:
    """Keep the largest strongly connected component of ``net`` until nothing changes.

    Each round reads the network, computes the component on the ``vclass`` lane-connection graph
    and, unless it already covers every edge, rebuilds the network from the previous one with
    ``--keep-edges.input-file`` (into ``work``).

    Returns:
        The final network and the number of rounds that removed edges.
    """
    for round_ in range(MAX_PRUNE_ROUNDS + 1):
        successors = passenger_successors(sumolib.net.readNet(str(net)), vclass)
        keep = largest_strongly_connected(successors)
        removed = len(successors) - len(keep)
        log.info("SCC check %d: %d edges, largest SCC %d", round_, len(successors), len(keep))
        if removed == 0:
            return net, round_
        keep_file = work / f"keep{round_ + 1}.txt"
        keep_file.write_text("".join(f"{e}\n" for e in sorted(keep)))
        pruned = work / f"round{round_ + 1}.net.xml"
        args = ["--sumo-net-file", net, "--keep-edges.input-file", keep_file, "--lefthand"]
        run_tool("netconvert", [*args, "--output-file", pruned])
        net = pruned
    raise RuntimeError(f"SCC pruning did not converge in {MAX_PRUNE_ROUNDS} rounds ({net})")


def passenger_successors(net: sumolib.net.Net, vclass: str = VCLASS) -> dict[str, list[str]]:
    """Edge graph of ``net``: edge id -> ids of the edges a ``vclass`` vehicle can turn into.

    Only edges that allow ``vclass`` appear; a connection counts when both its lanes allow it.
    """
    graph: dict[str, list[str]] = {}
    for edge in net.getEdges(withInternal=False):
        if not edge.allows(vclass):
            continue
        graph[edge.getID()] = sorted(
            to.getID()
            for to, conns in edge.getOutgoing().items()
            if to.allows(vclass)
            and any(c.getFromLane().allows(vclass) and c.getToLane().allows(vclass) for c in conns)
        )
    return graph


def largest_strongly_connected(successors: Mapping[str, Iterable[str]]) -> set[str]:
    """The largest strongly connected component of a directed graph (iterative Tarjan).

    Ties go to the component with the smallest member id, so the result does not depend on
    dict order. Successors that are not keys of ``successors`` are ignored.
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    best: list[str] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)

    for root in sorted(successors):
        if root in index:
            continue
        visit(root)
        work = [(root, iter(sorted(successors[root])))]
        while work:
            node, children = work[-1]
            for child in children:
                if child not in successors:
                    continue
                if child not in index:
                    visit(child)
                    work.append((child, iter(sorted(successors[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:  # all children done: close the node
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while not component or component[-1] != node:
                        component.append(stack.pop())
                        on_stack.discard(component[-1])
                    if len(component) > len(best) or (
                        len(component) == len(best) and min(component) < min(best)
                    ):
                        best = component
    return set(best)


def check_osm(path: str | Path) -> None:
    """Validate a plain OSM XML extract before netconvert sees it.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: malformed XML, root element not ``<osm>``, or no ``<node>``/``<way>``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"OSM file not found: {path}")
    counts = {"node": 0, "way": 0}
    try:
        events = ET.iterparse(path, events=("start", "end"))
        _, root = next(events)
        if root.tag != "osm":
            raise ValueError(f"{path}: not an OSM XML file (root element <{root.tag}>)")
        for event, elem in events:
            if event == "end" and elem.tag in counts:
                counts[elem.tag] += 1
                root.clear()  # a town extract can be large: keep no parsed elements
    except ET.ParseError as err:
        raise ValueError(f"{path}: malformed XML ({err})") from err
    except StopIteration as err:
        raise ValueError(f"{path}: empty XML document") from err
    missing = [f"<{tag}>" for tag, n in counts.items() if n == 0]
    if missing:
        raise ValueError(f"{path}: OSM file has no {' or '.join(missing)} elements")


def _provenance(source: Path, include_service: bool, options: Sequence[str], rounds: int) -> str:
    """A header comment that depends only on the input, the options and the netconvert version."""
    version = run_tool("netconvert", ["--version"]).stdout.splitlines()[0].strip()
    digest = hashlib.sha256(source.read_bytes()).hexdigest()
    words: list[str] = []
    for opt in map(str, options):
        if words and not re.match(r"-+[A-Za-z]", opt):  # the value of the previous option
            words[-1] += f"={opt}"
        else:
            words.append(opt.lstrip("-"))
    body = "\n".join(
        [
            "built by evcd.scenario.network.build_network",
            f"source: {source.name} (sha256 {digest})",
            f"include_service: {include_service}",
            f"tool: {version}",
            f"options: {' '.join(words)}",
            f"then: largest strongly connected component kept ({VCLASS} lane connections), "
            f"{rounds} pruning round(s)",
        ]
    )
    return "<!-- " + body.replace("--", "- -").replace("\n", "\n     ") + "\n-->\n\n"


def _write_deterministic(net: Path, target: Path, header: str) -> None:
    """Gzip ``net`` to ``target`` with netconvert's header replaced by ``header`` and no timestamp."""
    data = net.read_bytes()
    data, n = _HEADER.subn(header.encode(), data, count=1)
    if n != 1:
        raise RuntimeError(f"netconvert header comment not found in {net}")
    tmp = target.with_name(target.name + ".tmp")
    with open(tmp, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz:
        gz.write(data)
    os.replace(tmp, target)
