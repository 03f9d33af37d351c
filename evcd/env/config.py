"""The environment's settings, checked before any simulation starts."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from evcd.env.observation import OPTIONS
from evcd.forecast.registry import FORECASTERS, SETTINGS
from evcd.scenario.demand import DAY, DemandConfig
from evcd.scenario.scenario import JURONG_WEST, Scenario, load_scenario
from evcd.sim.perturbations import Perturbations
from evcd.sim.snapshots import DaySpec, snapshot_times
from evcd.utils.validation import check_choice, check_int, check_real, is_integer

PROTOCOLS = ("fast", "paper")
#: Paper protocol: every episode's simulation runs until 23:59.
PAPER_DAY_END = DAY - 60.0


@dataclass(frozen=True)
class EnvConfig:
    """Everything :class:`~evcd.env.ChargingNavEnv` takes (see its docstring for the meaning).

    Raises ``ValueError`` naming the offending value on construction; :meth:`load` then opens the
    scenario (still without starting SUMO).
    """

    scenario: str | Path = JURONG_WEST
    evs: int | None = None
    decision_interval: float = 60.0
    departure_window: tuple[float, float] = (0.0, float(DAY))
    max_travel_time: float = 7200.0
    stuck_limit: float = 600.0
    reward: str | Callable[..., float] = "paper"
    normalize_obs: bool = False
    protocol: str = "fast"
    charging_points: int | None = None
    demand: DemandConfig | Mapping[str, Any] | None = None
    demand_seeds: Sequence[int] = (0,)
    route_file: str | Path | None = None
    cache_dir: str | Path | None = None
    snapshot_every: float = 300.0
    step_length: float = 1.0
    time_to_teleport: float = 300.0
    day_end: float = PAPER_DAY_END
    max_insert_delay: float = 600.0
    gui: bool = False
    perturbations: Perturbations | Mapping[str, Any] | None = None
    observe: Sequence[str] = ()
    forecaster: str | Mapping[str, Any] = "history"
    forecast_days: Sequence[int] | None = None
    demand_config: DemandConfig = field(init=False, repr=False)

    def __post_init__(self) -> None:
        from evcd.env.reward import REWARDS

        for name in ("decision_interval", "max_travel_time", "stuck_limit", "snapshot_every", "step_length",
                     "max_insert_delay"):  # fmt: skip
            check_real(name, getattr(self, name), low=0.0, low_open=True)
        if self.decision_interval < self.step_length:
            raise ValueError(
                f"decision_interval={self.decision_interval} must be >= step_length={self.step_length}"
            )
        check_choice("protocol", self.protocol, PROTOCOLS)
        if self.evs is not None:
            check_int("evs", self.evs, minimum=0)
        if self.charging_points is not None:
            check_int("charging_points", self.charging_points, minimum=1)
        try:
            lo, hi = (float(x) for x in self.departure_window)
        except (TypeError, ValueError):
            raise ValueError(
                f"departure_window={self.departure_window!r}: must be (start, end) in s"
            ) from None
        if not 0 <= lo < hi <= DAY or hi - lo < self.step_length:
            raise ValueError(
                f"departure_window={self.departure_window!r}: need 0 <= start < end <= {DAY}, "
                f"at least one step long"
            )
        object.__setattr__(self, "departure_window", (lo, hi))
        check_real("day_end", self.day_end, low=0.0)
        if not callable(self.reward) and self.reward not in REWARDS:
            raise ValueError(f"reward={self.reward!r}: must be one of {sorted(REWARDS)} or a callable")
        seeds = tuple(self.demand_seeds)
        if not seeds or not all(is_integer(s) and s >= 0 for s in seeds):
            raise ValueError(f"demand_seeds={self.demand_seeds!r}: must be a non-empty list of integers >= 0")
        object.__setattr__(self, "demand_seeds", tuple(int(s) for s in seeds))
        if self.route_file is not None:
            if self.demand is not None or self.evs is not None or seeds != (0,):
                raise ValueError(
                    f"route_file={str(self.route_file)!r} is the whole background day: "
                    "leave demand, evs and demand_seeds unset"
                )
            if not Path(self.route_file).is_file():
                raise ValueError(f"route_file={str(self.route_file)!r}: no such file")
        object.__setattr__(self, "demand_config", self._demand_config())
        object.__setattr__(self, "perturbations", Perturbations.from_value(self.perturbations))
        if isinstance(self.observe, str) or not all(isinstance(o, str) for o in self.observe):
            raise ValueError(f"observe={self.observe!r}: must be a list of options from {', '.join(OPTIONS)}")
        unknown = sorted(set(self.observe) - set(OPTIONS))
        if unknown:
            raise ValueError(
                f"observe={list(self.observe)}: unknown option {unknown[0]!r}; the options: "
                f"{', '.join(OPTIONS)}"
            )
        object.__setattr__(self, "observe", tuple(o for o in OPTIONS if o in self.observe))
        object.__setattr__(self, "forecaster", forecaster_setting(self.forecaster))
        if "forecast" in self.observe and self.forecaster["name"] == "oracle" and self.protocol != "fast":
            raise ValueError("forecaster=oracle reads the played day's snapshots: it needs protocol='fast'")
        if self.forecast_days is not None:
            days = tuple(self.forecast_days)
            if not days or not all(is_integer(s) and s >= 0 for s in days):
                raise ValueError(
                    f"forecast_days={self.forecast_days!r}: must be a non-empty list of demand seeds >= 0"
                )
            object.__setattr__(self, "forecast_days", tuple(int(s) for s in days))
        elif "forecast" in self.observe and FORECASTERS[self.forecaster["name"]].needs_days:
            raise ValueError(
                f"forecaster={self.forecaster['name']} needs training days: forecast_days=[...] (the "
                "demand seeds of the days it may learn from; the scripts give it their training days)"
            )

    def _demand_config(self) -> DemandConfig:
        demand = self.demand
        if demand is None:
            demand = DemandConfig()
        elif isinstance(demand, Mapping):
            known = {f.name for f in dataclasses.fields(DemandConfig)}
            unknown = sorted(set(demand) - known)
            if unknown:
                raise ValueError(f"demand: unknown keys {unknown}; known: {sorted(known)}")
            values = {k: tuple(v) if isinstance(v, list) else v for k, v in demand.items()}
            demand = dataclasses.replace(DemandConfig(), **values)
        elif not isinstance(demand, DemandConfig):
            raise ValueError(f"demand={demand!r}: must be a DemandConfig, a dict of its fields or None")
        if self.evs is not None:
            demand = dataclasses.replace(demand, evs=int(self.evs))
        return demand

    def load(self) -> tuple[Scenario, list[DaySpec]]:
        """Open the scenario and describe the background days (no SUMO yet).

        Raises:
            ValueError: the scenario folder is missing or malformed (e.g. no stations file).
        """
        try:
            scenario = load_scenario(self.scenario, charging_points=self.charging_points)
        except (FileNotFoundError, ValueError) as exc:
            raise ValueError(f"scenario={str(self.scenario)!r}: {exc}") from exc
        common = {"step_length": self.step_length, "time_to_teleport": self.time_to_teleport}
        if self.route_file is not None:
            return scenario, [DaySpec(scenario, route_file=Path(self.route_file).resolve(),
                                      **self._events(scenario, 0), **common)]  # fmt: skip
        days = [DaySpec(scenario, self.demand_config, seed, **self._events(scenario, seed), **common)
                for seed in self.demand_seeds]  # fmt: skip
        return scenario, days

    def snapshot_times(self) -> list[float]:
        """The times of day (s) of the days' snapshots: every ``snapshot_every`` s over the
        departure window (:func:`evcd.sim.snapshots.snapshot_times`)."""
        return snapshot_times(self.departure_window, self.snapshot_every)

    def history_days(self, scenario: Scenario) -> list[DaySpec]:
        """The days the history forecaster is fitted on (``forecast_days``: the training days)."""
        if self.forecast_days is None:
            return []
        if self.route_file is not None:  # the route file is the only day there is
            return self.load()[1]
        return [DaySpec(scenario, self.demand_config, seed, step_length=self.step_length,
                        time_to_teleport=self.time_to_teleport, **self._events(scenario, seed))
                for seed in self.forecast_days]  # fmt: skip

    def _events(self, scenario: Scenario, seed: int) -> dict[str, Any]:
        """The perturbations of the day of ``seed``, drawn from it (:mod:`evcd.sim.perturbations`)."""
        p = self.perturbations
        events: dict[str, Any] = {"outages": p.outages_of(scenario.stations, seed)}
        if p.on_roads:
            lots = {st.lane for st in scenario.stations}  # the car parks' lanes stay open
            events["roads"] = p.roads_of(scenario.net, self.demand_config.hourly_profile, seed, lots)
        return events


def forecaster_setting(value: str | Mapping[str, Any]) -> dict[str, Any]:
    """``forecaster`` as ``{"name": ..., settings...}`` (a name alone, or a mapping with ``name``).

    Raises:
        ValueError: an unknown forecaster or setting (naming the allowed ones), or a setting's value
            out of range (the forecaster is made once to check them; the oracle takes no settings here).
    """
    spec = {"name": value} if isinstance(value, str) else dict(value)
    name = spec.get("name")
    if name not in FORECASTERS:
        raise ValueError(f"forecaster={value!r}: the forecasters are {', '.join(FORECASTERS)}")
    allowed = [k for k in SETTINGS[name] if k != "day"]
    unknown = sorted(set(spec) - {"name", *allowed})
    if unknown:
        raise ValueError(f"forecaster {name!r}: unknown setting {unknown[0]!r}; it takes {allowed or 'none'}")
    if name != "oracle":
        FORECASTERS[name](**{k: v for k, v in spec.items() if k != "name"})  # checks the values
    return spec
