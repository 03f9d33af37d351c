"""Build a scenario's SUMO road network from an OSMnx GraphML or a plain OpenStreetMap extract.

    python scripts/build_network.py --graphml ../shared/data/jurong_west.graphml --out sumo_net/jurong_west
    python scripts/build_network.py --osm my_town.osm --out sumo_net/my_town

Writes ``<out>/net.net.xml.gz`` (left-hand traffic, passenger roads, largest strongly connected
component; see ``evcd.scenario.network``) and prints a one-line summary of the network. Building
twice from the same input gives the same bytes. A folder that already holds a network is left as it
is unless ``--force`` is given (its stations file names lanes of that network: rebuild the stations
too, ``scripts/place_stations.py --force``).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from evcd.scenario.netstats import format_summary, network_summary
from evcd.scenario.network import build_network

log = logging.getLogger("build_network")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code (2 for bad input)."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--graphml", type=Path, help="OSMnx GraphML file (EPSG:4326)")
    source.add_argument("--osm", type=Path, help="plain OpenStreetMap XML extract (.osm)")
    p.add_argument("--out", type=Path, required=True, help="output folder (the scenario folder)")
    p.add_argument(
        "--no-service",
        dest="include_service",
        action="store_false",
        help="drop highway=service roads (car-park aisles, driveways)",
    )
    p.add_argument("--force", action="store_true", help="replace the network of an existing scenario folder")
    p.add_argument("-v", "--verbose", action="store_true", help="log the netconvert command lines")
    args = p.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stdout,
    )
    existing = sorted(args.out.glob("*.net.xml*")) if args.out.is_dir() else []
    if existing and not args.force:
        log.error("%s already holds a network (%s); pass --force to replace it (and then place the stations "
                  "again: the stations file names lanes of the old network)", args.out,
                  ", ".join(p.name for p in existing))  # fmt: skip
        return 2
    try:
        net_file = build_network(
            args.out, graphml=args.graphml, osm=args.osm, include_service=args.include_service
        )
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    except RuntimeError as exc:  # netconvert failed: its message is the useful part
        log.error("%s", exc)
        return 1
    print(f"{net_file}: {format_summary(network_summary(net_file))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
