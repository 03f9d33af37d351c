"""The rule as the learner's starting point (evcd.agents.rule_prior, DQNConfig.rule_prior): the prior
against the hand-computed return of the time reward, the untrained learner deciding as the rule (every
network, single target and fleet, in turn on the corrected observations), the correction learning from
returns, bad settings refused, and checkpoints that keep the setting and the prior's constants."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from evcd.agents import make_agent
from evcd.agents.base import Transition
from evcd.agents.fleet_rules import ReservationAgent
from evcd.agents.heuristics import QueueAwareAgent
from evcd.agents.rule_input import ESTIMATE_CAP_S, RuleEstimate
from evcd.agents.rule_prior import RulePriorQ, time_return
from evcd.utils.checkpoint import CheckpointError, save_checkpoint
from tests.agents.states import saved_options

M = 3
SMALL = {"hidden": (16, 16), "batch_size": 8, "buffer_size": 64, "learning_starts": 1000}
PRIOR = {"rule_prior": True, "decision_interval": 60.0, "reward": "time", "gamma": 0.9, "reward_scale": 10.0}

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _agent(name="dqn", blocks="DNZHPTG", seed=0, **kwargs):
    options = {**SMALL, **PRIOR, **kwargs}
    return make_agent(name, M, np.random.default_rng(seed), obs_blocks=blocks, points=2, **options)


def _fleet_obs(rows: int, seed: int = 1) -> np.ndarray:
    """Fleet observations ``[D, N, Z, H, P, T, G]`` in physical units: routes of 0.3-5 km, 0-4
    vehicles at a station, 0-2 points in service of 2, other guided EVs due first 0-3."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(300, 5000, (rows, M))
    n = rng.integers(0, 20, (rows, M))
    z = rng.integers(0, 5, (rows, M))
    h = rng.integers(0, 4, (rows, M))
    p = rng.integers(0, 3, (rows, M))
    t = d / rng.uniform(5, 15, (rows, M))
    g = np.minimum(h, rng.integers(0, 4, (rows, M)))
    return np.concatenate([d, n, z, h, p, t, g], axis=1).astype(np.float32)


def test_the_prior_is_the_time_rewards_discounted_return_by_hand() -> None:
    # 10 x (-60 s / 3600) = -1/6 a slot; 150 s are 2.5 slots: -1/6 x (1 - 0.9 ** 2.5) / 0.1
    seconds = torch.tensor([0.0, 120.0, 150.0])
    expected = [0.0, -1 / 6 * (1 + 0.9), -1 / 6 * (1 - 0.9**2.5) / 0.1]
    np.testing.assert_allclose(time_return(seconds, 60.0, 0.9, 10.0).numpy(), expected, rtol=1e-6)
    # undiscounted: minus the hours, scaled
    np.testing.assert_allclose(time_return(seconds, 60.0, 1.0, 10.0).numpy(), -seconds.numpy() / 360.0)
    # the capped estimate (a closed station) is the worst: the return falls with the seconds
    ladder = time_return(torch.tensor([60.0, 600.0, 3600.0, ESTIMATE_CAP_S]), 60.0, 0.9, 10.0)
    assert (ladder.diff() < 0).all()


@pytest.mark.parametrize(("name", "network"), [("dqn", "mlp"), ("dueling_ddqn", "mlp"),
                                               ("dueling_ddqn", "station")])  # fmt: skip
@pytest.mark.parametrize("reads", [False, True], ids=["prior", "prior_and_estimate"])
def test_an_untrained_learner_decides_as_the_fleets_rule(name, network, reads) -> None:
    agent = _agent(name, network=network, rule_estimate=reads)
    obs = _fleet_obs(200)
    rule = ReservationAgent(M, np.random.default_rng(0), points=2)
    rule.layout = "DNZHPTG"
    seconds = np.minimum(rule.estimate(obs), ESTIMATE_CAP_S)
    prior = time_return(torch.from_numpy(seconds), 60.0, 0.9, 10.0).numpy()
    # Q is the prior exactly (the correction starts at zero), whatever the network reads
    np.testing.assert_allclose(agent.q_values(obs), prior, rtol=1e-5, atol=1e-6)
    # so the greedy station is the rule's (Z + G with P and T), wherever the rule's choice is strict
    strict = np.sort(seconds, axis=1)[:, 1] > np.sort(seconds, axis=1)[:, 0] + 1.0
    assert strict.sum() > 150
    episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(len(obs))]
    chosen = agent.decide(obs, episodes)
    np.testing.assert_array_equal(chosen[strict], rule.decide(obs, episodes)[strict])
    correction = agent.online.correction
    assert isinstance(agent.online, RulePriorQ) and correction.trunk[0].in_features in (
        7 * M + (M if reads else 0), 7 + M + (1 if reads else 0))  # fmt: skip


