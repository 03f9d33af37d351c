"""Place charging stations on a scenario's network and write the scenario's additional files.

    python scripts/place_stations.py sumo_net/jurong_west --k 5 --min-spacing 1500 \
        --anchor "Jurong Point:103.7063,1.3397" --seed 0

Writes ``stations.add.xml`` (car parks + charging stations) and ``vtypes.add.xml`` (``car``, ``ev``)
into the scenario folder, then prints the station-to-station road distances. An existing stations
file is kept unless ``--force`` is given.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from evcd.scenario.placement import Anchor, place_stations, station_distances
from evcd.scenario.routing import RoadGraph
from evcd.scenario.scenario import STATIONS_FILE, VTYPES_FILE, find_net_file, read_net
from evcd.scenario.stations_file import write_stations
from evcd.scenario.vtypes import write_vtypes

log = logging.getLogger("place_stations")


def parse_anchor(text: str) -> Anchor:
    """``"Name:lon,lat"`` -> :class:`Anchor`."""
    try:
        name, coords = text.rsplit(":", 1)
        lon, lat = (float(v) for v in coords.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"anchor {text!r}: expected 'Name:lon,lat'") from None
    return Anchor(name, lon, lat)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", type=Path, help="scenario folder holding one *.net.xml[.gz]")
    p.add_argument("--k", type=int, default=5, help="number of stations (default 5)")
    p.add_argument("--min-spacing", type=float, default=1500.0, help="min road distance, m (default 1500)")
    p.add_argument(
        "--anchor", type=parse_anchor, action="append", default=[], help="Name:lon,lat (repeatable)"
    )
    p.add_argument("--points", type=int, default=2, help="charging points per station (default 2)")
    p.add_argument("--power-kw", type=float, default=100.0, help="power per point, kW (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of the candidate sampling (default 0)")
    p.add_argument("--force", action="store_true", help="overwrite an existing stations file")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        if not args.scenario.is_dir():
            raise FileNotFoundError(f"scenario folder not found: {args.scenario}")
        out = args.scenario / STATIONS_FILE
        if out.exists() and not args.force:
            raise ValueError(f"{out} exists; pass --force to replace it")
        net = read_net(find_net_file(args.scenario))
        stations = place_stations(
            net, args.k, args.min_spacing, np.random.default_rng(args.seed), anchors=args.anchor,
            points=args.points, power_w=args.power_kw * 1000.0,
        )  # fmt: skip
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    write_stations(stations, out)
    write_vtypes(args.scenario / VTYPES_FILE)
    d = station_distances(RoadGraph.from_net(net), stations)
    for s, row in zip(stations, d, strict=True):
        log.info("%s %-28s %s  road m: %s", s.id, s.name, s.lane, " ".join(f"{v:6.0f}" for v in row))
    log.info("wrote %s and %s", out, args.scenario / VTYPES_FILE)
    return 0


if __name__ == "__main__":
    sys.exit(main())
