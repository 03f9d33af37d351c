"""Deciding the EVs of one fleet tick in turn (evcd.agents.in_turn, DQNConfig.in_turn): every
correction computed by hand on two stations, and the DQN agent's decisions and stored transitions."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent
from evcd.agents.in_turn import counted_at, decide_in_turn
from evcd.env.transition import Transition
from evcd.utils.checkpoint import save_checkpoint
from tests.agents.states import saved_options

M = 2
SMALL = {"hidden": (16, 16), "batch_size": 8, "buffer_size": 64, "learning_starts": 1000}


#: one torch thread (tiny networks: faster), put back after every test
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _row(d=(500.0, 800.0), n=(1.0, 2.0), z=(0.0, 0.0), h=(0.0, 0.0)) -> np.ndarray:
    return np.array([*d, *n, *z, *h], dtype=np.float32)


def _fewest_heading(j: int, row: np.ndarray) -> int:
    """A rule for the tests: the station with the fewest guided EVs heading there (ties: lowest)."""
    return int(np.argmin(row[3 * M :]))


def test_each_ev_sees_the_stations_chosen_before_it() -> None:
    obs = np.stack([_row()] * 3)
    unknown = np.full(3, -1)
    stations, seen = decide_in_turn(obs, unknown, np.ones(M), [0, 1, 2], _fewest_heading)
    # side by side all three would take station 0; in turn they split 0, 1, 0
    assert stations.tolist() == [0, 1, 0]
    assert [row[3 * M :].tolist() for row in seen] == [[0, 0], [1, 0], [1, 1]]
    np.testing.assert_array_equal(seen[:, : 3 * M], obs[:, : 3 * M])  # D, N, Z untouched
    # another order: the last row decides first and sees nothing new
    stations, seen = decide_in_turn(obs, unknown, np.ones(M), [2, 1, 0], _fewest_heading)
    assert stations.tolist() == [0, 1, 0]
    assert [row[3 * M :].tolist() for row in seen] == [[1, 1], [1, 0], [0, 0]]


def test_an_ev_moved_from_where_it_was_counted_leaves_that_count() -> None:
    go_to_0 = lambda j, row: 0  # noqa: E731
    # EV 0 was heading to station 1 (in the others' H[1] = 2) and is sent to 0; EV 1 waits in
    # station 1's car park (in Z[1] = 3) and is sent to 0; EV 2 was heading to 0 and stays
    obs = np.stack(
        [_row(z=(0, 3), h=(1, 2)), _row(d=(400.0, 0.0), z=(0, 3), h=(1, 2)), _row(z=(0, 3), h=(1, 2))]
    )
    counted = np.array([1, 1, 0])  # EV 1 waits (D == 0 at station 1): counted in Z
    stations, seen = decide_in_turn(obs, counted, np.ones(M), [0, 1, 2], go_to_0)
    assert stations.tolist() == [0, 0, 0]
    assert seen[1, 2 * M :].tolist() == [0, 3, 2, 1]  # after EV 0: H[0] + 1, H[1] - 1
    assert seen[2, 2 * M :].tolist() == [0, 2, 3, 1]  # after EV 1 too: Z[1] - 1, H[0] + 1
    # an EV kept where it is counted changes nothing for those after it
    stations, seen = decide_in_turn(obs, np.array([0, 0, 0]), np.ones(M), [0, 1, 2], go_to_0)
    np.testing.assert_array_equal(seen, obs)


def test_g_follows_the_choices_before_an_ev_where_t_says_who_is_due_first() -> None:
    """Layout ``DNZHTG``: EV 0 (T = 100 s to both) was heading to station 1 and is sent to 0; EV 1 (T
    = 50 / 300 s) and EV 2 (T = 200 / 200 s) keep station 0. EV 0 is due at 0 after EV 1 (no change
    in EV 1's G[0]) and before EV 2 (G[0] + 1); it was due at 1 before both (G[1] - 1 for each).
    Without T in the layout G stays as observed."""
    go_to_0 = lambda j, row: 0  # noqa: E731

    def row(t: tuple[float, float], g: tuple[float, float]) -> np.ndarray:
        return np.concatenate([_row(h=(2, 1)), np.array([*t, *g], dtype=np.float32)])

    obs = np.stack([row((100, 100), (0, 0)), row((50, 300), (0, 1)), row((200, 200), (1, 1))])
    counted = np.array([1, 0, 0])
    stations, seen = decide_in_turn(obs, counted, np.ones(M), [0, 1, 2], go_to_0, "DNZHTG")
    assert stations.tolist() == [0, 0, 0]
    assert seen[1, 3 * M :].tolist() == [3, 0, 50, 300, 0, 0]  # H[0] + 1, H[1] - 1; G[1] - 1
    assert seen[2, 3 * M :].tolist() == [3, 0, 200, 200, 2, 0]  # G[0] + 1 as well
    no_t = np.delete(obs, [8, 9], axis=1)
    _, seen = decide_in_turn(no_t, counted, np.ones(M), [0, 1, 2], go_to_0, "DNZHG")
    np.testing.assert_array_equal(seen[:, 4 * M :], no_t[:, 4 * M :])


def test_normalised_observations_move_by_one_vehicle_in_their_units() -> None:
    points = np.array([2.0, 4.0])
    obs = np.stack([_row(h=(0.5, 0.25))] * 2)
    stations, seen = decide_in_turn(obs, np.array([0, -1]), 1.0 / points, [0, 1], lambda j, row: 1)
    assert stations.tolist() == [1, 1]
    assert seen[1, 3 * M :].tolist() == [0.0, 0.5]  # one vehicle less at 0 (1/2), one more at 1 (1/4)


def test_counts_never_go_below_zero_and_bad_input_is_named() -> None:
    obs = np.stack([_row()] * 2)  # EV 0 said to be counted at station 1, but nobody is there
    _, seen = decide_in_turn(obs, np.array([1, -1]), np.ones(M), [0, 1], lambda j, r: 0)
    assert seen[1, 3 * M :].tolist() == [1.0, 0.0]
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        decide_in_turn(np.zeros(6), np.full(1, -1), np.ones(M), [0], _fewest_heading)
    with pytest.raises(ValueError, match="permutation"):
        decide_in_turn(obs, np.full(2, -1), np.ones(M), [0, 0], _fewest_heading)


def test_counted_at_reads_waiting_evs_from_d_and_the_others_from_their_state() -> None:
    class Ep:
        def __init__(self, station):
            self.station = station

    d = np.array([[0.0, 300.0], [200.0, 300.0], [200.0, 0.0]])
    assert counted_at(d, [Ep(1), Ep(None), Ep(None)]).tolist() == [0, -1, 1]


def _agent(seed: int = 0, **kwargs):
    return make_agent("dqn", M, np.random.default_rng(seed), obs_blocks=4, **{**SMALL, **kwargs})


def _tick(rng: np.random.Generator, k: int) -> np.ndarray:
    """``k`` observations of one tick: distances, traffic, queues and guided EVs heading."""
    d = rng.uniform(200.0, 3000.0, (k, M))
    n = rng.integers(0, 10, (k, M))
    z = np.broadcast_to(rng.integers(0, 4, M), (k, M))
    h = np.broadcast_to(rng.integers(0, 4, M), (k, M))
    return np.concatenate([d, n, z, h], axis=1).astype(np.float32)


def test_the_agent_decides_each_ev_on_what_it_sees_after_those_before_it() -> None:
    agent = _agent(in_turn=True)
    obs = _tick(np.random.default_rng(1), 6)
    episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(6)]
    stations = agent.decide(obs, episodes)
    order = np.argsort(-agent.q_values(obs).max(axis=1), kind="stable")
    picked = np.zeros(M)
    for j in order:  # first decisions: nobody is counted anywhere yet, every pick adds one in H
        seen = episodes[j].seen
        np.testing.assert_array_equal(seen[3 * M :], obs[j, 3 * M :] + picked)
        assert stations[j] == agent.q_values(seen).argmax() == episodes[j].station
        picked[stations[j]] += 1
    side_by_side = _agent().decide(obs, [_agent().new_episode(np.random.default_rng(0)) for _ in range(6)])
    assert stations[order[0]] == side_by_side[order[0]]  # the first sees the tick as it is


def test_its_transitions_hold_what_it_decided_on_and_none_is_lost() -> None:
    agent = _agent(in_turn=True)
    rng = np.random.default_rng(2)
    episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(3)]
    first = _tick(rng, 3)
    agent.decide(first, episodes)
    seen_first = [e.seen.copy() for e in episodes]
    second = _tick(rng, 3)
    for j, e in enumerate(episodes):
        agent.observe(Transition(first[j], e.station, -0.1, second[j], False, False), e)
    assert len(agent.replay) == 0 and agent.steps == 3  # held until their next observations are known
    agent.decide(second, episodes)
    seen_second = [e.seen.copy() for e in episodes]
    assert len(agent.replay) == 3
    stored = agent.replay.state_dict()
    for j, e in enumerate(episodes):
        i = next(i for i in range(3) if np.array_equal(stored["obs"][i], seen_first[j]))
        np.testing.assert_array_equal(stored["next_obs"][i], seen_second[j])  # what it decided on next
        agent.observe(Transition(second[j], e.station, -0.1, second[j], j == 0, j > 0), e)
    assert len(agent.replay) == 6 and agent.steps == 6  # an EV's last transition is stored at once
    last = agent.replay.state_dict()["obs"][3:6]
    assert sorted(map(tuple, last)) == sorted(map(tuple, seen_second))
    assert not np.array_equal(np.stack(seen_first), first)  # the first tick's corrections were stored


def test_one_ev_alone_decides_and_stores_as_side_by_side() -> None:
    rng = np.random.default_rng(3)
    alone, parallel = _agent(in_turn=True), _agent()  # no learning (learning_starts): same network
    for episode in range(4):
        ea = alone.new_episode(np.random.default_rng(episode))
        ep = parallel.new_episode(np.random.default_rng(episode))
        obs = _tick(rng, 1)
        for t in range(3):
            a, b = alone.decide(obs, [ea], explore=True), parallel.decide(obs, [ep], explore=True)
            assert a.tolist() == b.tolist()
            nxt = _tick(rng, 1)
            alone.observe(Transition(obs[0], int(a[0]), -0.1, nxt[0], t == 2, False), ea)
            parallel.observe(Transition(obs[0], int(b[0]), -0.1, nxt[0], t == 2, False), ep)
            obs = nxt
        # at the end of an episode both replays hold the same transitions (in_turn stored each one
        # a tick later, at the EV's next decision)
        mine, theirs = alone.replay.state_dict(), parallel.replay.state_dict()
        assert len(alone.replay) == len(parallel.replay) == 3 * (episode + 1)
        for key in ("obs", "actions", "rewards", "next_obs", "terminated"):
            np.testing.assert_array_equal(mine[key], theirs[key])


def test_in_turn_is_the_fleets_and_a_checkpoint_keeps_it(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"in_turn=True with observations DNZ \(3 blocks\).*task=fleet"):
        make_agent("dqn", M, np.random.default_rng(0), in_turn=True, **SMALL)
    with pytest.raises(ValueError, match="in_turn"):
        _agent(in_turn="yes")
    save_checkpoint(tmp_path, _agent(in_turn=True).state_dict(), "agent")
    config = saved_options(tmp_path)
    assert config["in_turn"] is True
    rebuilt = make_agent(
        "dqn", M, np.random.default_rng(5), obs_blocks=4, checkpoint=tmp_path, **{**SMALL, **config}
    )
    assert rebuilt.config.in_turn