def test_an_untrained_learner_decides_as_queue_aware_on_the_single_target() -> None:
    agent = _agent("dueling_ddqn", blocks="DNZ", network="station")
    rng = np.random.default_rng(4)
    obs = np.concatenate([rng.uniform(300, 6000, (100, M)), rng.integers(0, 30, (100, M)),
                          rng.integers(0, 6, (100, M))], axis=1).astype(np.float32)  # fmt: skip
    rule = QueueAwareAgent(M, np.random.default_rng(0), points=2)
    seconds = rule.estimate(obs)
    strict = np.sort(seconds, axis=1)[:, 1] > np.sort(seconds, axis=1)[:, 0] + 1.0
    np.testing.assert_array_equal(agent.q_values(obs).argmax(1)[strict], seconds.argmin(1)[strict])


def test_in_turn_each_ev_reads_the_prior_of_its_corrected_observation() -> None:
    # nobody at two stations of two points, drives of 30 / 40 / 900 s: the first EVs take the nearest
    # station; once its points are filled the later ones read a backlog there and go on to the second
    agent = _agent("dqn", blocks="DNZH", in_turn=True, network="station")
    obs = np.array([[300.0, 400.0, 9000.0, 0, 0, 0, 0, 0, 0, 0, 0, 0]] * 5, dtype=np.float32)
    episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(5)]
    stations = agent.decide(obs, episodes)
    estimate = RuleEstimate(M, "DNZH", 2, False)
    for j, episode in enumerate(episodes):
        assert stations[j] == np.argmin(estimate(episode.seen))
    assert sorted(np.bincount(stations, minlength=M)) == [0, 2, 3]


def test_the_correction_learns_from_returns() -> None:
    # one observation, station 0 always ends in charging at once with a reward of -0.05 (x10 scale):
    # the prior says otherwise (its estimate is the drive), and after training Q(s, 0) is the return
    agent = _agent("dqn", blocks="DNZH", network="station", learning_starts=8, lr=1e-2, rule_prior=True)
    obs = np.array([1200.0, 600.0, 900.0, 0, 0, 0, 1, 0, 2, 0, 0, 0], dtype=np.float32)
    before = agent.q_values(obs)
    for _ in range(300):
        agent.observe(Transition(obs, 0, -0.05, obs, True, False))
    after = agent.q_values(obs)
    assert abs(after[0] - (-0.5)) < 0.1 < abs(before[0] - (-0.5))
    assert agent.gradient_steps > 200


def test_bad_settings_are_refused_before_anything_runs() -> None:
    with pytest.raises(ValueError, match="rule_prior=True with reward='paper'"):
        _agent(reward="paper")
    with pytest.raises(ValueError, match="rule_prior=True needs the environment's decision_interval"):
        _agent(decision_interval=None)
    with pytest.raises(ValueError, match="rule_estimate=True needs the stations' charging points"):
        make_agent("dqn", M, np.random.default_rng(0), obs_blocks=4, **{**SMALL, **PRIOR})
    with pytest.raises(ValueError, match="rule_prior"):
        _agent(rule_prior="yes")
    with pytest.raises(ValueError, match=r"gamma=1\.5 must be"):
        RulePriorQ(torch.nn.Linear(2, 2), 1, False, 60.0, 1.5, 1.0)


def test_a_checkpoint_keeps_the_setting_and_the_prior_it_was_trained_with(tmp_path) -> None:
    agent = _agent("dueling_ddqn", network="station", rule_estimate=True)
    with torch.no_grad():  # a trained correction
        agent.online.correction.head.bias.fill_(0.25)
    save_checkpoint(tmp_path, agent.state_dict(), "agent")
    config = saved_options(tmp_path)
    assert config["rule_prior"] is True
    # rebuilt for an environment of another slot: the policy adds the prior it was trained with
    options = {**SMALL, **config, "decision_interval": 30.0, "reward": "time"}
    rebuilt = make_agent("dueling_ddqn", M, np.random.default_rng(5), obs_blocks="DNZHPTG", points=2,
                         checkpoint=tmp_path, **options)  # fmt: skip
    obs = _fleet_obs(4)
    np.testing.assert_array_equal(rebuilt.q_values(obs), agent.q_values(obs))
    assert float(rebuilt.online.slot_s) == 60.0
    with pytest.raises(CheckpointError, match="rule_prior=True; this one has rule_prior=False"):
        _agent("dueling_ddqn", network="station", rule_estimate=True, rule_prior=False).load_state_dict(
            agent.state_dict(), policy_only=True)  # fmt: skip
    # a checkpoint from before the setting existed is a policy without the prior
    old = _agent("dqn", rule_prior=False).state_dict()
    del old["config"]["rule_prior"]
    with pytest.raises(CheckpointError, match="rule_prior=False; this one has rule_prior=True"):
        _agent("dqn").load_state_dict(old, policy_only=True)
    _agent("dqn", seed=3, rule_prior=False).load_state_dict(old, policy_only=True)


