"""The fleet (evcd.env.fleet): PettingZoo's API test, real queueing between guided EVs, when agents
appear and leave, determinism, and the background rule reproducing the plain day."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

from evcd.env import fleet
from evcd.env.fleet import FleetEnv, draw_guided, in_window, read_charging_trips
from evcd.env.fleet.trips import ChargingTrip
from tests.conftest import FLEET_DEMAND, FLEET_WINDOW
from tests.env.handmade import ev, write_routes


def play(env: FleetEnv, seed: int, policy: Callable[[str, np.ndarray, dict], int], **reset: Any) -> dict:
    """One episode; returns per agent its summed reward, last info, decisions and appearance time."""
    obs, infos = env.reset(seed=seed, **reset)
    returns = dict.fromkeys(env.agents, 0.0)
    appeared = {a: infos[a]["time"] for a in env.agents}
    last = dict(infos)
    while env.agents:
        actions = {a: policy(a, obs[a], last[a]) for a in env.agents}
        obs, rewards, terms, truncs, infos = env.step(actions)
        for a, r in rewards.items():
            if a not in returns:
                appeared[a] = infos[a]["time"]
            returns[a] = returns.get(a, 0.0) + r
        last.update(infos)
        assert set(rewards) == set(terms) == set(truncs) == set(infos) == set(obs)
    return {"returns": returns, "infos": last, "appeared": appeared, "outcomes": env.outcomes()}


def own_station(agent: str, obs: np.ndarray, info: dict) -> int:
    """The background's own rule: the station its trip planned (nearest its origin by road)."""
    return int(info["own_station"])


def greedy(agent: str, obs: np.ndarray, info: dict) -> int:
    m = obs.size // 4
    return int(np.argmin(obs[:m]))


# ------------------------------------------------------------------------------------ the trips
def test_charging_trips_are_read_from_the_route_file_and_drawn_per_share(small_scenario, tmp_path) -> None:
    routes = write_routes(
        tmp_path / "day.rou.xml",
        [
            ev("a", 5, "A0A1 A1B1 B1C1 C1D1", "pa_cs1"),
            ev("b", 7, "D2C2 C2B2 B2A2", "pa_cs2"),
            ev("plain", 8, "A0A1 A1B1", None),
            ev("c", 400, "A0A1 A1B1 B1C1 C1D1", "pa_cs1"),
        ],
    )
    trips = read_charging_trips(routes, small_scenario.stations)
    assert trips == [ChargingTrip("a", 5.0, 0), ChargingTrip("b", 7.0, 1), ChargingTrip("c", 400.0, 0)]
    assert [t.vehicle for t in in_window(trips, (0.0, 300.0))] == ["a", "b"]
    rng = np.random.default_rng(0)
    many = [ChargingTrip(f"v{i}", float(i), 0) for i in range(40)]
    half = draw_guided(many, 0.5, rng)
    assert len(half) == 20 and half == sorted(half, key=lambda t: t.depart)
    assert draw_guided(many, 1.0, rng) == many
    assert len(draw_guided(many, 0.01, rng)) == 1  # at least one


# ------------------------------------------------------------------------------------ the API
@pytest.mark.slow
def test_parallel_api_test_passes(make_fleet) -> None:
    env = make_fleet(guided_share=0.5)
    parallel_api_test(env, num_cycles=400)
    assert env.observation_space(env.possible_agents[0]).shape == (4 * len(env.stations),)
    assert env.metadata["name"] == "evcd_fleet_v1"  # PettingZoo's versioned name


@pytest.mark.slow
def test_the_aec_form_passes_pettingzoos_api_test_and_plays_the_parallel_episodes(
    make_fleet, grid_env_dir, env_cache
) -> None:
    aec = fleet.env(scenario=grid_env_dir, cache_dir=env_cache, demand=FLEET_DEMAND,
                    departure_window=FLEET_WINDOW, guided_share=0.5)  # fmt: skip
    try:
        api_test(aec, num_cycles=400)
        # every agent picks its nearest station, in turn; the tick runs when the last has acted
        aec.reset(seed=4)
        for _agent in aec.agent_iter():
            obs, _, terminated, truncated, _ = aec.last()
            m = len(aec.unwrapped.stations)
            aec.step(None if terminated or truncated else int(np.asarray(obs)[:m].argmin()))
        aec_outcomes = aec.unwrapped.outcomes()
    finally:
        aec.close()
    parallel = make_fleet(guided_share=0.5)
    nearest = play(parallel, 4, lambda agent, obs, info: int(obs[: len(parallel.stations)].argmin()))
    assert aec_outcomes == nearest["outcomes"] and len(aec_outcomes) > 1


