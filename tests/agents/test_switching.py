"""The switching margin (evcd.agents.switching, DQNConfig.switch_margin_s): Q-values read back as
seconds by hand, the keep rule by hand, an untrained learner with the margin deciding as the fleet rule
with the same margin (side by side and in turn), and bad settings refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from evcd.agents.fleet_rules import FleetRuleEpisode, ReservationAgent
from evcd.agents.rule_input import ESTIMATE_CAP_S
from evcd.agents.rule_prior import time_return
from evcd.agents.switching import keep_station, return_seconds
from evcd.loops.train_state import config_diff
from tests.agents.test_rule_prior import M, _agent

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("gamma", [0.9, 0.99, 1.0])
def test_q_values_read_back_as_the_seconds_of_their_return(gamma) -> None:
    # up to two hours (at gamma 0.9 a return hours away is within float precision of an endless wait)
    seconds = np.array([0.0, 45.0, 120.0, 150.0, 3600.0, 7200.0])
    q = time_return(torch.tensor(seconds, dtype=torch.float64), 60.0, gamma, 10.0).numpy()
    np.testing.assert_allclose(return_seconds(q, 60.0, gamma, 10.0), seconds, rtol=1e-9, atol=1e-6)
    # decreasing in q: a better return is a sooner charge; above 0 it is before now
    assert return_seconds(np.array(0.01), 60.0, gamma, 10.0) < 0.0


def test_a_return_at_or_below_an_endless_wait_reads_as_never() -> None:
    endless = -60.0 / 3600.0 * 10.0 / (1.0 - 0.9)  # the limit of the discounted return at gamma 0.9
    assert np.isinf(return_seconds(np.array([endless, endless - 1.0]), 60.0, 0.9, 10.0)).all()


def test_the_current_station_stays_within_the_margin_by_hand() -> None:
    seconds = np.array([300.0, 250.0, 400.0])
    assert keep_station(seconds, 0, 60.0) == 0  # 50 s sooner at station 1: within 60 s, stays
    assert keep_station(seconds, 0, 40.0) == 1  # more than 40 s sooner: moves
    assert keep_station(seconds, 0, 50.0) == 0  # exactly the margin: stays
    assert keep_station(seconds, 2, 150.0) == 2 and keep_station(seconds, 2, 149.0) == 1
    assert keep_station(seconds, -1, 1e9) == 1  # not sent anywhere yet: the best
    assert keep_station(seconds, 0, 0.0) == 1  # no margin: the best
    assert keep_station(np.array([np.inf, 250.0, 400.0]), 0, 1e9) == 1  # a closed station is left
    assert keep_station(seconds, 2, 200.0, best=0) == 2  # the best given (a learner's argmax)


def _close_stations(rows: int) -> np.ndarray:
    """Fleet observations ``[D, N, Z, H, P, T, G]`` where the stations are often close: routes of
    0.3-3 km, 0-2 vehicles at each station, every point in service, other guided EVs 0-1."""
    rng = np.random.default_rng(5)
    d = rng.uniform(300, 3000, (rows, M))
    h = rng.integers(0, 2, (rows, M))
    blocks = [d, rng.integers(0, 8, (rows, M)), rng.integers(0, 3, (rows, M)), h, np.full((rows, M), 2),
              d / rng.uniform(8, 12, (rows, M)), h * rng.integers(0, 2, (rows, M))]  # fmt: skip
    return np.concatenate(blocks, axis=1).astype(np.float32)


@pytest.mark.parametrize("margin", [60.0, 300.0])
def test_an_untrained_learner_with_a_margin_decides_as_the_rule_with_it(margin) -> None:
    agent = _agent("dueling_ddqn", network="station", switch_margin_s=margin)
    obs = _close_stations(300)
    rule = ReservationAgent(M, np.random.default_rng(0), points=2, switch_margin_s=margin)
    rule.layout = "DNZHPTG"
    plain = ReservationAgent(M, np.random.default_rng(0), points=2)
    plain.layout = "DNZHPTG"
    current = np.random.default_rng(7).integers(-1, M, len(obs))  # -1: not sent anywhere yet
    mine = [agent.new_episode(np.random.default_rng(i)) for i in range(len(obs))]
    theirs = [FleetRuleEpisode(np.random.default_rng(i)) for i in range(len(obs))]
    for a, b, c in zip(mine, theirs, current, strict=True):
        a.station = b.station = None if c < 0 else int(c)
    seconds = np.minimum(rule.estimate(obs), ESTIMATE_CAP_S)
    # rows where neither the best station nor the margin's comparison is within float32 noise
    order = np.sort(seconds, axis=1)
    gap = seconds[np.arange(len(obs)), np.maximum(current, 0)] - order[:, 0]
    clear = (order[:, 1] > order[:, 0] + 1.0) & (np.abs(gap - margin) > 1.0)
    assert clear.sum() > 200
    chosen = agent.decide(obs, mine)
    np.testing.assert_array_equal(chosen[clear], rule.decide(obs, theirs)[clear])
    kept = clear & (chosen != plain.decide(obs, [FleetRuleEpisode(None) for _ in obs]))
    assert kept.sum() > 10  # the margin changed choices, and the learner changed the same ones
    assert [e.station for e in mine] == chosen.tolist()  # where each EV was sent, for its next tick


def test_in_turn_an_ev_keeps_its_station_within_the_margin_and_the_others_see_it_there() -> None:
    # station 0 is 50 s sooner than station 1 for both EVs; the first was sent to station 1 before
    obs = np.array([[500.0, 1000.0, 9000.0, 0, 0, 0, 0, 0, 0, 0, 1, 0]] * 2, dtype=np.float32)

    def tick(margin: float) -> list[int]:
        agent = _agent("dqn", blocks="DNZH", in_turn=True, network="station", switch_margin_s=margin)
        episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(2)]
        episodes[0].station = 1
        return agent.decide(obs, episodes).tolist()

    assert tick(0.0) == [0, 0]  # both go to the sooner station
    assert tick(600.0) == [1, 0]  # the first stays; the second still counts it at station 1


def test_bad_margins_are_refused_before_anything_runs() -> None:
    with pytest.raises(ValueError, match=r"switch_margin_s=-1\.0: must be a finite number >= 0"):
        _agent(switch_margin_s=-1.0)
    with pytest.raises(ValueError, match=r"switch_margin_s=60\.0 with reward='paper'"):
        _agent(rule_prior=False, reward="paper", switch_margin_s=60.0)
    with pytest.raises(ValueError, match=r"switch_margin_s=60\.0 needs the environment's decision_interval"):
        _agent(rule_prior=False, decision_interval=None, switch_margin_s=60.0)
    _agent(rule_prior=False, reward="paper", switch_margin_s=0.0)  # no margin: any reward


def test_a_run_saved_before_the_margin_existed_resumes_without_one() -> None:
    saved = {"learner": {"lr": 0.001}}
    assert config_diff(saved, {"learner": {"lr": 0.001, "switch_margin_s": 0.0}}) == []
    assert config_diff(saved, {"learner": {"lr": 0.001, "switch_margin_s": 60.0}}) == [
        "learner.switch_margin_s: '<missing>' -> 60.0"
    ]