# ---------------------------------------------------------------------------------------- the bound
def _estimate_input(seconds: list[float]) -> torch.Tensor:
    """A network input (3 zero inputs) whose estimate block is ``seconds``."""
    return torch.cat([torch.zeros(1, M), torch.tensor([seconds]) / 1000.0], dim=1)


def test_a_bounded_correction_moves_the_estimate_by_at_most_its_seconds() -> None:
    # the network's output c moves each station's estimate by bound x tanh(c) seconds: by hand
    head = torch.nn.Sequential(torch.nn.Linear(M, M))  # its output layer is zeroed: Q is the prior
    q = RulePriorQ(head, M, False, 60.0, 0.9, 10.0, bound_s=120.0)
    x = _estimate_input([100.0, 600.0, 3000.0])
    expected = time_return(torch.tensor([[100.0, 600.0, 3000.0]]), 60.0, 0.9, 10.0)
    np.testing.assert_allclose(q(x).detach().numpy(), expected.numpy(), rtol=1e-6)
    with torch.no_grad():
        head[0].bias.copy_(torch.tensor([-10.0, 0.5, 10.0]))  # tanh: -1, 0.462, +1
    moved = torch.tensor([[0.0, 600.0 + 120.0 * np.tanh(0.5), 3120.0]])  # 100 - 120 clamps at 0
    np.testing.assert_allclose(q(x).detach().numpy(), time_return(moved, 60.0, 0.9, 10.0).numpy(), rtol=1e-5)
    # whatever the network outputs, a station the rule puts more than 2 x 120 s later stays behind
    with torch.no_grad():
        head[0].bias.copy_(torch.tensor([1e3, -1e3, -1e3]))
    assert int(q(_estimate_input([100.0, 341.0, 5000.0])).argmax()) == 0


def test_a_bounded_learner_starts_as_the_rule_and_learns_within_its_bound() -> None:
    kwargs = {"blocks": "DNZH", "network": "station"}
    agent = _agent("dqn", learning_starts=8, lr=1e-2, rule_prior_bound_s=300.0, **kwargs)
    plain = _agent("dqn", **kwargs)
    obs = _fleet_obs(50)[:, : 4 * M]
    np.testing.assert_allclose(agent.q_values(obs), plain.q_values(obs), rtol=1e-6)  # untrained: the prior
    # station 2 (two cars for its two points: the rule's 675 s) always ends in charging at once with
    # -0.5 (x10 scale; the return of ~3.4 slots): its estimate falls by the bound, 300 s, and no further
    one = np.array([1200.0, 600.0, 900.0, 0, 0, 0, 1, 0, 2, 0, 0, 0], dtype=np.float32)
    estimate = float(RuleEstimate(M, "DNZH", 2, False)(one)[2]) * 1000.0
    assert estimate == pytest.approx(675.0)
    for _ in range(300):
        agent.observe(Transition(one, 2, -0.05, one, True, False))
    floor = float(time_return(torch.tensor(estimate - 300.0), 60.0, 0.9, 10.0))
    q2 = float(agent.q_values(one)[2])
    assert floor - 1e-4 <= q2 < floor + 0.02 and q2 < -0.5 - 0.25
    assert q2 > float(plain.q_values(one)[2]) + 0.2


def test_the_bound_is_checked_and_kept_by_checkpoints(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"rule_prior_bound_s=300\.0 bounds the correction of rule_prior"):
        _agent(rule_prior=False, rule_prior_bound_s=300.0)
    with pytest.raises(ValueError, match="rule_prior_bound_s"):
        _agent(rule_prior_bound_s=-1.0)
    agent = _agent("dueling_ddqn", network="station", rule_prior_bound_s=300.0)
    save_checkpoint(tmp_path, agent.state_dict(), "agent")
    assert saved_options(tmp_path)["rule_prior_bound_s"] == 300.0
    with pytest.raises(CheckpointError, match=r"bound_s=300\.0; this one has rule_prior_bound_s=None"):
        _agent("dueling_ddqn", network="station").load_state_dict(agent.state_dict(), policy_only=True)
    # a checkpoint from before the setting existed has the additive correction
    old = _agent("dqn").state_dict()
    del old["config"]["rule_prior_bound_s"]
    _agent("dqn", seed=3).load_state_dict(old, policy_only=True)
    with pytest.raises(CheckpointError, match=r"bound_s=None; this one has rule_prior_bound_s=120\.0"):
        _agent("dqn", rule_prior_bound_s=120.0).load_state_dict(old, policy_only=True)


