"""The fleet's observation [D, N, Z, H] in the agents, and the fleet rules (pure: no SUMO)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from evcd.agents import (
    agent_class,
    agent_names,
    make_agent,
    make_agent_for_env,
    observation_blocks,
    split_observation,
)
from evcd.agents.fleet_rules import CentralAgent, FleetRuleEpisode, ReservationAgent
from evcd.agents.heuristics import (
    FixedStationAgent,
    ForecastQueueAgent,
    GreedyAgent,
    QueueAwareAgent,
    RandomAgent,
)
from evcd.env.observation import D_SCALE_M, N_SCALE, to_physical, unit_divisors


def fleet_obs(d, n=None, z=None, h=None) -> np.ndarray:
    """A raw fleet observation [D, N, Z, H] (zeros where not given)."""
    d = np.asarray(d, dtype=np.float64)
    n, z, h = (np.zeros_like(d) if x is None else np.asarray(x, dtype=np.float64) for x in (n, z, h))
    return np.concatenate([d, n, z, h]).astype(np.float32)


def normalized(obs: np.ndarray, points) -> np.ndarray:
    """The fleet env's normalisation (evcd.env.fleet.fleet_env: H divided by the points like Z), by hand."""
    d, n, z, h = np.split(obs.astype(np.float64), 4, axis=-1)
    pts = np.asarray(points, float)
    return np.concatenate([d / D_SCALE_M, n / N_SCALE, z / pts, h / pts], axis=-1).astype(np.float32)


def random_fleet_obs(rng: np.random.Generator, m: int, k: int) -> np.ndarray:
    return np.stack(
        [
            fleet_obs(
                rng.uniform(0, 5000, m), rng.integers(0, 40, m), rng.integers(0, 6, m), rng.integers(0, 6, m)
            )
            for _ in range(k)
        ]
    )


def states(agent, k: int) -> list:
    return [agent.new_episode(np.random.default_rng(i)) for i in range(k)]


# ---------------------------------------------------------------------------------------- observation
def test_split_observation_with_four_blocks():
    vec = np.arange(12.0)
    d, n, z, h = split_observation(vec, 3, blocks=4)
    assert (d.tolist(), n.tolist(), z.tolist(), h.tolist()) == ([0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11])
    parts = split_observation(np.stack([vec, vec + 100]), 3, 4)
    assert len(parts) == 4 and all(p.shape == (2, 3) for p in parts)
    assert parts[3][1].tolist() == [109, 110, 111]
    assert len(split_observation(np.arange(9.0), 3)) == 3  # the default stays [D, N, Z]


def test_split_observation_names_the_expected_shape():
    with pytest.raises(ValueError, match=r"shape \(9,\): expected \(12,\) = \[D, N, Z, H\] for 3 stations"):
        split_observation(np.zeros(9), 3, blocks=4)
    with pytest.raises(ValueError, match=r"shape \(2, 2, 12\): expected \(12,\)"):
        split_observation(np.zeros((2, 2, 12)), 3, blocks=4)
    with pytest.raises(ValueError) as info:  # three blocks: today's message, word for word
        split_observation(np.zeros(6), 3)
    assert (
        str(info.value)
        == "observation of shape (6,): expected (9,) = [D, N, Z] for 3 stations (or a batch of them)"
    )
    for blocks in (2, 5, True):
        with pytest.raises(ValueError, match="blocks"):
            split_observation(np.zeros(12), 3, blocks=blocks)


def test_observation_blocks_reads_the_layout_off_the_size():
    assert observation_blocks(np.zeros(9), 3) == 3
    assert observation_blocks(np.zeros((5, 12)), 3) == 4
    with pytest.raises(
        ValueError, match=r"shape \(10,\): expected \(9,\) = \[D, N, Z\] or \(12,\) = \[D, N, Z, H\]"
    ):
        observation_blocks(np.zeros(10), 3)
    with pytest.raises(ValueError, match=r"expected \(12,\) = \[D, N, Z, H\] for 3"):
        observation_blocks(np.zeros(9), 3, accepted=(4,))


