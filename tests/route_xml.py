"""Hand-written SUMO vehicles for tests: EVs that park to charge, conventional cars, route files."""

from __future__ import annotations

from pathlib import Path


def ev(
    vid: str,
    depart: float,
    route: str,
    lot: str | None,
    *,
    capacity: float,
    soc: float = 0.1,
    target: float | None = 0.3,
    hold: bool = False,
) -> str:
    """An EV driving ``route`` and, with ``lot``, parking there to charge from ``soc`` to ``target``."""
    params: dict[str, float] = {
        "device.battery.capacity": capacity,
        "device.battery.chargeLevel": capacity * soc,
    }
    if target is not None:
        params["evcd.targetSoc"] = target
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