def test_a_relative_correction_moves_each_station_by_its_part_beyond_the_mean_by_hand() -> None:
    head = torch.nn.Sequential(torch.nn.Linear(M, M))
    q = RulePriorQ(head, M, False, 60.0, 0.9, 10.0, bound_s=120.0, relative=True)
    x = _estimate_input([100.0, 600.0, 3000.0])
    # one shift of every station (what a biased estimate teaches) is no correction: the rule's return
    with torch.no_grad():
        head[0].bias.copy_(torch.tensor([-10.0, -10.0, -10.0]))
    expected = time_return(torch.tensor([[100.0, 600.0, 3000.0]]), 60.0, 0.9, 10.0)
    np.testing.assert_allclose(q(x).detach().numpy(), expected.numpy(), rtol=1e-6)
    # each station moves by bound x tanh(c - mean c); below 0 s there is no floor (a return above 0)
    with torch.no_grad():
        head[0].bias.copy_(torch.tensor([-10.0, 0.5, 10.0]))  # mean 1/6
    c = torch.tensor([-10.0, 0.5, 10.0])
    moved = torch.tensor([100.0, 600.0, 3000.0]) + 120.0 * torch.tanh(c - c.mean())
    assert float(moved[0]) < 0.0
    np.testing.assert_allclose(q(x).detach().numpy(), time_return(moved[None], 60.0, 0.9, 10.0).numpy(),
                               rtol=1e-5)  # fmt: skip
    assert float(q(x).detach()[0, 0]) > 0.0


def test_saturated_corrections_keep_the_rules_order_only_when_relative() -> None:
    # every correction at -bound: with the floor, the stations within the bound tie at 0 and the lowest
    # index wins; relative, the shift is none and the rule's nearest station stays the best
    x = _estimate_input([250.0, 100.0, 3000.0])
    for relative, best in [(False, 0), (True, 1)]:
        head = torch.nn.Sequential(torch.nn.Linear(M, M))
        q = RulePriorQ(head, M, False, 60.0, 0.9, 10.0, bound_s=300.0, relative=relative)
        with torch.no_grad():
            head[0].bias.fill_(-20.0)
        assert int(q(x).argmax()) == best


def test_the_relative_setting_is_checked_and_kept_by_checkpoints(tmp_path) -> None:
    with pytest.raises(ValueError, match="rule_prior_relative=true centres the bounded correction"):
        _agent(rule_prior_relative=True)
    agent = _agent("dueling_ddqn", network="station", rule_prior_bound_s=300.0, rule_prior_relative=True)
    obs = _fleet_obs(50)
    plain = _agent("dueling_ddqn", network="station")
    np.testing.assert_allclose(agent.q_values(obs), plain.q_values(obs), rtol=1e-6)  # untrained: the prior
    save_checkpoint(tmp_path, agent.state_dict(), "agent")
    assert saved_options(tmp_path)["rule_prior_relative"] is True
    with pytest.raises(CheckpointError, match="relative=True; this one has rule_prior_relative=False"):
        _agent("dueling_ddqn", network="station", rule_prior_bound_s=300.0).load_state_dict(
            agent.state_dict(), policy_only=True
        )
    # a checkpoint from before the setting existed has the floor
    old = _agent("dqn", rule_prior_bound_s=300.0).state_dict()
    del old["config"]["rule_prior_relative"]
    _agent("dqn", seed=3, rule_prior_bound_s=300.0).load_state_dict(old, policy_only=True)


def test_a_relative_learner_learns_a_stations_order_within_its_bound() -> None:
    # as the bounded learner above: station 2 always ends in charging at once; relative, it still moves
    # its estimate down by at most the bound (the others' corrections are what it is measured against)
    agent = _agent("dqn", blocks="DNZH", network="station", learning_starts=8, lr=1e-2,
                   rule_prior_bound_s=300.0, rule_prior_relative=True)  # fmt: skip
    plain = _agent("dqn", blocks="DNZH", network="station")
    one = np.array([1200.0, 600.0, 900.0, 0, 0, 0, 1, 0, 2, 0, 0, 0], dtype=np.float32)
    for _ in range(300):
        agent.observe(Transition(one, 2, -0.05, one, True, False))
    floor = float(time_return(torch.tensor(675.0 - 300.0), 60.0, 0.9, 10.0))
    q2 = float(agent.q_values(one)[2])
    assert floor - 1e-4 <= q2 and q2 > float(plain.q_values(one)[2]) + 0.2