def test_fleet_divisors_and_physical_units():
    assert unit_divisors([2, 3], 4).tolist() == [D_SCALE_M, D_SCALE_M, N_SCALE, N_SCALE, 2, 3, 2, 3]
    rng = np.random.default_rng(0)
    points = [2, 3, 1]
    raw = random_fleet_obs(rng, 3, 4)
    np.testing.assert_allclose(to_physical(normalized(raw, points), points, True, 4), raw, rtol=1e-6)
    assert to_physical(raw, points, False, 4) is not raw  # float64 copy
    np.testing.assert_array_equal(to_physical(raw[:, :9], points, False), raw[:, :9])
    with pytest.raises(ValueError, match="layout 5: must be 3 / 'DNZ' or 4 / 'DNZH'"):
        unit_divisors(points, 5)
    # computed once per points and layout, and read-only (every caller divides by the same array)
    divisors = unit_divisors(np.array(points), "DNZHP")
    assert unit_divisors(points, "DNZHP") is divisors and not divisors.flags.writeable
    assert unit_divisors([2, 3, 2], "DNZHP") is not divisors


def test_a_rule_reads_physical_blocks_as_they_are():
    """One estimate converts its observation once: the blocks it read pass through ``physical``."""
    rng = np.random.default_rng(1)
    points = [2, 3, 1]
    agent = ReservationAgent(3, np.random.default_rng(0), points=points, normalized=True)
    obs = normalized(random_fleet_obs(rng, 3, 5), points)
    blocks = agent.physical(obs)
    assert agent.physical(blocks) is blocks
    np.testing.assert_array_equal(agent.read(blocks)[2], agent.read(obs)[2])
    np.testing.assert_array_equal(agent.guided(blocks), agent.guided(obs))


# ---------------------------------------------------------------------------------------- rules, fleet obs
@pytest.mark.parametrize("name", ["random", "greedy", "queue_aware", "fixed"])
def test_rules_give_the_same_answer_on_a_fleet_observation_as_on_its_first_three_blocks(name):
    rng = np.random.default_rng(3)
    kwargs = {"station": 2} if name == "fixed" else {}
    make = FixedStationAgent if name == "fixed" else agent_class(name)
    agent = make(4, np.random.default_rng(0), **kwargs)
    for _ in range(50):
        batch = random_fleet_obs(rng, 4, 6)
        batch[:, 12:] *= 10  # H large: it must not matter to these rules
        seeds = rng.integers(1 << 30, size=6)
        fleet = agent.decide(batch, [agent.new_episode(np.random.default_rng(s)) for s in seeds])
        single = agent.decide(batch[:, :12], [agent.new_episode(np.random.default_rng(s)) for s in seeds])
        np.testing.assert_array_equal(fleet, single)
    if name == "queue_aware":
        np.testing.assert_array_equal(agent.estimate(batch), agent.estimate(batch[:, :12]))
    if name == "greedy":
        np.testing.assert_array_equal(fleet, np.argmin(batch[:, :4], axis=1))


def test_queue_aware_reads_a_normalised_fleet_observation_in_physical_units():
    rng = np.random.default_rng(4)
    points = [2, 3, 1, 2]
    raw = QueueAwareAgent(4, np.random.default_rng(0), points=points)
    scaled = QueueAwareAgent(4, np.random.default_rng(0), points=points, normalized=True)
    batch = random_fleet_obs(rng, 4, 50)
    np.testing.assert_allclose(scaled.estimate(normalized(batch, points)), raw.estimate(batch), rtol=1e-5)


@pytest.mark.parametrize("agent", [RandomAgent, GreedyAgent, QueueAwareAgent])
def test_rules_refuse_other_sizes_naming_both_shapes(agent):
    rule = agent(3, np.random.default_rng(0))
    with pytest.raises(
        ValueError, match=r"shape \(1, 10\): expected \(9,\) = \[D, N, Z\] or \(12,\) = \[D, N, Z, H\]"
    ):
        rule.act(np.zeros(10, dtype=np.float32))


@pytest.mark.parametrize("agent", [ReservationAgent, CentralAgent])
def test_fleet_rules_need_the_fleet_observation(agent):
    rule = agent(3, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"shape \(1, 9\): expected \(12,\) = \[D, N, Z, H\] for 3 stations"):
        rule.act(np.zeros(9, dtype=np.float32))
    with pytest.raises(ValueError, match=r"shape \(2, 9\): expected \(12,\)"):
        rule.decide(np.zeros((2, 9), dtype=np.float32), states(rule, 2))


