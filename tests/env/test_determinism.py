"""Seeds: the same seed replays the same episode, other seeds give other targets."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import WINDOW, run_episode


def assert_same_episode(a: dict, b: dict) -> None:
    assert len(a["observations"]) == len(b["observations"])
    for x, y in zip(a["observations"], b["observations"], strict=True):
        np.testing.assert_array_equal(x, y)
    assert a["actions"] == b["actions"] and a["rewards"] == b["rewards"]
    assert a["info"] == b["info"]


def test_same_seed_same_episode_in_one_process(make_env):
    env = make_env()
    first = run_episode(env, 11)
    run_episode(env, 12)  # a later departure: the next reset goes back in time
    again = run_episode(env, 11)
    assert_same_episode(first, again)
    assert first["info"]["reason"] == "charging"


def test_same_seed_same_episode_in_a_new_environment(make_env):
    a = run_episode(make_env(), 21)
    b = run_episode(make_env(), 21)  # closes the first: a fresh SUMO
    assert_same_episode(a, b)


def test_unseeded_resets_continue_the_generator(make_env):
    env = make_env()
    env.reset(seed=5)
    _, second = env.reset()
    env.reset(seed=5)
    _, again = env.reset()
    assert second == again


@pytest.mark.slow
def test_different_seeds_different_departures(make_env):
    env = make_env()
    infos = [env.reset(seed=s)[1] for s in range(6)]
    departures = {i["departure"] for i in infos}
    assert len(departures) == 6 and all(WINDOW[0] <= t < WINDOW[1] for t in departures)
    assert len({i["origin"] for i in infos}) > 1


@pytest.mark.slow
def test_days_are_drawn_from_demand_seeds(make_env):
    env = make_env(demand_seeds=[0, 1])
    days = {env.reset(seed=s)[1]["day"] for s in range(8)}
    assert days == {0, 1}
    _, info = env.reset(seed=3, options={"day": 1})
    assert info["day"] == 1