@pytest.mark.slow
def test_possible_agents_are_known_without_generating_a_day(make_fleet, tmp_path) -> None:
    env = make_fleet(guided_share=0.5, cache_dir=tmp_path / "fresh")
    agents = env.possible_agents
    assert agents[:3] == ["ev0", "ev1", "ev2"] and len(agents) == env.config.demand_config.evs
    assert not (tmp_path / "fresh").exists()  # no day generated, nothing simulated
    env.reset(seed=1)
    assert env.agents and set(env.agents) <= set(agents)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"guided_share": 0.0}, "guided_share=0.0"),
        ({"guided_share": 1.5}, "guided_share=1.5"),
        ({"guided_share": "half"}, "guided_share='half'"),
        ({"departure_window": (2000.0, 2000.0)}, "departure_window"),
        ({"decision_interval": -60.0}, "decision_interval=-60.0"),
        ({"observe": ["forecast"], "forecaster": "oracle"}, "forecaster='oracle' reads the cached"),
    ],
)
def test_bad_settings_fail_before_sumo_starts(make_fleet, overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_fleet(**overrides)


def test_a_bad_action_names_the_agent_and_the_range(make_fleet) -> None:
    env = make_fleet()
    env.reset(seed=0)
    agent = env.agents[0]
    with pytest.raises(ValueError, match=rf"actions\['{agent}'\]=7: must be a station index in \[0, 3\)"):
        env.step({agent: 7})
    with pytest.raises(ValueError, match="not an agent of this step"):
        env.step({"nobody": 0})
    # a bad action among good ones: none is applied (the good one is checked, not sent)
    ev = env.guided[agent]
    station, decisions = ev.station, ev.decisions
    with pytest.raises(ValueError, match=r"actions\['nobody'\]|not an agent of this step"):
        env.step({agent: (station + 1) % 3, "nobody": 0})
    assert (ev.station, ev.decisions) == (station, decisions)
    with pytest.raises(TypeError, match=r"step takes a dict \{agent: station index\}.*not a list: \[0, 1\]"):
        env.step([0, 1])
    env.step({agent: 0})  # nothing was sent by the refused calls: the episode goes on


# ------------------------------------------------------------------------------------ competition
def test_two_guided_evs_sent_to_a_one_point_station_charge_one_after_the_other(make_small_fleet) -> None:
    # both plan cs1 (2 points: no wait there); the centre sends both to cs2 (1 point)
    env = make_small_fleet(
        [ev("a", 5, "A0A1 A1B1 B1C1 C1D1", "pa_cs1"), ev("b", 8, "A0A1 A1B1 B1C1 C1D1", "pa_cs1")]
    )
    out = play(env, 0, lambda a, o, i: 1)
    infos = out["infos"]
    assert {i["reason"] for i in infos.values()} == {"charging"}
    assert {i["station_id"] for i in infos.values()} == {"cs2"}
    records = {r.vehicle: r for r in env.charge_records() if r.station == "cs2"}
    first, second = sorted(records.values(), key=lambda r: r.start_time)
    assert first.outcome is not None and first.release_time is not None  # charged, then drove on
    assert second.arrival_time < first.release_time <= second.start_time  # it waited for the point
    assert infos[second.vehicle]["queue_wait"] == pytest.approx(second.start_time - second.arrival_time)
    assert infos[second.vehicle]["queue_wait"] > 0 and infos[first.vehicle]["queue_wait"] == 0
    # each agent's rewards sum to minus its travel time (minus hours per slot)
    for agent, info in infos.items():
        assert -out["returns"][agent] * 3600 == pytest.approx(info["travel_time"])
        assert info["switches"] == 1


@pytest.mark.slow
def test_an_ev_sent_elsewhere_while_crossing_a_junction_still_charges_there(make_fleet) -> None:
    """At a tick, every guided EV found on a junction (an internal edge) is sent to another station:
    each of them must start charging there. (SUMO's rerouteParkingArea from inside a junction could
    leave the new car park off the route: the EV then drove to its destination uncharged and
    'vanished'.)"""
    env = make_fleet(guided_share=1.0, decision_interval=5.0)
    sent: dict[str, int] = {}

    def policy(agent: str, obs: np.ndarray, info: dict) -> int:
        if agent not in sent and env.simulation.api.vehicle.getRoadID(agent).startswith(":"):
            sent[agent] = (int(info["station"]) + 1) % len(env.stations)
        return sent.get(agent, int(info["station"]))

    out = play(env, 0, policy)
    assert len(sent) >= 3, sent  # the case happened (the seed and grid are fixed)
    for agent, station in sent.items():
        assert out["infos"][agent]["reason"] == "charging", out["infos"][agent]
        assert out["infos"][agent]["station"] == station
    assert all(o["reason"] == "charging" for o in out["outcomes"]), out["outcomes"]


def test_agents_appear_at_the_tick_after_insertion_and_leave_at_the_tick_after_charging(
    make_small_fleet,
) -> None:
    env = make_small_fleet(
        [ev("a", 15, "A0A1 A1B1 B1C1 C1D1", "pa_cs1"), ev("b", 35, "A0A1 A1B1 B1C1 C1D1", "pa_cs1")]
    )
    _, infos = env.reset(seed=0)
    assert env.agents == ["a"] and infos["a"]["time"] == 20.0  # ticks every 10 s from 0
    seen: dict[str, list[float]] = {"a": [20.0]}
    ends: dict[str, dict] = {}
    while env.agents:
        _, _, terms, truncs, infos = env.step(dict.fromkeys(env.agents, 0))
        for agent, info in infos.items():
            seen.setdefault(agent, []).append(info["time"])
            if terms[agent] or truncs[agent]:
                ends[agent] = info
    assert seen["b"][0] == 40.0
    for agent, info in ends.items():
        start = info["departure"] + info["travel_time"]  # the charge start
        assert info["reason"] == "charging"
        assert seen[agent][-1] == pytest.approx(10.0 * np.ceil(start / 10.0))  # the tick after it
        assert seen[agent][-2] < start
    assert [o["decisions"] for o in env.outcomes()] == [len(seen["a"]) - 1, len(seen["b"]) - 1]


def test_h_counts_the_other_guided_evs_heading_to_each_station(make_small_fleet) -> None:
    env = make_small_fleet(
        [ev("a", 5, "A0A1 A1B1 B1C1 C1D1", "pa_cs1"), ev("b", 6, "D2C2 C2B2 B2A2", "pa_cs2")]
    )
    obs, _ = env.reset(seed=0)
    assert env.agents == ["a", "b"]
    m = len(env.stations)
    assert obs["a"][3 * m :].tolist() == [0.0, 1.0]  # b heads to cs2; a itself is not counted
    assert obs["b"][3 * m :].tolist() == [1.0, 0.0]
    obs, *_ = env.step({"a": 1, "b": 0})  # they swap: a to cs2, b to cs1
    assert env.agents == ["a", "b"]
    assert obs["a"][3 * m :].tolist() == [1.0, 0.0]
    assert obs["b"][3 * m :].tolist() == [0.0, 1.0]


# ------------------------------------------------------------------------------------ reproducibility
@pytest.mark.slow
def test_same_seed_same_episode_and_the_share_draws_the_guided(make_fleet) -> None:
    env = make_fleet(guided_share=0.5)
    a = play(env, 3, greedy)
    play(env, 3, lambda agent, obs, info: 2)  # another dispatcher in between: the next does not see it
    b = play(env, 3, greedy)
    c = play(env, 4, greedy)
    assert a["infos"] == b["infos"] and a["returns"] == b["returns"]
    assert set(a["infos"]) != set(c["infos"])
    n = len(env.candidates[0])
    assert len(a["outcomes"]) == round(0.5 * n)


@pytest.mark.slow
def test_the_background_rule_reproduces_the_plain_day(make_fleet) -> None:
    env = make_fleet(guided_share=1.0)
    out = play(env, 0, own_station)
    fleet = {o["vehicle"]: o["travel_time"] for o in out["outcomes"] if o["reason"] == "charging"}
    assert len(fleet) >= 10
    # the same window of the plain day: no agent, nothing re-routed
    sim = env.simulation
    sim.start_at(0, FLEET_WINDOW[0])
    sim.driver.step(
        until=max(FLEET_WINDOW[1], *(o["departure"] + o["travel_time"] for o in out["outcomes"])) + 1
    )
    depart = {t.vehicle: t.depart for t in env.candidates[0]}
    plain: dict[str, float] = {}
    for r in sim.controller.records:
        if r.vehicle in fleet and r.start_time is not None and r.vehicle not in plain:
            plain[r.vehicle] = r.start_time - depart[r.vehicle]
    assert plain == fleet


@pytest.mark.slow
def test_the_fleet_plays_its_days_outages(make_fleet):
    """``perturbations`` reaches the fleet's world like the single environment's: each day its own
    outages, in force in the controller once an episode of that day began."""
    fleet = make_fleet(
        demand_seeds=(3, 4), perturbations={"outages": {"per_day": 20, "start_window": [0, 3000]}}
    )
    days = fleet.world.days
    assert days[0].outages and days[0].outages != days[1].outages
    fleet.reset(seed=0, options={"day": 1})
    assert fleet.world.simulation.controller.outages == days[1].outages
