"""One description of the simulated world for both environments (evcd.env.world): a setting means
the same in ChargingNavEnv and FleetEnv, the fleet takes every one of them (its defaults aside), and
what it cannot do is refused by name before SUMO starts."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from evcd.env import ChargingNavEnv
from evcd.env.config import EnvConfig
from evcd.env.fleet import FleetEnv
from evcd.env.fleet.fleet_env import MORNING_PEAK, WORLD_OPTIONS
from evcd.env.world import World

#: A world on the test grid that differs from every default (no SUMO is started by these tests).
SETTINGS = {
    "evs": 30,
    "decision_interval": 30.0,
    "departure_window": (21600.0, 23400.0),
    "max_travel_time": 1800.0,
    "reward": "time",
    "normalize_obs": True,
    "charging_points": 3,
    "demand": {"cars_per_day": 300},
    "demand_seeds": (4, 7),
    "snapshot_every": 120.0,
    "step_length": 0.5,
    "time_to_teleport": 200.0,
    "stuck_limit": 400.0,
    "day_end": 80_000.0,
    "max_insert_delay": 300.0,
}


def test_both_environments_describe_the_same_world_alike(grid_env_dir: Path, env_cache: Path) -> None:
    single = ChargingNavEnv(scenario=grid_env_dir, cache_dir=env_cache, **SETTINGS)
    fleet = FleetEnv(scenario=grid_env_dir, cache_dir=env_cache, **SETTINGS)
    assert isinstance(single.world, World) and isinstance(fleet.world, World)
    # every setting, the derived demand and the days alike (the fleet's guided_share is its own)
    assert fleet.config == single.config
    assert [d.demand_seed for d in fleet.days] == [4, 7] == [d.demand_seed for d in single.days]
    assert fleet.days[0].key == single.days[0].key
    assert all(st.points == 3 for st in fleet.stations) and fleet.stations == single.stations
    # one observer in the same units: the shared part of the observation spaces is the same
    m = len(single.stations)
    assert np.array_equal(fleet.observation_space(None).high[: 3 * m], single.observation_space.high)
    assert fleet.observer.normalize and single.observer.normalize
    assert fleet.graph.lengths.shape == single.graph.lengths.shape
    # the simulations load the same snapshots of the same day caches
    assert fleet.simulation.times == single.simulation.times and fleet.simulation.times[0] <= 21600.0
    assert [c.spec.key for c in fleet.simulation.caches] == [c.spec.key for c in single.simulation.caches]


def test_the_fleet_takes_every_world_option_and_only_those() -> None:
    keys = {f.name for f in dataclasses.fields(EnvConfig) if f.init}
    assert set(WORLD_OPTIONS) == keys - {"scenario", "departure_window", "reward"}
    defaults = FleetEnv.__init__.__kwdefaults__
    assert defaults["departure_window"] == MORNING_PEAK and defaults["reward"] == "time"


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"protocol": "paper"}, "protocol='paper': the fleet runs from the day's snapshot"),
        ({"gui": True}, "gui=True: the fleet runs headless"),
        ({"speed": 2}, "unknown arguments \\['speed'\\]; besides scenario, guided_share"),
        ({"guided_share": 0.0}, "guided_share"),
        ({"step_length": -1.0}, "step_length"),
        ({"day_end": -5.0}, "day_end"),
    ],
)
def test_what_the_fleet_cannot_do_is_refused_by_name(grid_env_dir: Path, kwargs, needle) -> None:
    with pytest.raises(ValueError, match=needle):
        FleetEnv(scenario=grid_env_dir, **kwargs)
