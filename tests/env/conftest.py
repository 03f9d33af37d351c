"""Fixtures for the environment tests: real SUMO on small generated networks.

``grid_env_dir``: the 8 x 8 grid scenario of ``tests/scenario/conftest.py`` (3 stations, 2 points).
Its background day is light and short (:data:`GRID_DEMAND`: all departures in the first two hours),
so that building the day's snapshots takes a couple of seconds and the paper protocol, stopped at
:data:`PAPER_DAY_END`, a few seconds per episode.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from evcd.env import ChargingNavEnv
from tests.scenario.conftest import make_grid_scenario

GRID_DEMAND: dict[str, Any] = {
    "cars_per_day": 800,
    "evs": 40,
    "min_trip_m": 500.0,
    "charging_share": 0.5,
    "hourly_profile": [8.0, 8.0] + [0.0] * 22,
}
WINDOW = (1800.0, 3600.0)
PAPER_DAY_END = 5400.0
GRID_ENV: dict[str, Any] = {
    "demand": GRID_DEMAND,
    "departure_window": WINDOW,
    "snapshot_every": 300.0,
    "day_end": PAPER_DAY_END,
}


@pytest.fixture(scope="session")
def grid_env_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A scenario folder on the 8 x 8 grid (do not modify: shared by the session)."""
    return make_grid_scenario(tmp_path_factory.mktemp("grid_env"))


@pytest.fixture(scope="session")
def env_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A snapshot cache shared by the session's environments (days are built once)."""
    return tmp_path_factory.mktemp("evcd_cache")


class EnvFactory:
    """Makes environments one at a time (libsumo: one simulation per process); closes them all."""

    def __init__(self) -> None:
        self.made = 0
        self._envs: list[ChargingNavEnv] = []

    def make(self, **kwargs: Any) -> ChargingNavEnv:
        self.close()
        env = ChargingNavEnv(**kwargs)
        self._envs.append(env)
        self.made += 1
        return env

    def close(self) -> None:
        for env in self._envs:
            env.close()


@pytest.fixture
def make_env(grid_env_dir: Path, env_cache: Path) -> Iterator[Callable[..., ChargingNavEnv]]:
    """``make_env(**overrides)``: a grid environment, closed after the test (one libsumo at a time)."""
    factory = EnvFactory()
    yield lambda **overrides: factory.make(
        **{"scenario": grid_env_dir, "cache_dir": env_cache, **GRID_ENV, **overrides}
    )
    factory.close()


def run_episode(
    env: ChargingNavEnv,
    seed: int,
    policy: Callable[[Any], int] | None = None,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Play one episode (greedy by ``D`` unless ``policy``); return its observations, actions, info."""
    m = int(env.action_space.n)
    obs, info = env.reset(seed=seed, options=options)
    observations, actions, rewards = [obs], [], []
    while True:
        action = policy(obs) if policy is not None else int(obs[:m].argmin())
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(reward)
        if terminated or truncated:
            return {
                "observations": observations,
                "actions": actions,
                "rewards": rewards,
                "terminated": terminated,
                "info": info,
            }


@pytest.fixture
def make_small_env(
    small_scenario, env_cache: Path, tmp_path: Path
) -> Iterator[Callable[..., ChargingNavEnv]]:
    """``make_small_env(vehicles, **overrides)``: an environment whose background day is the
    hand-built ``vehicles`` (see ``tests/env/handmade.py``) on the small 4 x 4 grid."""
    from tests.env.handmade import write_routes

    factory = EnvFactory()

    def make(vehicles: list[str], **overrides: Any) -> ChargingNavEnv:
        routes = write_routes(tmp_path / f"day{factory.made}.rou.xml", vehicles)
        kwargs = {
            "scenario": small_scenario.root,
            "route_file": routes,
            "departure_window": (0.0, 600.0),
            "snapshot_every": 100.0,
            "cache_dir": env_cache,
            **overrides,
        }
        return factory.make(**kwargs)

    yield make
    factory.close()
