"""A vehicle's next stop and whether what is left of its route still reaches it.

A re-route that SUMO refuses, or ``rerouteParkingArea`` from inside a junction, can replace a
vehicle's stop but keep its old route: the stop is then off the route, SUMO drops it when the
vehicle passes, and libsumo 1.28 crashes (segmentation fault) on ``rerouteTraveltime`` for such a
vehicle. The road player and the fleet's guided EVs both check for it here.
"""

from __future__ import annotations

from typing import Any


def next_stop_on_route(veh: Any, vid: str) -> tuple[Any | None, bool]:
    """``vid``'s next stop (``None`` when it has none) and whether the stop's edge is on what is left
    of its route (``False`` without a stop). ``veh``: the TraCI ``vehicle`` domain."""
    stops = veh.getStops(vid, 1)
    if not stops:
        return None, False
    edge = stops[0].lane.rpartition("_")[0]
    return stops[0], edge in veh.getRoute(vid)[veh.getRouteIndex(vid) :]
