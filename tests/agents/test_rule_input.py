"""The rule's estimate as a learner's input (evcd.agents.rule_input, DQNConfig.rule_estimate): the block
against hand-computed seconds (single target and fleet, raw and normalised units), what the network
reads, the fleet's in-turn corrections reaching the block, and checkpoints that keep the setting."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent
from evcd.agents.rule_input import ESTIMATE_CAP_S, ESTIMATE_UNIT_S, RuleEstimate
from evcd.env.observation import unit_divisors
from evcd.utils.checkpoint import CheckpointError, save_checkpoint
from tests.agents.states import saved_options

M = 2
SMALL = {"hidden": (16, 16), "batch_size": 8, "buffer_size": 64, "learning_starts": 1000}
# the rules' defaults: 10 m/s, 2 s per vehicle on the route, 1350 s a charge
SPEED, DELAY, CHARGE = 10.0, 2.0, 1350.0

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _agent(blocks="DNZH", seed: int = 0, **kwargs):
    options = {**SMALL, **kwargs}
    return make_agent("dqn", M, np.random.default_rng(seed), obs_blocks=blocks, points=2, **options)


def test_single_target_block_is_queue_awares_estimate_by_hand() -> None:
    # station 0: 5 km, no traffic, 3 charging (2 points): drive 500 s, backlog (3 - 2 + 1) x 1350 / 2
    # station 1: 1 km, 10 vehicles on the route, empty: drive 100 + 20 s, backlog 0
    obs = np.array([5000.0, 1000.0, 0.0, 10.0, 3.0, 0.0], dtype=np.float32)
    expected = np.array([max(500.0, 2 * CHARGE / 2), 1000 / SPEED + 10 * DELAY]) / ESTIMATE_UNIT_S
    raw = RuleEstimate(M, "DNZ", points=2, normalized=False)
    np.testing.assert_allclose(raw(obs), expected, rtol=1e-6)
    # the same world in the env's normalised units gives the same block
    scaled = (obs / unit_divisors([2, 2], "DNZ")).astype(np.float32)
    np.testing.assert_allclose(RuleEstimate(M, "DNZ", points=2, normalized=True)(scaled), expected, rtol=1e-5)
    batch = np.stack([obs, obs])
    assert raw(batch).shape == (2, M) and raw(batch).dtype == np.float32


def test_fleet_block_counts_g_reads_p_and_t_and_caps_a_closed_station() -> None:
    layout = "DNZHPTG"
    d, n, z, h = [800.0, 900.0], [0.0, 0.0], [1.0, 1.0], [5.0, 0.0]
    p, t, g = [1.0, 0.0], [240.0, 60.0], [2.0, 0.0]
    obs = np.array([*d, *n, *z, *h, *p, *t, *g], dtype=np.float32)
    block = RuleEstimate(M, layout, points=2, normalized=False)(obs)
    # station 0: Z + G = 3 ahead of the one point in service: (3 - 1 + 1) x 1350 / 1, above T = 240 s
    # (H = 5 would say 5); station 1 has no point in service: the closed-station value, capped
    np.testing.assert_allclose(block, [3 * CHARGE / ESTIMATE_UNIT_S, ESTIMATE_CAP_S / ESTIMATE_UNIT_S])
    # without G the fleet's rule counts Z + H; with T the drive is T, not the guess from D and N
    no_g = RuleEstimate(M, "DNZHT", points=2, normalized=False)(np.array([*d, *n, *z, *h, *t], np.float32))
    np.testing.assert_allclose(no_g, [(6 - 2 + 1) * CHARGE / 2 / ESTIMATE_UNIT_S, 60.0 / ESTIMATE_UNIT_S])


def test_the_network_reads_the_block_after_the_observation() -> None:
    agent = _agent("DNZH", network="station", rule_estimate=True)
    assert agent.online.trunk[0].in_features == 5 + M  # D, N, Z, H and the estimate, and the index
    obs = np.array([[500.0, 800.0, 1.0, 2.0, 0.0, 3.0, 1.0, 0.0]] * 3, dtype=np.float32)
    x = agent._input(obs).numpy()
    assert x.shape == (3, 5 * M)
    np.testing.assert_allclose(x[:, 4 * M :], RuleEstimate(M, "DNZH", 2, False)(obs))
    assert agent.q_values(obs).shape == (3, M) and agent.q_values(obs[0]).shape == (M,)
    assert _agent("DNZH").online.trunk[0].in_features == 4 * M  # off by default: the observation alone
    with pytest.raises(ValueError, match="rule_estimate=True needs the stations' charging points"):
        make_agent("dqn", M, np.random.default_rng(0), obs_blocks=4, rule_estimate=True, **SMALL)
    with pytest.raises(ValueError, match="rule_estimate"):
        _agent(rule_estimate="yes")


def test_in_turn_corrections_reach_the_block() -> None:
    # two points per station, nobody there: with b EVs sent to a station before it, an EV reads a
    # backlog of max(0, b - 1) x 1350 / 2 s there (drives of 30 and 40 s): the second EV sent to a
    # station fills its points, the later ones queue
    agent = _agent("DNZH", seed=1, in_turn=True, rule_estimate=True, network="station")
    obs = np.array([[300.0, 400.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]] * 4, dtype=np.float32)
    episodes = [agent.new_episode(np.random.default_rng(i)) for i in range(4)]
    stations = agent.decide(obs, episodes)
    estimate = RuleEstimate(M, "DNZH", 2, False)
    order = np.argsort(-agent.q_values(obs).max(axis=1), kind="stable")
    before = np.zeros(M)
    for j in order:
        seen = episodes[j].seen
        expected = np.maximum([30.0, 40.0], np.maximum(0.0, before - 1) * CHARGE / 2) / ESTIMATE_UNIT_S
        np.testing.assert_allclose(estimate(seen), expected, rtol=1e-6)
        assert stations[j] == agent.q_values(seen).argmax()
        before[stations[j]] += 1
    last = order[-1]  # four EVs on two stations: the last read a queue that the tick did not show
    assert not np.allclose(estimate(episodes[last].seen), estimate(obs[last]))


def test_a_checkpoint_keeps_the_setting_and_refuses_another(tmp_path) -> None:
    agent = _agent("DNZH", rule_estimate=True)
    save_checkpoint(tmp_path, agent.state_dict(), "agent")
    config = saved_options(tmp_path)
    assert config["rule_estimate"] is True
    rebuilt = make_agent("dqn", M, np.random.default_rng(5), obs_blocks=4, points=2, checkpoint=tmp_path,
                         **{**SMALL, **config})  # fmt: skip
    obs = np.array([500.0, 800.0, 1.0, 2.0, 0.0, 3.0, 1.0, 0.0], dtype=np.float32)
    np.testing.assert_array_equal(rebuilt.q_values(obs), agent.q_values(obs))
    with pytest.raises(CheckpointError, match="rule_estimate=True; this one has rule_estimate=False"):
        _agent("DNZH").load_state_dict(agent.state_dict(), policy_only=True)
    # a checkpoint from before the setting existed is a policy without the estimate
    old = _agent("DNZH").state_dict()
    del old["config"]["rule_estimate"]
    plain = _agent("DNZH", seed=3)
    plain.load_state_dict(old, policy_only=True)
    with pytest.raises(CheckpointError, match="rule_estimate=False; this one has rule_estimate=True"):
        _agent("DNZH", rule_estimate=True).load_state_dict(old, policy_only=True)