# ---------------------------------------------------------------------------------------- reservation
def test_reservation_avoids_a_short_queue_the_fleet_is_already_driving_to():
    kw = {"points": 2, "speed_mps": 10.0, "vehicle_delay_s": 2.0, "charge_s": 1200.0}
    # station 0: 1 km (100 s), nobody there, 4 guided EVs on their way; station 1: 3 km (300 s), one car
    obs = fleet_obs([1000.0, 3000.0], [0, 0], [0, 1], [4, 0])
    queue_aware = QueueAwareAgent(2, np.random.default_rng(0), **kw)
    reservation = ReservationAgent(2, np.random.default_rng(0), **kw)
    assert queue_aware.estimate(obs).tolist() == pytest.approx([100.0, 300.0])
    assert queue_aware.act(obs) == 0
    # Z + H = 4 at station 0: 4 - 2 + 1 = 3 departures x 1200 s / 2 points = 1800 s; station 1: 1 < 2 points
    assert reservation.estimate(obs).tolist() == pytest.approx([1800.0, 300.0])
    assert reservation.act(obs) == 1


def test_reservation_is_queue_aware_when_nobody_is_heading_anywhere():
    rng = np.random.default_rng(5)
    reservation = ReservationAgent(4, np.random.default_rng(0), points=[2, 3, 1, 2])
    queue_aware = QueueAwareAgent(4, np.random.default_rng(0), points=[2, 3, 1, 2])
    batch = random_fleet_obs(rng, 4, 100)
    batch[:, 12:] = 0.0
    np.testing.assert_array_equal(reservation.estimate(batch), queue_aware.estimate(batch))
    batch[:, 12:] = rng.integers(0, 6, (100, 4))
    assert (reservation.estimate(batch) >= queue_aware.estimate(batch)).all()
    assert (reservation.estimate(batch) > queue_aware.estimate(batch)).any()


# ---------------------------------------------------------------------------------------- central
ONE_POINT = {"points": 1, "speed_mps": 10.0, "vehicle_delay_s": 2.0, "charge_s": 1200.0}


def test_central_splits_evs_that_see_the_same_two_equal_stations():
    # two stations 1 km away (100 s), one point each, nobody there or heading there
    batch = np.stack([fleet_obs([1000.0, 1000.0])] * 4)
    central = CentralAgent(2, np.random.default_rng(0), **ONE_POINT)
    episodes = states(central, 4)
    # EV0: both 100 s -> 0; EV1: one ahead at 0 (1200 s) -> 1; EV2: one ahead at each -> 0; EV3 -> 1
    assert central.decide(batch, episodes).tolist() == [0, 1, 0, 1]
    assert [e.station for e in episodes] == [0, 1, 0, 1]
    for herd in (QueueAwareAgent, ReservationAgent):  # each on its own: all to the same station
        rule = herd(2, np.random.default_rng(0), **ONE_POINT)
        assert rule.decide(batch, states(rule, 4)).tolist() == [0, 0, 0, 0]


def test_central_fills_the_points_of_a_station_before_the_next():
    kw = {**ONE_POINT, "points": 2}  # 2 points: backlog (ahead - 1) x 600 s
    batch = np.stack([fleet_obs([1000.0, 1000.0])] * 6)
    central = CentralAgent(2, np.random.default_rng(0), **kw)
    # ahead at 0 / 1 before each EV: 0/0 -> 0, 1/0 -> 0 (no wait), 2/0 -> 1, 2/1 -> 1, 2/2 -> 0, 3/2 -> 1
    assert central.decide(batch, states(central, 6)).tolist() == [0, 0, 1, 1, 0, 1]


def test_central_assigns_the_soonest_ev_first():
    central = CentralAgent(2, np.random.default_rng(0), **ONE_POINT)
    far = fleet_obs([3000.0, 5000.0])  # best: station 0 in 300 s
    near = fleet_obs([1000.0, 4000.0])  # best: station 0 in 100 s
    # the near EV takes station 0; the far one then counts it there (1200 s) and takes station 1 (500 s)
    assert central.decide(np.stack([far, near]), states(central, 2)).tolist() == [1, 0]
    assert central.decide(np.stack([near, far]), states(central, 2)).tolist() == [0, 1]


def test_central_with_one_ev_is_reservation():
    rng = np.random.default_rng(6)
    points = [2, 3, 1, 2]
    central = CentralAgent(4, np.random.default_rng(0), points=points)
    reservation = ReservationAgent(4, np.random.default_rng(0), points=points)
    for row in random_fleet_obs(rng, 4, 200):
        central.begin_episode()
        assert central.act(row) == reservation.act(row)


