"""The figure of a day's perturbations: where the incidents and road works are (a map) and when the
incidents, the rain and the charger outages happen (a timeline). ``scripts/inspect_scenario.py``
writes it as ``day_events.png``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import sumolib
from matplotlib import colormaps
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from evcd.scenario.stations_file import Station
from evcd.sim.outages import Outage
from evcd.sim.road_events import RoadEvents
from evcd.utils.atomic import atomic_write_png

INCIDENT, WORKS, RAIN, OUTAGE = "tab:red", "tab:orange", "tab:blue", "tab:purple"


def plot_day_events(
    net: sumolib.net.Net,
    stations: Sequence[Station],
    roads: RoadEvents,
    outages: Sequence[Outage],
    path: str | Path,
    title: str = "",
) -> Path:
    """Save a PNG: the network with the incidents (red, numbered), the road works (orange) and the
    stations (left); a timeline over the day of the rain, each incident and each station's charger
    outages (right).

    Args:
        net: the network.
        stations: the stations (their outages get a row each).
        roads: the day's incidents, rain and road works.
        outages: the day's charger outages.
        path: PNG to write (atomically).
        title: figure title.
    """
    fig = Figure(figsize=(16, 7.5))
    ax_map, ax_time = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.05, 1]})
    segs = [e.getShape() for e in net.getEdges(withInternal=False)]
    ax_map.add_collection(LineCollection(segs, linewidths=0.6, colors="0.7"))
    works = [net.getEdge(w.edge).getShape() for w in roads.roadworks]
    ax_map.add_collection(LineCollection(works, linewidths=5, colors=WORKS))
    for k, inc in enumerate(roads.incidents, 1):
        shape = net.getEdge(inc.edge).getShape()
        ax_map.add_collection(LineCollection([shape], linewidths=5, colors=INCIDENT))
        x, y = shape[len(shape) // 2]
        ax_map.annotate(str(k), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=9, color=INCIDENT,
                        fontweight="bold")  # fmt: skip
    colors = colormaps["tab10"](np.arange(len(stations)) % 10)
    for st, c in zip(stations, colors, strict=True):
        x, y = sumolib.geomhelper.positionAtShapeOffset(net.getLane(st.lane).getShape(), st.mid_pos)
        ax_map.plot(x, y, marker="*", markersize=18, color=c, markeredgecolor="k", zorder=5)
        ax_map.annotate(st.id, (x, y), xytext=(7, 7), textcoords="offset points", fontsize=9)
    ax_map.autoscale()
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    ax_map.set_title(f"{len(roads.incidents)} incidents (numbered) and {len(roads.roadworks)} road works")
    ax_map.legend(
        handles=[Line2D([], [], color=INCIDENT, lw=4, label="incident"), Line2D([], [], color=WORKS, lw=4,
                 label="road works (all day)")], loc="lower left", fontsize=8,
    )  # fmt: skip

    rows: list[tuple[str, list[tuple[float, float]], str]] = [
        ("rain", [(r.start, r.end) for r in roads.rain], RAIN),
        *((f"incident {k}", [(e.start, e.end)], INCIDENT) for k, e in enumerate(roads.incidents, 1)),
        *(
            (f"{s.id} outage", [(o.start, o.end) for o in outages if o.station == s.id], OUTAGE)
            for s in stations
        ),
    ]
    for i, (_, spans, color) in enumerate(rows):
        bars = [(a / 3600.0, (b - a) / 3600.0) for a, b in spans]
        ax_time.broken_barh(bars, (i - 0.35, 0.7), facecolors=color, alpha=0.8)
    for i, o in ((i, o) for i, st in enumerate(stations) for o in outages if o.station == st.id):
        row = 1 + len(roads.incidents) + i
        middle = (o.start + o.end) / 7200.0
        ax_time.annotate(f"-{o.points}", (middle, row), ha="center", va="center", fontsize=7, color="white")
    ax_time.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax_time.set_ylim(len(rows) - 0.5, -0.5)
    ax_time.set_xlim(0, 24)
    ax_time.set_xticks(range(0, 25, 3))
    ax_time.set_xlabel("time of day (h)")
    ax_time.grid(axis="x", alpha=0.3)
    ax_time.set_title("When: rain, incidents, charger outages (white: points out)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return atomic_write_png(fig, path)
