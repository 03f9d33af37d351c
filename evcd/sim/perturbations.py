"""A day that is not calm: its perturbations, drawn from the day's own seed.

    p = Perturbations.from_value({"outages": {"per_day": 3, "minutes": [30, 180], "points": 1}})
    outages = p.outages_of(stations, demand_seed=101)     # the same for every agent and every run

A day's events are drawn from its demand seed in a stream of their own (so a perturbed day has the
same demand as the calm one, and one kind's draws do not move another's), and are part of the day's
description: its cache key (:class:`~evcd.sim.snapshots.DaySpec`), its snapshots and every episode
played in it.

Kinds (settings under their name; a kind left out does not happen):

- ``outages`` (:mod:`evcd.sim.outages`): a Poisson number of outages per day, mean ``per_day``;
  each at a station drawn with probability proportional to its charging points, ``points`` of them
  out (at most the station's), starting uniformly in ``start_window`` (s of day), lasting
  uniformly ``minutes`` (the issue's 30-180 min by default). Overlapping outages at one station
  that would take out more points than it has are dropped (the later one), so a station with one
  point is closed at most once at a time.

Incidents, rain and road works are still to come (issue 31): asking for them is refused by name.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evcd.scenario.demand import DAY
from evcd.scenario.stations_file import Station
from evcd.sim.outages import Outage, check_outages
from evcd.utils.validation import check_int, check_real

#: Every kind the design names, and those this version draws.
KINDS = ("incidents", "rain", "outages", "roadworks")
IMPLEMENTED = ("outages",)
#: The stream of each kind's draws, beside the day's demand seed.
_STREAMS = {"outages": 1}


@dataclass(frozen=True)
class OutageSettings:
    """How charger outages are drawn (module docstring)."""

    per_day: float = 2.0
    minutes: tuple[float, float] = (30.0, 180.0)
    points: int = 1
    start_window: tuple[float, float] = (0.0, float(DAY))

    def __post_init__(self) -> None:
        check_real("perturbations.outages.per_day", self.per_day, low=0.0, high=100.0)
        check_int("perturbations.outages.points", self.points, minimum=1)
        lo, hi = _pair("perturbations.outages.minutes", self.minutes)
        if not 1.0 <= lo <= hi <= 24 * 60:
            raise ValueError(
                f"perturbations.outages.minutes={list(self.minutes)}: need 1 <= low <= high <= 1440 (minutes)"
            )
        s0, s1 = _pair("perturbations.outages.start_window", self.start_window)
        if not 0.0 <= s0 < s1 <= DAY:
            raise ValueError(
                f"perturbations.outages.start_window={list(self.start_window)}: need 0 <= "
                f"start < end <= {DAY} (s of day)"
            )
        object.__setattr__(self, "minutes", (lo, hi))
        object.__setattr__(self, "start_window", (s0, s1))


@dataclass(frozen=True)
class Perturbations:
    """The perturbations of every day of an environment (``None`` for a kind: it does not happen)."""

    outages: OutageSettings | None = None

    @classmethod
    def from_value(cls, value: Perturbations | Mapping[str, Any] | None) -> Perturbations:
        """From a mapping of kind -> settings (a Hydra block), ``None`` (calm) or an instance.

        Raises:
            ValueError: an unknown kind (the message lists them), one not drawn yet, or a bad setting.
        """
        if value is None or isinstance(value, Perturbations):
            return value or cls()
        if not isinstance(value, Mapping):
            raise ValueError(f"perturbations={value!r}: must be a mapping of kind -> settings, or None")
        unknown = sorted(set(value) - set(KINDS))
        if unknown:
            raise ValueError(f"perturbations: unknown kind {unknown[0]!r}; the kinds: {', '.join(KINDS)}")
        later = sorted(k for k in value if k not in IMPLEMENTED and value[k] is not None)
        if later:
            raise ValueError(
                f"perturbations.{later[0]}: not drawn yet (issue 31); drawn today: {', '.join(IMPLEMENTED)}"
            )
        outages = value.get("outages")
        if outages is not None and not isinstance(outages, OutageSettings):
            if not isinstance(outages, Mapping):
                raise ValueError(f"perturbations.outages={outages!r}: must be a mapping of its settings")
            known = {f.name for f in dataclasses.fields(OutageSettings)}
            bad = sorted(set(outages) - known)
            if bad:
                raise ValueError(
                    f"perturbations.outages.{bad[0]}: unknown; known: {', '.join(sorted(known))}"
                )
            outages = OutageSettings(
                **{k: tuple(v) if isinstance(v, list) else v for k, v in outages.items()}
            )
        return cls(outages=outages)

    @property
    def calm(self) -> bool:
        """Whether no kind happens."""
        return self.outages is None

    def outages_of(self, stations: Sequence[Station], demand_seed: int) -> tuple[Outage, ...]:
        """The charger outages of the day of ``demand_seed`` (sorted by start; none when calm)."""
        s = self.outages
        if s is None or s.per_day == 0:
            return ()
        rng = np.random.default_rng([int(demand_seed), _STREAMS["outages"]])
        weights = np.array([st.points for st in stations], dtype=np.float64)
        kept: list[Outage] = []
        for _ in range(int(rng.poisson(s.per_day))):
            st = stations[int(rng.choice(len(stations), p=weights / weights.sum()))]
            start = float(math.floor(rng.uniform(*s.start_window)))
            minutes = float(rng.uniform(*s.minutes))
            end = min(float(DAY), start + round(minutes * 60.0))
            outage = Outage(st.id, min(s.points, st.points), start, max(end, start + 1.0))
            try:  # drop an outage that would take out more points than the station has
                check_outages([*kept, outage], stations)
            except ValueError:
                continue
            kept.append(outage)
        return check_outages(kept, stations)


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r}: must be [low, high]") from None
    return lo, hi
