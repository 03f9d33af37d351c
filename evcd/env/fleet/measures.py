"""What one fleet episode did to its guided EVs and to everybody else.

- ``guided_travel``: mean travel time (scheduled departure to charge start, s) of the guided EVs that
  started charging; ``truncated``: guided EVs that did not (any truncation, ``not_inserted`` too).
- ``guided_travel_censored``: the mean over EVERY guided EV, a truncated one counted at the time it
  was truncated (from its departure): a lower bound of what the guided EVs spent, which a dispatcher
  cannot improve by losing its slowest EVs (``guided_travel`` leaves them out).
- ``all_travel``: the same over ALL the charging EVs departing in the window, guided or not: the
  system's view (a centre that helps its users by pushing others into queues shows it here). Only the
  EVs that started charging before the episode ended count; ``all_unfinished`` says how many had not.
- ``queue_wait``: mean time the guided EVs waited at stations (s; every visit, the last one up to its
  charge start).
- ``herding``: the largest share of the guided EVs departing in one 10-minute bin of the window that
  ended at the same station (bins with at least :data:`HERD_MIN_EVS` guided EVs; NaN if none). 1 means
  everybody of some bin went to one station.
- ``switches``: mean number of station changes per guided EV (how much the centre changed its mind).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from evcd.env.fleet.trips import ChargingTrip
from evcd.sim.charge_record import ChargeRecord

#: Width of the herding bins (s).
HERD_BIN_S = 600.0
#: A bin counts for herding with at least this many guided EVs.
HERD_MIN_EVS = 4


@dataclass(frozen=True)
class FleetMeasures:
    """One fleet episode's figures (see the module docstring)."""

    guided: int
    guided_charged: int
    truncated: int
    guided_travel: float
    queue_wait: float
    all_evs: int
    all_unfinished: int
    all_travel: float
    herding: float
    switches: float = 0.0
    guided_travel_censored: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for JSON and CSV)."""
        return asdict(self)


def measure(
    outcomes: Sequence[Mapping[str, Any]],
    candidates: Sequence[ChargingTrip],
    records: Sequence[ChargeRecord],
    window_start: float,
) -> FleetMeasures:
    """The measures of an episode.

    Args:
        outcomes: per guided EV, its final info (:meth:`FleetEnv.outcomes`).
        candidates: every charging EV departing in the window (guided or not).
        records: the station visits of the day (:meth:`FleetEnv.charge_records`).
        window_start: the window's start (s of day): the herding bins start there.
    """
    charged = [o for o in outcomes if o.get("reason") == "charging"]
    guided_travel = _mean([float(o["travel_time"]) for o in charged])
    queue_wait = _mean([float(o["queue_wait"]) for o in outcomes if "queue_wait" in o])
    first_start: dict[str, float] = {}
    for r in records:
        if r.start_time is not None and r.vehicle not in first_start:
            first_start[r.vehicle] = r.start_time
    travel = [first_start[t.vehicle] - t.depart for t in candidates if t.vehicle in first_start]
    bins: dict[int, Counter[int]] = {}
    for o in outcomes:
        if o.get("station") is None:
            continue
        b = int((float(o["departure"]) - window_start) // HERD_BIN_S)
        bins.setdefault(b, Counter())[int(o["station"])] += 1
    shares = [max(c.values()) / sum(c.values()) for c in bins.values() if sum(c.values()) >= HERD_MIN_EVS]
    return FleetMeasures(
        guided=len(outcomes),
        guided_charged=len(charged),
        truncated=len(outcomes) - len(charged),
        guided_travel=guided_travel,
        queue_wait=queue_wait,
        all_evs=len(candidates),
        all_unfinished=len(candidates) - len(travel),
        all_travel=_mean(travel),
        herding=max(shares) if shares else math.nan,
        switches=_mean([float(o.get("switches", 0)) for o in outcomes]) if outcomes else 0.0,
        guided_travel_censored=_mean([float(o["travel_time"]) for o in outcomes if "travel_time" in o]),
    )


def _mean(values: Sequence[float]) -> float:
    return float(sum(values) / len(values)) if values else math.nan
