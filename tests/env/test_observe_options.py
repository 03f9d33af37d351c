"""The observation options (``observe=``, :mod:`evcd.env.observation`): the points in service (``P``)
and the route's current travel time (``T``) against values computed by hand, in both units, in the
single environment and the fleet; the layout reaching the agents; the queue-aware rule reading them;
bad input."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.agents.heuristics import CLOSED_S, QueueAwareAgent
from evcd.env import ChargingNavEnv
from evcd.env.observation import T_SCALE_S, check_layout
from evcd.sim.outages import points_in_service
from tests.env.handmade import TO_CS1, ev

BOTH = ["points_in_service", "route_time"]
OUTAGES = {"outages": {"per_day": 40.0, "start_window": [0, 300], "minutes": [60, 60]}}


def _route_time_by_hand(env: ChargingNavEnv, route: tuple[str, ...], pos: float, end_pos: float) -> float:
    """Free-flow time of ``route`` from ``pos`` on its first edge to ``end_pos`` on its last: each
    edge's length over its speed limit, the first and last for the part driven (no traffic)."""
    net = env.scenario.net
    edges = [net.getEdge(e) for e in route]
    times = [e.getLength() / e.getSpeed() for e in edges]
    if len(edges) == 1:
        return (end_pos - pos) / edges[0].getSpeed()
    times[0] *= (edges[0].getLength() - pos) / edges[0].getLength()
    times[-1] *= end_pos / edges[-1].getLength()
    return float(sum(times))


def test_points_in_service_and_route_time_in_the_single_environment(make_small_env):
    """An empty day with charger outages early on: ``P`` is each station's points less its outages in
    force at the observation's time, ``T`` the free-flow time of each route computed from the network
    (no traffic: SUMO's travel time of an empty edge is its length over its limit); normalised, ``P``
    is in multiples of the points and ``T`` in minutes."""
    raw = make_small_env([], observe=BOTH, perturbations=OUTAGES)
    assert raw.layout == "DNZPT" and raw.observation_space.shape == (10,)
    obs, _ = raw.reset(seed=3, options={"departure": 120.0})
    o = raw.last_observation
    now = raw.simulation.time
    outages = raw.days[0].outages
    assert any(x.active(now) for x in outages)  # the case happens
    expected_p = [points_in_service(st.points, [x for x in outages if x.station == st.id], now)
                  for st in raw.stations]  # fmt: skip
    np.testing.assert_array_equal(o.extra["P"], expected_p)
    road, pos = o.routes[0][0], raw.simulation.api.vehicle.getLanePosition("evcd_target")
    for i, st in enumerate(raw.stations):
        assert o.extra["T"][i] == pytest.approx(
            _route_time_by_hand(raw, o.routes[i], pos, st.end_pos), rel=1e-3
        )
        assert o.routes[i][0] == road
    np.testing.assert_allclose(obs[6:8], expected_p)
    np.testing.assert_allclose(obs[8:], o.extra["T"], rtol=1e-6)
    raw.close()
    scaled = make_small_env([], observe=BOTH, perturbations=OUTAGES, normalize_obs=True)
    obs_n, _ = scaled.reset(seed=3, options={"departure": 120.0})
    points = np.array([st.points for st in scaled.stations])
    np.testing.assert_allclose(obs_n[6:8], np.array(expected_p) / points, rtol=1e-6)
    np.testing.assert_allclose(obs_n[8:], o.extra["T"] / T_SCALE_S, rtol=1e-5)


def test_the_route_time_sees_rain_and_queues_behind_the_target(make_small_env):
    """Rain halving every limit doubles ``T`` on empty roads (``D`` unchanged); cars queued on the
    target's route make it longer than free flow, while ``D`` is the same."""
    calm = make_small_env([], observe=["route_time"])
    calm.reset(seed=3, options={"departure": 120.0})
    base = calm.last_observation
    rain = {"rain": {"chance": 1.0, "speed_factor": 0.5, "start_window": [0, 60]}}
    wet = make_small_env([], observe=["route_time"], perturbations=rain)
    wet.reset(seed=3, options={"departure": 120.0})
    o = wet.last_observation
    np.testing.assert_allclose(o.distance, base.distance)
    np.testing.assert_allclose(o.extra["T"], 2.0 * base.extra["T"], rtol=0.01)


def test_the_layout_reaches_every_agent_and_the_learners_inputs(make_small_env):
    env = make_small_env([], observe=BOTH)
    rng = np.random.default_rng(0)
    for name in ("greedy", "queue_aware", "random"):
        agent = make_agent_for_env(name, env, rng)
        assert agent.layout == "DNZPT"
    obs, _ = env.reset(seed=1)
    for name in ("dqn", "ppo"):
        learner = make_agent_for_env(
            name, env, rng, hidden=[8], **({"batch_size": 4} if name == "dqn" else {})
        )
        inputs = learner.policy.inputs if name == "dqn" else learner.inputs
        assert learner.layout == "DNZPT" and inputs.size == 10
        assert 0 <= learner.act(obs, explore=True) < 2
    with pytest.raises(ValueError, match=r"shape \(1, 6\): expected \(10,\) = \[D, N, Z, P, T\]"):
        make_agent_for_env("greedy", env, rng).act(obs[:6])


def test_queue_aware_reads_the_points_in_service_and_the_route_time():
    """Two stations, cs0 nearer: plain, it wins; with its points all out (``P = 0``) the other wins;
    with ``T`` the route times replace the distance guess."""
    rule = QueueAwareAgent(2, np.random.default_rng(0), points=[2, 2])
    d, n, z = [1000.0, 3000.0], [0.0, 0.0], [0.0, 0.0]
    assert rule.act(np.array(d + n + z)) == 0
    rule.layout = "DNZP"
    assert rule.act(np.array(d + n + z + [0.0, 2.0])) == 1
    assert rule.estimate(np.array(d + n + z + [0.0, 2.0]))[0] == CLOSED_S
    assert rule.act(np.array(d + n + z + [1.0, 2.0])) == 0  # one point still in service, free
    rule.layout = "DNZT"
    assert rule.act(np.array(d + n + z + [900.0, 300.0])) == 1
    np.testing.assert_allclose(rule.estimate(np.array(d + n + z + [900.0, 300.0])), [900.0, 300.0])


def test_the_fleet_puts_h_before_the_options_blocks(make_small_fleet):
    env = make_small_fleet([ev("a", 5, TO_CS1, "pa_cs1")], observe=["points_in_service"])
    assert env.layout == "DNZHP" and env.observation_space("a").shape == (10,)
    obs, _ = env.reset(seed=0)
    row = obs["a"]
    np.testing.assert_array_equal(row[6:8], [0.0, 0.0])  # H: no other guided EV
    np.testing.assert_array_equal(row[8:], [st.points for st in env.stations])  # P: all in service
    agent = make_agent_for_env("reservation", env, np.random.default_rng(0))
    assert agent.layout == "DNZHP" and agent.act(row) in (0, 1)


@pytest.mark.parametrize(
    ("observe", "message"),
    [
        (["speed"], "unknown option 'speed'; the options: points_in_service, route_time"),
        ("route_time", "must be a list of options"),
    ],
)
def test_bad_observation_options_are_refused_by_name(small_scenario, observe, message):
    with pytest.raises(ValueError, match=None) as info:
        ChargingNavEnv(scenario=small_scenario.root, observe=observe)
    assert message in str(info.value)
    with pytest.raises(ValueError, match="layout 'DNZTP'"):
        check_layout("DNZTP")
