"""Hand-built background days on the 4 x 4 grid of ``tests/conftest.py::small_scenario``.

Stations, in action order: ``cs1`` (index 0, 2 points) on ``B1C1``, ``cs2`` (index 1, 1 point) on
``C2B2``; both car parks span 60-100 m of their 185.6 m edge.
"""

from __future__ import annotations

from pathlib import Path

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
    params = {
        "device.battery.capacity": CAPACITY_WH,
        "device.battery.chargeLevel": CAPACITY_WH * soc,
        "evcd.targetSoc": target,
    }
    if hold:
        params["evcd.hold"] = 1
    body = "".join(f'<param key="{k}" value="{v}"/>' for k, v in params.items())
    body += f'<route edges="{route}"/>'
    if lot:
        body += f'<stop parkingArea="{lot}" parking="true" duration="1000000"/>'
    return f'<vehicle id="{vid}" type="ev" depart="{depart}" departSpeed="max">{body}</vehicle>'


def car(vid: str, depart: float, route: str, stop: str = "") -> str:
    """A conventional car driving ``route`` (``stop``: an optional ``<stop>`` element)."""
    body = f'<route edges="{route}"/>{stop}'
    return f'<vehicle id="{vid}" type="car" depart="{depart}" departSpeed="max">{body}</vehicle>'


def write_routes(path: Path, vehicles: list[str]) -> Path:
    """A route file of ``vehicles`` (give them in departure order: SUMO skips the others)."""
    path.write_text("<routes>\n" + "\n".join(vehicles) + "\n</routes>\n", encoding="utf-8")
    return path
