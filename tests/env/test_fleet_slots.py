"""The fleet's fixed-slot view (:mod:`evcd.env.fleet.slots`) on the grid: PettingZoo's parallel API,
the same episodes as the fleet itself, EVs seated and freed as documented, bad input refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from evcd.env.fleet.slots import SLOT_INFO, FleetSlots


def _choice(obs: np.ndarray) -> int:
    """A deterministic rule on one observation: the station with the fewest vehicles on the way."""
    m = obs.size // 4
    return int(np.argmin(obs[m : 2 * m]))


@pytest.mark.slow
def test_parallel_api_test_passes(make_fleet):
    env = FleetSlots(make_fleet(), slots=40)
    try:
        parallel_api_test(env, num_cycles=300)
    finally:
        env.close()


@pytest.mark.slow
def test_the_slots_play_the_fleets_episode_decision_for_decision(make_fleet):
    """The same rule through the slots and on the fleet directly: every EV's travel time equal; every
    slot present in every step; an EV keeps its slot; inactive slots are zeros with reward 0."""
    fleet = make_fleet()
    obs, _ = fleet.reset(seed=7)
    direct: dict[str, float] = {}
    while fleet.agents:
        obs, _, terms, truncs, infos = fleet.step({a: _choice(obs[a]) for a in fleet.agents})
        direct |= {a: infos[a]["travel_time"] for a in obs if terms[a] or truncs[a]}
    env = FleetSlots(make_fleet(), slots=40)
    try:
        obs, infos = env.reset(seed=7)
        ended, seats, steps = [], {}, 0
        while env.agents:
            assert set(obs) == set(infos) == set(env.possible_agents) == set(env.agents)
            for i, ev in enumerate(env.occupant):
                if ev is not None:
                    assert seats.setdefault(ev, i) == i  # an EV keeps its slot
                else:
                    assert not obs[f"slot_{i}"].any() and infos[f"slot_{i}"]["active"] == 0.0
            obs, rewards, terms, truncs, infos = env.step({a: _choice(obs[a]) for a in env.agents})
            steps += 1
            for a, info in infos.items():
                assert set(info) == set(SLOT_INFO)
                if info["ended"]:
                    ended.append(info["travel_time"])
                elif not info["active"]:
                    assert rewards[a] == 0.0 and not obs[a].any()
        assert all(terms.values()) and not any(truncs.values())
    finally:
        env.close()
    assert steps > 3 and len(seats) == len(direct) > 3
    assert sorted(ended) == pytest.approx(sorted(direct.values()))
    assert not any(math.isnan(t) for t in ended)


def test_too_few_slots_name_the_number_needed(make_fleet):
    env = FleetSlots(make_fleet(), slots=1)
    try:
        with pytest.raises(RuntimeError, match=r"FleetSlots\(slots=1\): .* make slots >= \d+"):
            env.reset(seed=7)
            while env.agents:
                env.step({a: 0 for a in env.agents})
    finally:
        env.close()


def test_bad_input(make_fleet):
    with pytest.raises(ValueError, match="slots"):
        FleetSlots(make_fleet(), slots=0)
    with pytest.raises(TypeError, match="wraps a FleetEnv"):
        FleetSlots(object(), slots=3)  # type: ignore[arg-type]
    env = FleetSlots(make_fleet(), slots=40)
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step({})
        env.reset(seed=7)
        with pytest.raises(ValueError, match="no action for 'slot_0'"):
            env.step({})
        with pytest.raises(ValueError, match="actions"):
            env.step({a: 99 for a in env.agents})  # out of range for an occupied slot
    finally:
        env.close()
