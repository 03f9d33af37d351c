"""Hand-built background days on the 4 x 4 grid of ``tests/conftest.py::small_scenario``.

Stations, in action order: ``cs1`` (index 0, 2 points) on ``B1C1``, ``cs2`` (index 1, 1 point) on
``C2B2``; both car parks span 60-100 m of their 185.6 m edge.
"""

from __future__ import annotations

from tests import route_xml
from tests.route_xml import car, write_routes

__all__ = ["car", "ev", "write_routes"]

TO_CS1 = "A1B1 B1C1"
TO_CS2 = "D2C2 C2B2"
CAPACITY_WH = 20_000.0  # small batteries: 100 kW (95 % efficient) adds 0.13 % SoC per second


def ev(
    vid: str,
    depart: float,
    route: str,
    lot: str | None,
    *,
    soc: float = 0.1,
    target: float = 0.3,
    hold: bool = False,
) -> str:
    """An EV driving ``route`` and, with ``lot``, parking there to charge from ``soc`` to ``target``."""
    return route_xml.ev(vid, depart, route, lot, capacity=CAPACITY_WH, soc=soc, target=target, hold=hold)
