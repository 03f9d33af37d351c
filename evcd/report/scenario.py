"""Summaries of a simulated day: the tables ``scripts/inspect_scenario.py`` prints and saves."""

from __future__ import annotations

import numpy as np

from evcd.scenario.placement import station_distances
from evcd.scenario.routing import RoadGraph
from evcd.scenario.scenario import Scenario
from evcd.sim.day import DayResult


def station_distance_matrix(scenario: Scenario) -> np.ndarray:
    """Road distance (m) between the car-park midpoints of every pair of stations (row -> column)."""
    return station_distances(RoadGraph.from_net(scenario.net), scenario.stations)


def station_table(scenario: Scenario, day: DayResult) -> list[dict]:
    """Per station: EVs arrived, served (got a point), fully charged, max waiting, mean/max wait (s)."""
    rows = []
    for s in scenario.stations:
        recs = [r for r in day.charges if r.station == s.id]
        waits = [r.queue_wait for r in recs if r.queue_wait is not None]
        rows.append(
            {
                "station": s.id,
                "name": s.name,
                "arrived": len(recs),
                "served": len(waits),
                "charged": sum(1 for r in recs if r.outcome == "charged"),
                "max_waiting": int(max(day.traffic.waiting[s.id], default=0)),
                "mean_wait_s": float(np.mean(waits)) if waits else 0.0,
                "max_wait_s": float(np.max(waits)) if waits else 0.0,
                "total_wait_s": float(np.sum(waits)) if waits else 0.0,
            }
        )
    return rows


def day_summary(day: DayResult, trips_in_span: int) -> dict:
    """Whole-span figures: trips, arrivals, teleports and their shares."""
    t = day.traffic
    return {
        "trips_in_span": trips_in_span,
        "departed": t.departed,
        "arrived": t.arrived,
        "arrived_share": t.arrived / trips_in_span if trips_in_span else float("nan"),
        "teleports": t.teleports,
        "teleport_share": t.teleports / trips_in_span if trips_in_span else float("nan"),
        "in_network_at_end": day.in_network_at_end,
        "not_yet_inserted_at_end": day.expected_at_end - day.in_network_at_end,
        "total_queue_wait_s": float(sum(r.queue_wait or 0.0 for r in day.charges)),
        "wall_s": day.wall_s,
    }


def format_table(rows: list[dict], floatfmt: str = "{:.1f}") -> str:
    """A plain fixed-width text table of a list of dicts (same keys)."""
    if not rows:
        return "(empty)"
    keys = list(rows[0])
    cells = [[floatfmt.format(r[k]) if isinstance(r[k], float) else str(r[k]) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(keys)]
    line = "  ".join(k.rjust(w) for k, w in zip(keys, widths, strict=True))
    body = ["  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join([line, *body])