def test_central_does_not_count_twice_the_evs_it_sent_at_the_last_tick():
    kw = {**ONE_POINT, "points": 2}
    central = CentralAgent(2, np.random.default_rng(0), **kw)
    episodes = states(central, 2)
    # tick 1: 100 s vs 300 s; the second EV counts the first at station 0, still no wait with 2 points
    tick1 = np.stack([fleet_obs([1000.0, 3000.0])] * 2)
    assert central.decide(tick1, episodes).tolist() == [0, 0]
    # tick 2: the env counts each in the other's H at station 0
    tick2 = np.stack([fleet_obs([1000.0, 3000.0], h=[1, 0])] * 2)
    assert central.decide(tick2, episodes).tolist() == [0, 0]  # nothing changed: nobody moves
    # without the memory (first decisions), the first EV would be counted twice at station 0
    # for the second one (H + this tick's assignment): 2 ahead -> 600 s > 300 s, so it moves
    assert central.decide(tick2, states(central, 2)).tolist() == [0, 1]


def test_central_frees_the_place_of_an_ev_it_moves():
    central = CentralAgent(2, np.random.default_rng(0), **ONE_POINT)
    episodes = [
        FleetRuleEpisode(np.random.default_rng(0), station=1),
        FleetRuleEpisode(np.random.default_rng(1), 1),
    ]
    # both were sent to station 1; each sees the other heading there; both 100 s away
    batch = np.stack([fleet_obs([1000.0, 1000.0], h=[0, 1])] * 2)
    # EV0: 100 s at 0 vs 1200 s at 1 -> 0; EV1 then sees nobody at 1 and one at 0 -> stays at 1
    assert central.decide(batch, episodes).tolist() == [0, 1]
    assert [e.station for e in episodes] == [0, 1]


def test_central_frees_the_car_park_place_of_a_waiting_ev_it_moves():
    kw = {**ONE_POINT, "points": [1, 2]}
    central = CentralAgent(2, np.random.default_rng(0), **kw)
    z = [0, 3]  # station 1: two charging and the waiting EV
    waiting = fleet_obs([1000.0, 0.0], z=z)  # without itself: 2 at 2 points -> 600 s; station 0: 100 s
    driving = fleet_obs([2000.0, 500.0], z=z)  # 200 s at 0; 3 ahead at 1 -> 2 x 600 = 1200 s
    # the waiting EV (100 s) goes first and leaves station 1 for station 0; the driving one then counts
    # 1 at 0 (1200 s) and 2 at 1 (600 s)
    assert central.decide(np.stack([waiting, driving]), states(central, 2)).tolist() == [0, 1]
    reservation = ReservationAgent(2, np.random.default_rng(0), **kw)
    assert reservation.decide(np.stack([waiting, driving]), states(reservation, 2)).tolist() == [0, 0]


def test_with_g_the_rules_count_only_the_guided_evs_due_before_this_one():
    """Layout ``DNZHG``: reservation counts ``Z + G``. Four EVs head to station 0 (1 km, 100 s), none
    due before this one: station 0; three due before it: 2 of them wait at its 2 points, 1200 s."""
    kw = {"points": 2, "speed_mps": 10.0, "vehicle_delay_s": 2.0, "charge_s": 1200.0}
    reservation = ReservationAgent(2, np.random.default_rng(0), **kw)
    reservation.layout = "DNZHG"
    base = fleet_obs([1000.0, 3000.0], [0, 0], [0, 1], [4, 0])
    first = np.concatenate([base, [0.0, 0.0]]).astype(np.float32)
    assert reservation.estimate(first).tolist() == pytest.approx([100.0, 300.0])
    behind = np.concatenate([base, [3.0, 0.0]]).astype(np.float32)
    assert reservation.estimate(behind).tolist() == pytest.approx([1200.0, 300.0])
    assert reservation.act(first) == 0 and reservation.act(behind) == 1


def test_the_forecast_rule_adds_the_guided_evs_due_first_to_the_forecast():
    """Layout ``DNZHFG``: queue_forecast counts ``F + G`` (2 points, 1200 s a charge): 1 forecast + 2
    due first at station 0 = 3 ahead, 1200 s; without ``G`` in the layout, 1 ahead: no wait."""
    kw = {"points": 2, "speed_mps": 10.0, "vehicle_delay_s": 2.0, "charge_s": 1200.0}
    base = fleet_obs([1000.0, 3000.0], [0, 0], [0, 0], [2, 0])
    with_g = ForecastQueueAgent(2, np.random.default_rng(0), **kw)
    with_g.layout = "DNZHFG"
    assert with_g.estimate(np.concatenate([base, [1.0, 0.0], [2.0, 0.0]])).tolist() == pytest.approx(
        [1200.0, 300.0]
    )
    without = ForecastQueueAgent(2, np.random.default_rng(0), **kw)
    without.layout = "DNZHF"
    assert without.estimate(np.concatenate([base, [1.0, 0.0]])).tolist() == pytest.approx([100.0, 300.0])


