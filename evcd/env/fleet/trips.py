"""The EVs of a background day that the fleet's navigation centre may guide.

A guided EV is one of the day's own charging EVs: a vehicle of the route file with a parking stop at
a station's car park (the generated days send every charging EV to the station nearest its origin by
road, :mod:`evcd.scenario.demand`). Those departing in the fleet's window are the candidates; each
episode guides a share of them, drawn from the episode's generator (:func:`draw_guided`).
"""

from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evcd.scenario.stations_file import Station

_VEHICLE_TAGS = ("trip", "vehicle", "flow")


@dataclass(frozen=True)
class ChargingTrip:
    """One charging EV of a background day.

    Attributes:
        vehicle: its SUMO id.
        depart: its scheduled departure (s of day); its travel time counts from it.
        station: index (in the scenario's order) of the station its trip plans to charge at.
    """

    vehicle: str
    depart: float
    station: int


def read_charging_trips(route_file: str | Path, stations: Sequence[Station]) -> list[ChargingTrip]:
    """Every vehicle of ``route_file`` whose first stop is at a station's car park, by departure.

    Raises:
        ValueError: the file is not a SUMO route file, or a charging vehicle departs at a time that
            is not a number (``"triggered"`` and the like cannot be guided).
    """
    lots = {st.parking_area: i for i, st in enumerate(stations)}
    path = Path(route_file)
    opener = gzip.open if path.suffix == ".gz" else open
    trips: list[ChargingTrip] = []
    with opener(path, "rb") as f:
        try:
            for _, el in ET.iterparse(f):
                if el.tag not in _VEHICLE_TAGS:
                    continue
                stop = el.find("stop")
                lot = None if stop is None else stop.get("parkingArea")
                if lot in lots:
                    depart = el.get("depart", "")
                    try:
                        t = float(depart)
                    except ValueError:
                        raise ValueError(
                            f"{path}: charging vehicle {el.get('id')!r} departs at {depart!r}; "
                            "the fleet needs departures in seconds"
                        ) from None
                    trips.append(ChargingTrip(str(el.get("id")), t, lots[lot]))
                el.clear()
        except ET.ParseError as exc:
            raise ValueError(f"{path} is not a readable SUMO route file: {exc}") from exc
    trips.sort(key=lambda trip: (trip.depart, trip.vehicle))
    return trips


def in_window(trips: Sequence[ChargingTrip], window: tuple[float, float]) -> list[ChargingTrip]:
    """The trips departing in ``[start, end)``."""
    lo, hi = window
    return [trip for trip in trips if lo <= trip.depart < hi]


def draw_guided(trips: Sequence[ChargingTrip], share: float, rng: np.random.Generator) -> list[ChargingTrip]:
    """The guided EVs of an episode: ``round(share * n)`` of the ``n`` candidates (at least one),
    drawn without replacement from ``rng``, in departure order. ``share == 1`` takes them all without
    drawing."""
    n = len(trips)
    if n == 0:
        return []
    if share >= 1.0:
        return list(trips)
    k = min(n, max(1, round(share * n)))
    picked = np.sort(rng.choice(n, size=k, replace=False))
    return [trips[i] for i in picked]
