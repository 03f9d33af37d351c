"""The Gymnasium contract: registration, spaces, check_env, bad input, life cycle."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from evcd.env import ENV_ID, ChargingNavEnv
from evcd.scenario.scenario import STATIONS_FILE
from evcd.sim.driver import SumoDriver
from tests.conftest import GRID_ENV


@pytest.mark.slow
def test_check_env_passes_on_the_grid(grid_env_dir, env_cache):
    env = gymnasium.make(ENV_ID, scenario=grid_env_dir, cache_dir=env_cache, **GRID_ENV)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert not [w for w in caught if "WARN" in str(w.message)], [str(w.message) for w in caught]
    finally:
        env.close()
    assert SumoDriver.active() is None


def test_the_id_is_versioned_and_an_older_version_is_refused_naming_todays():
    assert ENV_ID == "evcd/ChargingNav-v1"
    with pytest.raises(gymnasium.error.DeprecatedEnv, match="evcd/ChargingNav-v1"):
        gymnasium.make("evcd/ChargingNav-v0")


def test_spaces_and_first_observation(make_env):
    env = make_env()
    m = len(env.stations)
    assert m == 3 and env.action_space == gymnasium.spaces.Discrete(3)
    assert env.observation_space.shape == (9,) and env.observation_space.dtype == np.float32
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and obs in env.observation_space
    assert 1800 <= info["departure"] < 3600 and info["time"] > info["departure"]
    assert env.simulation.api.vehicle.getRoadID("evcd_target") == info["origin"]
    assert (obs[:m] > 0).all()  # it departs away from every car park


def test_normalized_observation_scales(make_env):
    raw_env = make_env()
    raw, _ = raw_env.reset(seed=4)
    env = make_env(normalize_obs=True)
    norm, _ = env.reset(seed=4)
    assert norm in env.observation_space
    points = np.array([st.points for st in env.stations], dtype=np.float32)
    np.testing.assert_allclose(norm[:3], raw[:3] / 1000, rtol=1e-6)
    np.testing.assert_allclose(norm[3:6], raw[3:6] / 10, rtol=1e-6)
    np.testing.assert_allclose(norm[6:], raw[6:] / points, rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"evs": -1}, "evs=-1"),
        ({"decision_interval": -60}, "decision_interval=-60"),
        ({"decision_interval": 0}, "decision_interval=0"),
        ({"protocol": "slow"}, "protocol='slow'"),
        ({"reward": "money"}, "reward='money'"),
        ({"departure_window": (3600, 1800)}, "departure_window"),
        ({"departure_window": (0, 90_000)}, "departure_window"),
        ({"max_travel_time": 0}, "max_travel_time=0"),
        ({"charging_points": 0}, "charging_points=0"),
        ({"demand_seeds": []}, "demand_seeds"),
        ({"demand_seeds": [-2]}, "demand_seeds"),
        ({"demand": {"lanes": 3}}, "lanes"),
        ({"snapshot_every": 0}, "snapshot_every=0"),
    ],
)
def test_bad_arguments_are_value_errors_before_sumo(kwargs, match, grid_env_dir, env_cache):
    with pytest.raises(ValueError, match=match):
        ChargingNavEnv(grid_env_dir, cache_dir=env_cache, **{**GRID_ENV, **kwargs})
    assert SumoDriver.active() is None


def test_scenario_without_stations_is_a_value_error(grid_env_dir, tmp_path):
    folder = tmp_path / "no_stations"
    shutil.copytree(grid_env_dir, folder)
    (folder / STATIONS_FILE).unlink()
    with pytest.raises(ValueError, match=r"scenario=.*no_stations.*stations"):
        ChargingNavEnv(folder, cache_dir=tmp_path)
    with pytest.raises(ValueError, match="scenario="):
        ChargingNavEnv(tmp_path / "nowhere", cache_dir=tmp_path)


def test_bad_actions_and_life_cycle(make_env):
    env = make_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.reset(seed=1)
    for bad in (3, -1, 1.5, "0", True, np.array([0, 1])):
        with pytest.raises(ValueError, match="action="):
            env.step(bad)
    _, reward, terminated, _, info = env.step(np.int64(2))  # numpy integers are fine
    assert info["station"] == 2 and (reward == 0.0 or terminated)
    with pytest.raises(ValueError, match="reset options"):
        env.reset(options={"colour": "red"})
    with pytest.raises(ValueError, match="departure=99"):
        env.reset(options={"departure": 99})  # outside the window (fast protocol)
    env.close()
    env.close()
    assert SumoDriver.active() is None
    obs, _ = env.reset(seed=1)  # a closed environment starts SUMO again
    assert obs in env.observation_space


def test_route_file_excludes_generated_demand(grid_env_dir, env_cache, tmp_path: Path):
    routes = tmp_path / "r.rou.xml"
    routes.write_text("<routes/>\n", encoding="utf-8")
    with pytest.raises(ValueError, match="route_file"):
        ChargingNavEnv(grid_env_dir, route_file=routes, evs=10, cache_dir=env_cache)
    with pytest.raises(ValueError, match="no such file"):
        ChargingNavEnv(grid_env_dir, route_file=tmp_path / "missing.rou.xml", cache_dir=env_cache)