def test_central_with_g_counts_an_ev_it_assigns_only_for_those_due_after_it():
    """Three EVs, two one-point stations, nobody there: EV0 (T 100 / 1000 s) takes station 0; EV1
    (150 / 600) counts it there and takes 1; EV2 (700 / 300) is due at 1 before EV1, so with ``G`` it
    does not count EV1 there and takes 1 (300 s); with ``H`` it counts everyone assigned before it
    and breaks the tie of 1200 s to station 0. Without ``T`` the drive guess from ``D`` decides alike."""
    times = [(100.0, 1000.0), (150.0, 600.0), (700.0, 300.0)]

    def rows(layout: str) -> np.ndarray:
        out = []
        for t in times:
            blocks = {"D": np.array(t) * 10.0, "N": [0, 0], "Z": [0, 0], "H": [0, 0], "T": t, "G": [0, 0]}
            out.append(np.concatenate([np.asarray(blocks[c], dtype=np.float64) for c in layout]))
        return np.stack(out).astype(np.float32)

    for layout, expected in (("DNZHTG", [0, 1, 1]), ("DNZHT", [0, 1, 0]), ("DNZHG", [0, 1, 1])):
        central = CentralAgent(2, np.random.default_rng(0), **ONE_POINT)
        central.layout = layout
        assert central.decide(rows(layout), states(central, 3)).tolist() == expected, layout


def test_central_checks_one_row_per_episode():
    central = CentralAgent(2, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"shape \(3, 8\) for 2 episodes"):
        central.decide(np.zeros((3, 8), dtype=np.float32), states(central, 2))
    with pytest.raises(ValueError, match=r"shape \(8,\) for 1 episodes"):
        central.decide(np.zeros(8, dtype=np.float32), states(central, 1))


# ---------------------------------------------------------------------------------------- units, registry
@pytest.mark.parametrize("name", ["greedy", "queue_aware", "reservation", "central"])
def test_normalised_and_raw_fleet_observations_give_the_same_decisions(name):
    rng = np.random.default_rng(7)
    points = [2, 3, 1]
    raw = make_agent(name, 3, np.random.default_rng(0), **({} if name == "greedy" else {"points": points}))
    scaled_kw = {} if name == "greedy" else {"points": points, "normalized": True}
    scaled = make_agent(name, 3, np.random.default_rng(0), **scaled_kw)
    for _ in range(50):
        batch = random_fleet_obs(rng, 3, 8)
        np.testing.assert_array_equal(
            scaled.decide(normalized(batch, points), states(scaled, 8)), raw.decide(batch, states(raw, 8))
        )


def test_the_fleet_rules_are_registered_apart_from_the_single_env_dispatchers():
    for name, cls in (("reservation", ReservationAgent), ("central", CentralAgent)):
        agent = make_agent(name, 4, np.random.default_rng(0), charge_s=600.0)
        assert type(agent) is cls and agent_class(name) is cls and agent.charge_s == 600.0
        assert name in agent_names("fleet") and name not in agent_names("single")  # [D, N, Z, H] only
    assert all(4 in agent_class(name).obs_blocks for name in agent_names("fleet"))
    assert all(3 in agent_class(name).obs_blocks for name in agent_names("single"))
    with pytest.raises(ValueError, match=r"'centrall'.*reservation, central"):
        make_agent("centrall", 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"reservation.*\['speed'\]"):
        make_agent("reservation", 3, np.random.default_rng(0), speed=3)


def test_make_agent_for_env_reads_a_pettingzoo_fleet():
    stations = [SimpleNamespace(points=p) for p in (2, 3, 1)]
    env = SimpleNamespace(action_space=lambda agent: SimpleNamespace(n=3), possible_agents=["ev0"],
                          stations=stations, config=SimpleNamespace(normalize_obs=True))  # fmt: skip
    env.unwrapped = env
    agent = make_agent_for_env("central", env, np.random.default_rng(0))
    assert isinstance(agent, CentralAgent) and agent.n_stations == 3
    assert agent.points.tolist() == [2, 3, 1] and agent.normalized
