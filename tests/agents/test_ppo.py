"""PPOAgent and its arithmetic with real torch networks, without SUMO: GAE and the clipped loss checked
by hand (terminated vs truncated, lam 0 and 1, clipped and unclipped ratios, where the gradient
flows), sampling from each episode's own generator, what an episode adds to the rollout (scaled
rewards, bootstrap from the critic after a truncation, an aborted episode's last decision dropped),
when an update happens and what its gradient is, the registry and validation, state round trips (in
memory and through checkpoint files, resumed exactly with a rollout in progress), the absence of
global random state, and a contextual bandit it must learn."""

from __future__ import annotations

import copy
import math
import re

import numpy as np
import pytest
import torch

from evcd.agents import agent_class, agent_names, make_agent
from evcd.agents.base import Transition
from evcd.agents.dqn import DQNAgent
from evcd.agents.ppo import STATE_FORMAT, PPOAgent, PPOEpisode
from evcd.agents.ppo_config import PPOConfig
from evcd.agents.ppo_loss import LossTerms, gae, ppo_loss
from evcd.env.observation import unit_divisors
from evcd.utils.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from tests.agents.states import np_state_equal, state_equal

M = 3  # stations
OBS_DIM = 3 * M
SMALL = {"hidden": (16, 16), "network": "mlp", "rollout_steps": 1000, "minibatch_size": 8, "epochs": 2}

#: one torch thread (tiny networks: faster), put back after every test
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _agent(seed: int = 0, n_stations: int = M, **kwargs) -> PPOAgent:
    return PPOAgent(n_stations, np.random.default_rng(seed), **{**SMALL, **kwargs})


def _obs(rng: np.random.Generator, n: int | None = None, dim: int = OBS_DIM) -> np.ndarray:
    shape = (dim,) if n is None else (n, dim)
    return rng.uniform(0.0, 5.0, size=shape).astype(np.float32)


def _episodes(agent: PPOAgent, n: int, seed: int = 0) -> list[PPOEpisode]:
    return [agent.new_episode(np.random.default_rng([seed, i])) for i in range(n)]


def _params(*nets: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for net in nets for p in net.parameters()]


def _equal(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return len(a) == len(b) and all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def _value(agent: PPOAgent, obs: np.ndarray) -> float:
    """The critic's value of one raw observation (points=None: the network reads it as given)."""
    with torch.no_grad():
        return float(agent.critic(torch.from_numpy(np.asarray(obs, np.float32)[None])).squeeze())


def _gae_by_hand(rewards, values, bootstrap, gamma, lam) -> tuple[np.ndarray, np.ndarray]:
    """A_t = sum_k (gamma lam)^k delta_{t+k} (the forward sum, not the backward recursion)."""
    v = [*values, bootstrap]
    deltas = [rewards[t] + gamma * v[t + 1] - v[t] for t in range(len(rewards))]
    adv = [
        sum((gamma * lam) ** k * deltas[t + k] for k in range(len(deltas) - t)) for t in range(len(deltas))
    ]
    return np.array(adv), np.array(adv) + np.array(values)


def _play_episode(agent: PPOAgent, obs: np.ndarray, rewards, end: str, seed: int = 0) -> PPOEpisode:
    """One episode through decide/observe (exploring): a decision on each row of ``obs`` but the last,
    which is the last transition's next observation. ``end``: ``"terminated"`` or ``"truncated"`` (the
    last transition's flag), or ``"aborted"`` (one more decision, on the last row, without a
    transition). The episode is not ended."""
    episode = agent.new_episode(np.random.default_rng(seed))
    n = len(rewards)
    for t in range(n):
        action = int(agent.decide(obs[t][None], [episode], explore=True)[0])
        last = t == n - 1
        agent.observe(
            Transition(obs[t], action, rewards[t], obs[t + 1], last and end == "terminated",
                       last and end == "truncated"),
            episode,
        )  # fmt: skip
    if end == "aborted":
        agent.decide(obs[n][None], [episode], explore=True)
    return episode


# -- gae ------------------------------------------------------------------------------------------------

REWARDS = [1.0, -2.0, 0.5]
VALUES = [0.5, 1.0, -0.5]


@pytest.mark.parametrize(
    ("bootstrap", "advantages"),
    [
        # terminated: delta = [1 + .9*1 - .5, -2 + .9*(-.5) - 1, .5 + 0 + .5] = [1.4, -3.45, 1.0];
        # A_2 = 1.0, A_1 = -3.45 + .72 * 1.0 = -2.73, A_0 = 1.4 + .72 * (-2.73) = -0.5656
        (0.0, [-0.5656, -2.73, 1.0]),
        # truncated, V_T = 2: delta_2 = .5 + .9*2 + .5 = 2.8; A_1 = -3.45 + .72 * 2.8 = -1.434,
        # A_0 = 1.4 + .72 * (-1.434) = 0.36752
        (2.0, [0.36752, -1.434, 2.8]),
    ],
)
def test_gae_by_hand(bootstrap, advantages):
    adv, ret = gae(np.array(REWARDS), np.array(VALUES), bootstrap, gamma=0.9, lam=0.8)
    np.testing.assert_allclose(adv, advantages, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ret, np.array(advantages) + VALUES, rtol=0, atol=1e-12)
    assert adv.dtype == np.float64
    assert ret.dtype == np.float64
    by_hand = _gae_by_hand(REWARDS, VALUES, bootstrap, 0.9, 0.8)
    np.testing.assert_allclose(adv, by_hand[0], atol=1e-12)
    np.testing.assert_allclose(ret, by_hand[1], atol=1e-12)


@pytest.mark.parametrize(
    ("bootstrap", "returns"),
    [
        # G_2 = .5, G_1 = -2 + .9 * .5 = -1.55, G_0 = 1 + .9 * (-1.55) = -0.395
        (0.0, [-0.395, -1.55, 0.5]),
        # G_2 = .5 + .9 * 2 = 2.3, G_1 = -2 + .9 * 2.3 = 0.07, G_0 = 1 + .9 * .07 = 1.063
        (2.0, [1.063, 0.07, 2.3]),
    ],
)
def test_gae_with_lambda_one_is_monte_carlo_returns_minus_values(bootstrap, returns):
    adv, ret = gae(np.array(REWARDS), np.array(VALUES), bootstrap, gamma=0.9, lam=1.0)
    np.testing.assert_allclose(ret, returns, atol=1e-12)
    np.testing.assert_allclose(adv, np.array(returns) - VALUES, atol=1e-12)


@pytest.mark.parametrize(
    ("bootstrap", "deltas"),
    [(0.0, [1.4, -3.45, 1.0]), (2.0, [1.4, -3.45, 2.8])],
)
def test_gae_with_lambda_zero_is_the_one_step_td_error(bootstrap, deltas):
    adv, ret = gae(np.array(REWARDS), np.array(VALUES), bootstrap, gamma=0.9, lam=0.0)
    np.testing.assert_allclose(adv, deltas, atol=1e-12)
    # R_t = r_t + gamma V_{t+1}
    np.testing.assert_allclose(ret, [1.0 + 0.9 * 1.0, -2.0 + 0.9 * -0.5, 0.5 + 0.9 * bootstrap], atol=1e-12)


def test_gae_with_gamma_zero_is_the_reward_minus_the_value():
    adv, ret = gae(np.array(REWARDS), np.array(VALUES), 5.0, gamma=0.0, lam=0.95)
    np.testing.assert_allclose(adv, [0.5, -3.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(ret, REWARDS, atol=1e-12)


def test_gae_of_one_step_and_of_no_step():
    adv, ret = gae(np.array([3.0]), np.array([1.0]), 10.0, gamma=0.5, lam=0.7)
    np.testing.assert_allclose(adv, [3.0 + 5.0 - 1.0])
    np.testing.assert_allclose(ret, [8.0])
    adv, ret = gae(np.array([]), np.array([]), 1.0, gamma=0.9, lam=0.9)
    assert adv.shape == ret.shape == (0,)


def test_gae_does_not_change_its_inputs():
    rewards, values = np.array(REWARDS), np.array(VALUES)
    gae(rewards, values, 2.0, gamma=0.9, lam=0.8)
    np.testing.assert_array_equal(rewards, REWARDS)
    np.testing.assert_array_equal(values, VALUES)


@pytest.mark.parametrize(
    ("rewards", "values"),
    [([1.0, 2.0, 3.0], [1.0, 2.0]), ([1.0], [1.0, 2.0]), ([[1.0, 2.0]], [[1.0, 2.0]]), ([1.0], [])],
)
def test_gae_with_mismatched_lengths_raises(rewards, values):
    with pytest.raises(ValueError, match="rewards"):
        gae(np.array(rewards), np.array(values), 0.0, gamma=0.9, lam=0.9)


# -- ppo_loss -------------------------------------------------------------------------------------------

CLIP = 0.2
#: ratio, advantage: inside the range (A > 0, A < 0), above it (A > 0: clipped; A < 0: not), below it
#: (A > 0: not clipped; A < 0: clipped)
RATIOS = [1.1, 1.5, 0.5, 1.5, 0.5, 0.9]
ADVANTAGES = [2.0, 1.0, 1.0, -1.0, -2.0, -0.5]
#: min(rho A, clip(rho) A): 2.2, min(1.5, 1.2), min(.5, .8), min(-1.5, -1.2), min(-1, -1.6), -.45
SURROGATES = [2.2, 1.2, 0.5, -1.5, -1.6, -0.45]
#: whether the sample's gradient goes through rho A (the unclipped side) or is cut by the clip
FLOWS = [True, False, True, True, False, True]
OLD_LOGP = [-1.0, -0.5, -2.0, -1.2, -0.7, -1.5]
NEW_VALUES = [1.0, 2.0, 0.0, -1.0, 0.5, 3.0]
RETURNS = [0.0, 2.0, 1.0, 1.0, 0.5, 2.0]  # V - R = [1, 0, -1, -2, 0, 1]: 0.5 * mean(sq) = 0.5 * 7 / 6
ENTROPY = [1.0, 0.5, 0.8, 1.2, 0.3, 0.2]  # mean 4 / 6


def _loss_inputs() -> dict[str, torch.Tensor]:
    old = torch.tensor(OLD_LOGP, dtype=torch.float64)
    return {
        "new_logp": (old + torch.log(torch.tensor(RATIOS, dtype=torch.float64))).requires_grad_(),
        "old_logp": old,
        "advantages": torch.tensor(ADVANTAGES, dtype=torch.float64),
        "new_values": torch.tensor(NEW_VALUES, dtype=torch.float64, requires_grad=True),
        "returns": torch.tensor(RETURNS, dtype=torch.float64),
        "entropy": torch.tensor(ENTROPY, dtype=torch.float64, requires_grad=True),
    }


def test_ppo_loss_by_hand():
    terms = ppo_loss(**_loss_inputs(), clip=CLIP, value_coef=0.5, entropy_coef=0.1)
    assert isinstance(terms, LossTerms)
    n = len(RATIOS)
    policy = -sum(SURROGATES) / n  # -0.35 / 6
    value = 0.5 * 7.0 / 6.0
    entropy = 4.0 / 6.0
    assert terms.policy == pytest.approx(policy, abs=1e-12)
    assert terms.value == pytest.approx(value, abs=1e-12)
    assert terms.entropy == pytest.approx(entropy, abs=1e-12)
    # total = -7/120 + 0.5 * 70/120 - 0.1 * 80/120 = 20/120
    assert float(terms.total.detach()) == pytest.approx(1.0 / 6.0, abs=1e-12)
    assert float(terms.total.detach()) == pytest.approx(policy + 0.5 * value - 0.1 * entropy, abs=1e-12)
    kl = sum((r - 1.0) - math.log(r) for r in RATIOS) / n
    assert terms.approx_kl == pytest.approx(kl, abs=1e-12)
    assert terms.clip_fraction == pytest.approx(4.0 / 6.0)  # 1.5, 0.5, 1.5, 0.5 are outside [0.8, 1.2]
    for name in ("policy", "value", "entropy", "approx_kl", "clip_fraction"):
        assert type(getattr(terms, name)) is float


@pytest.mark.parametrize(("value_coef", "entropy_coef"), [(0.5, 0.0), (1.0, 0.01), (0.0, 0.5)])
def test_ppo_loss_weights_its_terms(value_coef, entropy_coef):
    terms = ppo_loss(**_loss_inputs(), clip=CLIP, value_coef=value_coef, entropy_coef=entropy_coef)
    expected = -sum(SURROGATES) / 6 + value_coef * 0.5 * 7 / 6 - entropy_coef * 4 / 6
    assert float(terms.total.detach()) == pytest.approx(expected, abs=1e-12)
    # the reported terms do not depend on the weights
    assert terms.value == pytest.approx(0.5 * 7 / 6, abs=1e-12)
    assert terms.entropy == pytest.approx(4 / 6, abs=1e-12)


def test_ppo_loss_defaults_weigh_the_value_by_half_and_drop_the_entropy():
    terms = ppo_loss(**_loss_inputs(), clip=CLIP)
    assert float(terms.total.detach()) == pytest.approx(-sum(SURROGATES) / 6 + 0.5 * 0.5 * 7 / 6, abs=1e-12)


def test_ppo_loss_gradient_flows_only_through_the_unclipped_side():
    inputs = _loss_inputs()
    value_coef, entropy_coef = 0.5, 0.1
    ppo_loss(**inputs, clip=CLIP, value_coef=value_coef, entropy_coef=entropy_coef).total.backward()
    n = len(RATIOS)
    # d(-mean(rho A))/d new_logp_i = -rho_i A_i / n where the unclipped side is the minimum, else 0
    expected = [-r * a / n if flows else 0.0 for r, a, flows in zip(RATIOS, ADVANTAGES, FLOWS, strict=True)]
    np.testing.assert_allclose(inputs["new_logp"].grad.numpy(), expected, atol=1e-12)
    assert [g != 0 for g in inputs["new_logp"].grad.tolist()] == FLOWS
    diffs = np.array(NEW_VALUES) - np.array(RETURNS)
    np.testing.assert_allclose(inputs["new_values"].grad.numpy(), value_coef * diffs / n, atol=1e-12)
    np.testing.assert_allclose(inputs["entropy"].grad.numpy(), [-entropy_coef / n] * n, atol=1e-12)
    assert inputs["old_logp"].grad is None


def test_ppo_loss_at_the_old_policy_is_the_advantage_weighted_policy_gradient():
    """ratio 1: no clipping, KL 0, and the policy gradient is -A / n (the vanilla policy gradient)."""
    old = torch.tensor(OLD_LOGP, dtype=torch.float64)
    new = old.clone().requires_grad_()
    adv = torch.tensor(ADVANTAGES, dtype=torch.float64)
    terms = ppo_loss(new, old, adv, torch.zeros(6), torch.zeros(6), torch.zeros(6), clip=0.1)
    assert terms.approx_kl == 0.0
    assert terms.clip_fraction == 0.0
    assert terms.policy == pytest.approx(-sum(ADVANTAGES) / 6, abs=1e-12)
    terms.total.backward()
    np.testing.assert_allclose(new.grad.numpy(), -np.array(ADVANTAGES) / 6, atol=1e-12)


def test_ppo_loss_approx_kl_is_non_negative_and_grows_with_the_change():
    old = torch.full((4,), -1.0)
    kls = []
    for shift in (0.0, 0.05, 0.3, 1.0):
        new = old + torch.tensor([shift, -shift, shift, -shift])
        kls.append(ppo_loss(new, old, torch.ones(4), torch.zeros(4), torch.zeros(4), torch.zeros(4),
                            clip=0.2).approx_kl)  # fmt: skip
    assert kls[0] == 0.0
    assert all(k >= 0 for k in kls)  # float32 rounding aside (see the update test below)
    assert kls == sorted(kls)
    assert kls[1] < kls[2] < kls[3]


# -- acting ---------------------------------------------------------------------------------------------


def test_explore_false_takes_the_most_probable_station_and_stores_nothing():
    agent = _agent(hidden=(16,))
    obs = _obs(np.random.default_rng(1), 200)
    probs = agent.probabilities(obs)
    assert probs.shape == (200, M)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, atol=1e-6)
    episodes = _episodes(agent, 200)
    rng_states = [ep.rng.bit_generator.state for ep in episodes]
    actions = agent.decide(obs, episodes, explore=False)
    assert actions.dtype == np.int64
    np.testing.assert_array_equal(actions, probs.argmax(axis=1))
    assert len(set(actions.tolist())) > 1  # the argmax moves with the observation: not a constant
    for ep, state in zip(episodes, rng_states, strict=True):
        assert ep.obs == ep.actions == ep.logp == ep.values == ep.rewards == []
        assert ep.rng.bit_generator.state == state  # no draw


def test_probabilities_are_the_softmax_of_the_actor():
    agent = _agent()
    obs = _obs(np.random.default_rng(2), 7)
    with torch.no_grad():
        logits = agent.actor(torch.from_numpy(obs)).double().numpy()
    expected = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    np.testing.assert_allclose(agent.probabilities(obs), expected, rtol=1e-5)
    np.testing.assert_allclose(agent.probabilities(obs[0]), expected[0], rtol=1e-5)


def _inverse_cdf(probs: np.ndarray, u: float) -> int:
    """The station whose cumulative probability first exceeds ``u`` (inverse-CDF sampling)."""
    return int(min(np.searchsorted(np.cumsum(probs), u * probs.sum(), side="right"), len(probs) - 1))


def test_exploring_draws_come_from_each_episodes_own_generator():
    agent = _agent(hidden=(16,))
    obs = _obs(np.random.default_rng(3), 300)
    agent_rng = agent.rng.bit_generator.state
    first = agent.decide(obs, _episodes(agent, 300, seed=4), explore=True)
    again = agent.decide(obs, _episodes(agent, 300, seed=4), explore=True)
    other = agent.decide(obs, _episodes(agent, 300, seed=5), explore=True)
    np.testing.assert_array_equal(first, again)
    assert (first != other).any()
    assert agent.rng.bit_generator.state == agent_rng  # the agent's own generator is not drawn from
    # one uniform draw of the episode's generator, by inverse CDF of the policy's probabilities
    probs = agent.probabilities(obs)
    expected = [_inverse_cdf(probs[i], np.random.default_rng([4, i]).random()) for i in range(300)]
    assert np.mean(first == np.array(expected)) > 0.99  # ties at a boundary of the CDF aside
    # an episode's draw does not depend on the others deciding beside it
    alone = [int(agent.decide(obs[i][None], [agent.new_episode(np.random.default_rng([4, i]))], True)[0])
             for i in range(20)]  # fmt: skip
    assert alone == first[:20].tolist()


def test_exploring_frequencies_match_the_probabilities():
    agent = _agent(hidden=(16,))
    obs = _obs(np.random.default_rng(6))
    probs = agent.probabilities(obs)
    assert probs.max() - probs.min() > 0.2  # far from uniform
    assert probs.min() > 0.05  # and every station drawn often
    n = 6000
    actions = agent.decide(np.repeat(obs[None], n, axis=0), _episodes(agent, n, seed=7), explore=True)
    freq = np.bincount(actions, minlength=M) / n
    # 4 standard errors of a frequency out of 6000 draws
    np.testing.assert_allclose(freq, probs, atol=4 * math.sqrt(0.25 / n))


def test_exploring_keeps_each_decision_in_its_episode():
    agent = _agent()
    rng = np.random.default_rng(8)
    episodes = _episodes(agent, 4)
    obs_steps = [_obs(rng, 4) for _ in range(3)]
    taken = [agent.decide(obs, episodes, explore=True) for obs in obs_steps]
    for j, ep in enumerate(episodes):
        assert isinstance(ep, PPOEpisode)
        assert len(ep.obs) == len(ep.actions) == len(ep.logp) == len(ep.values) == 3
        assert ep.rewards == []
        for t in range(3):
            np.testing.assert_array_equal(ep.obs[t], obs_steps[t][j])
            assert ep.actions[t] == taken[t][j]
            probs = agent.probabilities(obs_steps[t][j])
            assert ep.logp[t] == pytest.approx(math.log(probs[ep.actions[t]]), abs=1e-5)
            assert ep.values[t] == pytest.approx(_value(agent, obs_steps[t][j]), abs=1e-6)
    # the stored observation is a copy: changing the caller's array afterwards does not reach it
    obs_steps[0][0] += 100.0
    assert episodes[0].obs[0].max() <= 5.0


@pytest.mark.parametrize("obs", [np.zeros((1, OBS_DIM + 1)), np.zeros((1, 2 * M))])
def test_wrong_observation_shape_raises(obs):
    agent = _agent()
    with pytest.raises(ValueError, match="shape"):
        agent.decide(obs.astype(np.float32), _episodes(agent, 1))
    with pytest.raises(ValueError, match="shape"):
        agent.probabilities(obs.astype(np.float32))


@pytest.mark.parametrize("obs", [np.zeros((2, OBS_DIM)), np.zeros(OBS_DIM)])
def test_one_observation_row_per_episode(obs):
    agent = _agent()
    with pytest.raises(ValueError, match="episodes"):
        agent.decide(obs.astype(np.float32), _episodes(agent, 3))


def test_act_decides_for_the_current_episode():
    agent = _agent()
    obs = _obs(np.random.default_rng(9), 20)
    assert [agent.act(o) for o in obs] == agent.probabilities(obs).argmax(axis=1).tolist()
    agent.begin_episode(np.random.default_rng([10, 0]))
    explored = [agent.act(o, explore=True) for o in obs]
    assert len(agent.episode.actions) == 20
    episode = agent.new_episode(np.random.default_rng([10, 0]))
    assert explored == [int(agent.decide(o[None], [episode], explore=True)[0]) for o in obs]


def test_fleet_observations_are_accepted_with_four_blocks():
    agent = _agent(obs_blocks=4, network="station")
    obs = _obs(np.random.default_rng(11), 5, dim=4 * M)
    assert agent.obs_dim == 4 * M
    assert agent.decide(obs, _episodes(agent, 5), explore=True).shape == (5,)
    with pytest.raises(ValueError, match="shape"):
        agent.decide(_obs(np.random.default_rng(11), 5), _episodes(agent, 5))


def test_observations_are_scaled_before_the_network():
    points = [2, 1, 4]
    agent = _agent(points=points)
    np.testing.assert_allclose(agent.inputs.scale, 1.0 / unit_divisors(points, 3), rtol=1e-6)
    raw = np.random.default_rng(12).uniform(0, 3000, size=(6, OBS_DIM)).astype(np.float32)
    with torch.no_grad():
        logits = agent.actor(torch.from_numpy(raw * agent.inputs.scale)).double().numpy()
    expected = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    np.testing.assert_allclose(agent.probabilities(raw), expected, rtol=1e-5, atol=1e-9)


# -- the rollout ----------------------------------------------------------------------------------------

EPISODE = {"gamma": 0.9, "gae_lambda": 0.8, "reward_scale": 2.0}


def _episode_obs(seed: int = 13) -> np.ndarray:
    return _obs(np.random.default_rng(seed), 4)  # three decisions and the last next observation


def test_a_terminated_episode_adds_its_transitions_with_gae_of_its_scaled_rewards():
    agent = _agent(**EPISODE)
    obs = _episode_obs()
    rewards = [1.0, -0.5, 0.25]
    episode = _play_episode(agent, obs, rewards, "terminated")
    assert episode.rewards == [2.0, -1.0, 0.5]  # reward_scale 2
    assert episode.terminated
    values = list(episode.values)
    np.testing.assert_allclose(values, [_value(agent, o) for o in obs[:3]], atol=1e-6)
    actions, logp = list(episode.actions), list(episode.logp)
    agent.end_episode(episode)

    rollout = agent.rollout
    assert len(rollout["actions"]) == 3
    np.testing.assert_array_equal(np.stack(rollout["obs"]), obs[:3])
    assert rollout["actions"] == actions
    np.testing.assert_allclose(rollout["logp"], logp)
    probs = agent.probabilities(obs[:3])
    np.testing.assert_allclose(rollout["logp"], np.log(probs[np.arange(3), actions]), atol=1e-5)
    adv, ret = _gae_by_hand([2.0, -1.0, 0.5], values, 0.0, 0.9, 0.8)
    np.testing.assert_allclose(rollout["advantages"], adv, atol=1e-9)
    np.testing.assert_allclose(rollout["returns"], ret, atol=1e-9)
    np.testing.assert_allclose(
        rollout["advantages"], gae(np.array([2.0, -1.0, 0.5]), np.array(values), 0.0, 0.9, 0.8)[0]
    )
    assert agent.stats() == {"transitions": 3.0, "episodes": 1.0, "updates": 0.0, "gradient_steps": 0.0,
                             "rollout": 3.0}  # fmt: skip


@pytest.mark.parametrize("end", ["truncated", "aborted"])
def test_an_episode_that_did_not_terminate_bootstraps_from_the_critic(end):
    """A truncation bootstraps from V(last next_obs); an aborted episode (a last decision the target
    could not be observed after) drops that decision and bootstraps from the observation it was made
    on, the last transition's next observation."""
    agent = _agent(**EPISODE)
    obs = _episode_obs()
    rewards = [1.0, -0.5, 0.25] if end == "truncated" else [1.0, -0.5]
    episode = _play_episode(agent, obs, rewards, end)
    n = len(rewards)
    assert len(episode.actions) == 3  # aborted: 2 transitions after 3 decisions
    assert len(episode.rewards) == n
    assert not episode.terminated
    values, actions, logp = list(episode.values[:n]), list(episode.actions[:n]), list(episode.logp[:n])
    bootstrap = _value(agent, obs[n])
    agent.end_episode(episode)

    rollout = agent.rollout
    assert len(rollout["actions"]) == n
    np.testing.assert_array_equal(np.stack(rollout["obs"]), obs[:n])
    assert rollout["actions"] == actions
    np.testing.assert_allclose(rollout["logp"], logp)
    scaled = [2.0 * r for r in rewards]
    adv, ret = _gae_by_hand(scaled, values, bootstrap, 0.9, 0.8)
    np.testing.assert_allclose(rollout["advantages"], adv, atol=1e-6)
    np.testing.assert_allclose(rollout["returns"], ret, atol=1e-6)
    not_bootstrapped = _gae_by_hand(scaled, values, 0.0, 0.9, 0.8)[0]
    assert np.abs(not_bootstrapped - adv).min() > 1e-3  # the test tells the two apart
    assert agent.stats()["transitions"] == n
    assert agent.stats()["episodes"] == 1


def test_an_episode_without_a_transition_adds_nothing():
    agent = _agent()
    episode = agent.new_episode(np.random.default_rng(0))
    agent.decide(_obs(np.random.default_rng(1), 1), [episode], explore=True)
    agent.end_episode(episode)
    assert agent.rollout["actions"] == []
    assert agent.stats()["episodes"] == 1
    assert agent.stats()["transitions"] == 0


def test_episodes_in_a_batch_are_kept_apart():
    """Two episodes decided together, ended in the other order: each adds its own transitions."""
    agent = _agent(**EPISODE)
    rng = np.random.default_rng(14)
    obs = [_obs(rng, 2) for _ in range(3)]
    episodes = _episodes(agent, 2)
    for t in range(2):
        actions = agent.decide(obs[t], episodes, explore=True)
        for j in range(2):
            agent.observe(Transition(obs[t][j], int(actions[j]), float(j + t), obs[t + 1][j], t == 1, False),
                          episodes[j])  # fmt: skip
    values = [list(ep.values) for ep in episodes]
    agent.end_episode(episodes[1])
    agent.end_episode(episodes[0])
    np.testing.assert_array_equal(
        np.stack(agent.rollout["obs"]), [obs[0][1], obs[1][1], obs[0][0], obs[1][0]]
    )
    expected = [*_gae_by_hand([2.0, 4.0], values[1], 0.0, 0.9, 0.8)[0],
                *_gae_by_hand([0.0, 2.0], values[0], 0.0, 0.9, 0.8)[0]]  # fmt: skip
    np.testing.assert_allclose(agent.rollout["advantages"], expected, atol=1e-9)


@pytest.mark.parametrize(
    ("rollout_steps", "minibatch_size", "epochs", "length"),
    [(10, 4, 3, 3), (7, 5, 2, 2), (6, 6, 1, 3), (5, 64, 2, 1)],
)
def test_an_update_happens_once_the_rollout_is_full(rollout_steps, minibatch_size, epochs, length):
    agent = _agent(rollout_steps=rollout_steps, minibatch_size=minibatch_size, epochs=epochs)
    rng = np.random.default_rng(15)
    before = _params(agent.actor, agent.critic)
    per_update = math.ceil(rollout_steps / length)  # episodes that fill the rollout
    n = per_update * length  # transitions in the rollout at the update
    for i in range(per_update):
        assert agent.stats()["updates"] == 0
        assert agent.stats()["rollout"] == i * length
        obs = _obs(rng, length + 1)
        rewards = rng.uniform(-1, 1, size=length).tolist()
        agent.end_episode(_play_episode(agent, obs, rewards, "terminated", seed=i))
        if i < per_update - 1:
            assert _equal(_params(agent.actor, agent.critic), before)
    stats = agent.stats()
    assert stats["updates"] == 1
    assert stats["gradient_steps"] == epochs * math.ceil(n / minibatch_size)
    assert stats["rollout"] == 0
    assert all(agent.rollout[k] == [] for k in agent.rollout)
    assert stats["transitions"] == n
    assert stats["episodes"] == per_update
    after = _params(agent.actor, agent.critic)
    n_actor = len(list(agent.actor.parameters()))
    assert not _equal(after[:n_actor], before[:n_actor])  # the actor learned
    assert not _equal(after[n_actor:], before[n_actor:])  # and the critic
    scalars = agent.scalars()
    assert set(scalars) == {"losses/policy", "losses/value", "losses/entropy", "charts/approx_kl",
                            "charts/clip_fraction"}  # fmt: skip
    assert all(math.isfinite(v) for v in scalars.values())
    assert scalars["charts/approx_kl"] >= -1e-6  # non-negative up to float32 rounding of exp
    assert 0 <= scalars["charts/clip_fraction"] <= 1
    assert 0 < scalars["losses/entropy"] <= math.log(M) + 1e-6


def test_updates_go_on_rollout_after_rollout():
    agent = _agent(rollout_steps=4, minibatch_size=3, epochs=2)
    assert agent.scalars() == {}
    rng = np.random.default_rng(16)
    for i in range(9):  # episodes of 2 transitions: an update after every second one
        agent.end_episode(_play_episode(agent, _obs(rng, 3), [1.0, -1.0], "terminated", seed=i))
        assert agent.stats()["updates"] == (i + 1) // 2
        assert agent.stats()["gradient_steps"] == 2 * 2 * ((i + 1) // 2)
        assert agent.stats()["rollout"] == 2 * ((i + 1) % 2)


def test_the_update_step_is_the_gradient_of_the_clipped_loss_by_hand():
    """One epoch, one minibatch holding the whole rollout: the agent's gradient (clipped to
    max_grad_norm) is that of -mean(A rho) + value_coef 0.5 mean((V - R)^2) - entropy_coef mean(H),
    taken by hand on copies of the networks before the update, and Adam steps with it."""
    config = {"rollout_steps": 1000, "minibatch_size": 64, "epochs": 1, "normalize_advantages": False,
              "value_coef": 0.7, "entropy_coef": 0.05, "max_grad_norm": 0.3, "lr": 1e-2}  # fmt: skip
    agent = _agent(**config, **EPISODE)
    rng = np.random.default_rng(17)
    for i in range(3):
        agent.end_episode(_play_episode(agent, _obs(rng, 4), [1.0, -2.0, 0.5], "terminated", seed=i))
    assert agent.stats()["rollout"] == 9
    obs = torch.from_numpy(np.stack(agent.rollout["obs"]))
    actions = torch.tensor(agent.rollout["actions"])
    old_logp = torch.tensor(agent.rollout["logp"], dtype=torch.float32)
    adv = torch.tensor(agent.rollout["advantages"], dtype=torch.float32)
    ret = torch.tensor(agent.rollout["returns"], dtype=torch.float32)
    actor, critic = copy.deepcopy(agent.actor), copy.deepcopy(agent.critic)
    params = [*actor.parameters(), *critic.parameters()]
    optimizer = torch.optim.Adam(params, lr=1e-2)

    logp_all = torch.log_softmax(actor(obs), dim=-1)
    logp = logp_all.gather(1, actions[:, None]).squeeze(1)
    entropy = -(logp_all.exp() * logp_all).sum(-1)
    loss = (
        -(adv * torch.exp(logp - old_logp)).mean()  # ratio 1: inside the clipping range
        + 0.7 * 0.5 * ((critic(obs).squeeze(-1) - ret) ** 2).mean()
        - 0.05 * entropy.mean()
    )
    loss.backward()
    norm = float(torch.nn.utils.clip_grad_norm_(params, 0.3))
    assert norm > 0.3  # the clipping is exercised
    optimizer.step()

    means = agent.update()
    assert agent.stats()["gradient_steps"] == 1
    assert agent.stats()["updates"] == 1
    assert agent.stats()["rollout"] == 0
    agent_params = [*agent.actor.parameters(), *agent.critic.parameters()]
    for mine, theirs in zip(params, agent_params, strict=True):
        # the last step's gradients are still on the parameters
        torch.testing.assert_close(theirs.grad, mine.grad, rtol=1e-4, atol=1e-6)
        torch.testing.assert_close(theirs.detach(), mine.detach(), rtol=1e-4, atol=1e-6)
    assert means["approx_kl"] == pytest.approx(0.0, abs=1e-6)
    assert means["clip_fraction"] == 0.0
    assert means["policy"] == pytest.approx(-float(adv.mean()), abs=1e-5)
    assert means["entropy"] == pytest.approx(float(entropy.mean().detach()), abs=1e-5)
    assert agent.scalars()["losses/value"] == means["value"]


def test_minibatches_are_drawn_from_the_learn_generator():
    """Two agents alike but for their learn generator shuffle the rollout into other minibatches and
    end apart; the update advances that generator and no other."""
    first = _agent(rollout_steps=1000, minibatch_size=3, epochs=2)
    rng = np.random.default_rng(19)
    for i in range(3):
        first.end_episode(_play_episode(first, _obs(rng, 4), [1.0, -2.0, 0.5], "terminated", seed=i))
    second = _agent(seed=1, rollout_steps=1000, minibatch_size=3, epochs=2)
    second.load_state_dict(first.state_dict())
    second.learn_rng = np.random.default_rng(123)
    agent_rng = first.rng.bit_generator.state
    learn_rng = first.learn_rng.bit_generator.state
    first.update()
    second.update()
    assert first.learn_rng.bit_generator.state != learn_rng
    assert first.rng.bit_generator.state == agent_rng
    assert first.stats() == second.stats()
    assert not _equal(_params(first.actor), _params(second.actor))


def test_a_non_finite_loss_raises():
    agent = _agent(rollout_steps=2, reward_scale=1.0)
    rng = np.random.default_rng(18)
    with pytest.raises(FloatingPointError, match="non-finite"):
        agent.end_episode(_play_episode(agent, _obs(rng, 3), [float("nan"), 1.0], "terminated"))


# -- registry and validation ----------------------------------------------------------------------------


def test_the_registry_makes_a_ppo_agent():
    assert agent_class("ppo") is PPOAgent
    assert "ppo" in agent_names("single")
    assert "ppo" in agent_names("fleet")
    agent = make_agent("ppo", M, np.random.default_rng(0), hidden=[8], lr=1e-3, rollout_steps=64)
    assert isinstance(agent, PPOAgent)
    assert agent.learns
    assert agent.config.hidden == (8,)
    assert agent.config.lr == 1e-3
    assert agent.config.rollout_steps == 64
    assert set(PPOConfig.field_names()) <= set(PPOAgent.option_names())
    assert {"config", "points", "normalized", "obs_blocks", "checkpoint"} <= set(PPOAgent.option_names())
    assert "ppo" in repr(agent).lower()


def test_make_agent_rejects_unknown_options():
    with pytest.raises(ValueError, match="bogus"):
        make_agent("ppo", M, np.random.default_rng(0), bogus=1)


def test_default_settings_are_valid():
    agent = PPOAgent(M, np.random.default_rng(0))
    assert agent.config == PPOConfig()
    np.testing.assert_array_equal(agent.inputs.scale, np.ones(OBS_DIM, np.float32))
    config = PPOConfig(lr=5e-4, gamma=0.5)
    assert PPOAgent(M, np.random.default_rng(0), config).config == config
    assert PPOAgent(M, np.random.default_rng(0), config, gamma=0.7).config == PPOConfig(lr=5e-4, gamma=0.7)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"clip": 0}, "clip=0"),
        ({"clip": -0.1}, "clip=-0.1"),
        ({"gamma": 1.5}, "gamma=1.5"),
        ({"gamma": -0.1}, "gamma=-0.1"),
        ({"gae_lambda": 1.01}, "gae_lambda=1.01"),
        ({"rollout_steps": 0}, "rollout_steps=0"),
        ({"rollout_steps": 2.5}, "rollout_steps=2.5"),
        ({"epochs": 0}, "epochs=0"),
        ({"minibatch_size": 0}, "minibatch_size=0"),
        ({"lr": 0.0}, "lr=0.0"),
        ({"lr": float("nan")}, "lr=nan"),
        ({"max_grad_norm": 0.0}, "max_grad_norm=0.0"),
        ({"reward_scale": 0}, "reward_scale=0"),
        ({"value_coef": -1.0}, "value_coef=-1.0"),
        ({"entropy_coef": -0.01}, "entropy_coef=-0.01"),
        ({"normalize_advantages": "yes"}, "normalize_advantages='yes'"),
        ({"network": "cnn"}, "network='cnn'"),
        ({"hidden": []}, "hidden=[]"),
        ({"hidden": [8, 0]}, "hidden=[8, 0]"),
        ({"bogus": 1}, "bogus"),
        ({"points": [2, 2]}, "points"),
        ({"obs_blocks": 5}, "obs_blocks=5"),
        ({"normalized": True}, "normalized=True"),
        ({"config": {"lr": 1.0}}, "config="),
    ],
)
def test_bad_settings_raise_naming_the_value(kwargs, named):
    with pytest.raises(ValueError) as info:
        _agent(**kwargs)
    assert named in str(info.value)
    if not {"points", "bogus", "obs_blocks", "normalized", "config"} & set(kwargs):
        with pytest.raises(ValueError) as info:
            PPOConfig(**kwargs)
        assert named in str(info.value)
        with pytest.raises(ValueError) as info:
            make_agent("ppo", M, np.random.default_rng(0), **kwargs)
        assert named in str(info.value)


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="n_stations=0"):
        PPOAgent(0, np.random.default_rng(0))
    with pytest.raises(ValueError, match="rng"):
        PPOAgent(M, 0)  # type: ignore[arg-type]


# -- state ----------------------------------------------------------------------------------------------

RESUME = {"hidden": (16, 16), "network": "mlp", "rollout_steps": 16, "minibatch_size": 6, "epochs": 3,
          "lr": 3e-3, "reward_scale": 1.0, "gamma": 0.9}  # fmt: skip
ENDS = ("terminated", "truncated", "aborted")


def _play(agent: PPOAgent, seed: int, episodes: range, group: int = 3) -> list[int]:
    """A toy stream: episodes ``group`` at a time in lockstep (one decide per step for those still
    running, so episodes are in flight across an update), each of 1 to 4 decisions, ending terminated,
    truncated, or aborted (its last decision without a transition); the reward is minus the chosen
    station's Z plus noise. Returns the actions taken."""
    taken: list[int] = []
    for start in range(episodes.start, episodes.stop, group):
        ids = list(range(start, min(start + group, episodes.stop)))
        plans = {}
        for i in ids:
            rng = np.random.default_rng([seed, i])
            length = int(rng.integers(1, 5))
            plans[i] = (_obs(rng, length + 1), rng.normal(size=length), ENDS[int(rng.integers(3))])
        states = {i: agent.new_episode(np.random.default_rng([seed, i, 1])) for i in ids}
        step = 0
        alive = ids
        while alive:
            actions = agent.decide(np.stack([plans[i][0][step] for i in alive]), [states[i] for i in alive],
                                   explore=True)  # fmt: skip
            taken += actions.tolist()
            for i, a in zip(alive, actions.tolist(), strict=True):
                obs, noise, end = plans[i]
                last = step == len(noise) - 1
                if not (last and end == "aborted"):
                    reward = -float(obs[step][2 * M + a]) + float(noise[step])
                    ended = (last and end == "terminated", last and end == "truncated")
                    agent.observe(Transition(obs[step], a, reward, obs[step + 1], *ended), states[i])
                if last:
                    agent.end_episode(states[i])
            step += 1
            alive = [i for i in alive if step < len(plans[i][1])]
    return taken


def _mid_training(seed: int = 30) -> PPOAgent:
    agent = make_agent("ppo", M, np.random.default_rng(seed), **RESUME)
    _play(agent, seed=31, episodes=range(27))  # whole groups: no episode in flight
    assert agent.updates >= 2
    assert agent.stats()["rollout"] > 0  # a rollout in progress
    return agent


def _continue(agent: PPOAgent) -> list[int]:
    return _play(agent, seed=31, episodes=range(27, 57))


def _assert_same_agent(a: PPOAgent, b: PPOAgent) -> None:
    assert a.stats() == b.stats()
    assert a.scalars() == b.scalars()
    assert _equal(_params(a.actor), _params(b.actor))
    assert _equal(_params(a.critic), _params(b.critic))
    assert state_equal(a.optimizer.state_dict(), b.optimizer.state_dict())
    assert a.learn_rng.bit_generator.state == b.learn_rng.bit_generator.state
    assert a.rng.bit_generator.state == b.rng.bit_generator.state
    assert a.rollout["actions"] == b.rollout["actions"]
    for key in ("logp", "advantages", "returns"):  # a saved rollout is float32, as the update reads it
        np.testing.assert_array_equal(np.float32(a.rollout[key]), np.float32(b.rollout[key]))
    np.testing.assert_array_equal(np.float32(a.rollout["obs"]), np.float32(b.rollout["obs"]))


@pytest.mark.parametrize("via", ["memory", "checkpoint"])
def test_restored_agent_continues_exactly(tmp_path, via):
    original = _mid_training()
    state = original.state_dict()
    if via == "checkpoint":
        save_checkpoint(tmp_path, {"format": "evcd.train/1", "agent": state, "episode": 27}, "ckpt_27")
        state = load_checkpoint(tmp_path)["agent"]
    restored = make_agent("ppo", M, np.random.default_rng(999), **RESUME)
    assert not _equal(_params(restored.actor), _params(original.actor))
    restored.load_state_dict(state)
    assert restored.stats() == original.stats()
    assert restored.rollout["actions"] == original.rollout["actions"]
    np.testing.assert_array_equal(np.stack(restored.rollout["obs"]), np.stack(original.rollout["obs"]))

    updates = original.updates
    taken_a = _continue(original)
    taken_b = _continue(restored)
    assert original.updates > updates + 1  # the continuation learns, from the saved rollout on
    assert taken_a == taken_b
    _assert_same_agent(original, restored)


def test_a_fresh_agent_does_not_continue_like_the_trained_one():
    """The counter-test of the resume test: without the state, the same continuation differs."""
    original = _mid_training()
    other = make_agent("ppo", M, np.random.default_rng(999), **RESUME)
    assert _continue(original) != _continue(other)
    assert not _equal(_params(original.actor), _params(other.actor))


def test_a_state_without_its_rollout_does_not_continue_exactly():
    """The rollout in progress matters: dropping it from the state changes the continuation."""
    original = _mid_training()
    state = original.state_dict()
    state["rollout"] = {k: v[:0] for k, v in state["rollout"].items()}
    restored = make_agent("ppo", M, np.random.default_rng(999), **RESUME)
    restored.load_state_dict(state)
    _continue(original)
    _continue(restored)
    assert not _equal(_params(original.actor), _params(restored.actor))


def test_state_dict_is_a_snapshot():
    """A state taken mid-training and loaded only after the original went on (into two agents at
    once) still replays the original's continuation: neither the state nor the agents share data."""
    original = _mid_training()
    state = original.state_dict()
    copied = copy.deepcopy(state)
    taken = _continue(original)
    assert state_equal(state, copied)  # training afterwards did not change it
    first = make_agent("ppo", M, np.random.default_rng(7), **RESUME)
    second = make_agent("ppo", M, np.random.default_rng(8), **RESUME)
    first.load_state_dict(state)
    second.load_state_dict(state)
    assert _continue(first) == taken
    assert _continue(second) == taken
    _assert_same_agent(first, original)
    _assert_same_agent(second, original)
    assert state_equal(state, copied)  # nor did loading it and training the loaded agents


def test_state_dict_is_what_torch_loads_with_weights_only(tmp_path):
    agent = _mid_training()
    path = save_checkpoint(tmp_path, agent.state_dict(), "agent")
    loaded = load_checkpoint(path)
    assert loaded["format"] == STATE_FORMAT
    assert loaded["n_stations"] == M
    assert loaded["obs_dim"] == OBS_DIM
    assert loaded["config"]["hidden"] == [16, 16]
    assert loaded["rng"] == agent.rng.bit_generator.state
    assert loaded["learn_rng"] == agent.learn_rng.bit_generator.state


def test_the_state_neither_holds_nor_sets_torchs_global_generator():
    agent = _mid_training()
    state = agent.state_dict()
    assert not [k for k in state if "torch" in k]
    torch.manual_seed(77)
    before = torch.random.get_rng_state()
    make_agent("ppo", M, np.random.default_rng(1), **RESUME).load_state_dict(state)
    assert torch.equal(torch.random.get_rng_state(), before)


def test_policy_only_loads_just_the_networks():
    trained = _mid_training()
    fresh = make_agent("ppo", M, np.random.default_rng(5), **RESUME)
    optimizer = copy.deepcopy(fresh.optimizer.state_dict())
    learn_rng = fresh.learn_rng.bit_generator.state
    fresh.load_state_dict(trained.state_dict(), policy_only=True)
    assert _equal(_params(fresh.actor), _params(trained.actor))
    assert _equal(_params(fresh.critic), _params(trained.critic))
    assert fresh.stats() == {"transitions": 0.0, "episodes": 0.0, "updates": 0.0, "gradient_steps": 0.0,
                             "rollout": 0.0}  # fmt: skip
    assert state_equal(fresh.optimizer.state_dict(), optimizer)
    assert fresh.learn_rng.bit_generator.state == learn_rng
    assert fresh.scalars() == {}
    obs = _obs(np.random.default_rng(6), 50)
    np.testing.assert_array_equal(fresh.probabilities(obs), trained.probabilities(obs))
    # the policy's part alone loads too, and the full load needs more than it
    other = make_agent("ppo", M, np.random.default_rng(9), **RESUME)
    other.load_state_dict(trained.policy_state_dict(), policy_only=True)
    assert _equal(_params(other.actor), _params(trained.actor))
    assert not {"optimizer", "rollout", "counters", "learn_rng"} & set(trained.policy_state_dict())


def test_a_loaded_policy_sees_what_it_was_trained_on():
    """The checkpoint's input scale wins: a policy trained on raw observations with points (2, 1, 4)
    loaded into an agent without points gives the same probabilities on the same observations."""
    trained = _agent(points=[2, 1, 4])
    raw = np.random.default_rng(7).uniform(0, 3000, size=(20, OBS_DIM)).astype(np.float32)
    other = _agent(seed=3)
    assert not np.allclose(other.probabilities(raw), trained.probabilities(raw))
    other.load_state_dict(trained.state_dict(), policy_only=True)
    np.testing.assert_array_equal(other.inputs.scale, trained.inputs.scale)
    np.testing.assert_allclose(other.probabilities(raw), trained.probabilities(raw), rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"n_stations": 4}, "(4, 12 = layout DNZ, "),
        ({"n_stations": 2}, "(2, 6 = layout DNZ, "),
        ({"hidden": (16, 8)}, "'hidden': [16, 8]"),
        ({"hidden": (16,)}, "'hidden': [16]"),
        ({"network": "station"}, "'network': 'station'"),
        ({"obs_blocks": 4}, "(3, 12 = layout DNZH, "),
    ],
)
@pytest.mark.parametrize("policy_only", [False, True])
def test_load_into_a_mismatched_agent_raises(kwargs, named, policy_only):
    state = _agent(**RESUME).state_dict()
    other = _agent(seed=2, **{**RESUME, **kwargs})
    before = _params(other.actor, other.critic)
    with pytest.raises(CheckpointError, match=re.escape(named)):
        other.load_state_dict(state, policy_only=policy_only)
    assert _equal(_params(other.actor, other.critic), before)


@pytest.mark.parametrize("policy_only", [False, True])
def test_load_rejects_a_state_that_is_not_a_ppo_agent(policy_only):
    agent = _agent()
    before = _params(agent.actor, agent.critic)
    dqn = DQNAgent(M, np.random.default_rng(0), hidden=(16, 16))
    for state in (dqn.state_dict(), dqn.policy_state_dict(), {"format": "evcd.train/1"}, [1, 2]):
        with pytest.raises(CheckpointError, match="not a PPO agent"):
            agent.load_state_dict(state, policy_only=policy_only)  # type: ignore[arg-type]
    assert _equal(_params(agent.actor, agent.critic), before)
    assert isinstance(CheckpointError("x"), ValueError)


@pytest.mark.parametrize("network", ["mlp", "station"])
def test_checkpoint_options_rebuild_an_agent_that_loads_the_policy(tmp_path, network):
    trained = _agent(hidden=(12, 5), network=network)
    save_checkpoint(tmp_path, trained.policy_state_dict(), "policy")
    policy = load_checkpoint(tmp_path)
    options = PPOAgent.checkpoint_options(policy)
    assert options == {"hidden": (12, 5), "network": network}
    assert PPOAgent.checkpoint_options(trained.state_dict()) == options
    rebuilt = make_agent("ppo", M, np.random.default_rng(4), **options)
    rebuilt.load_state_dict(policy, policy_only=True)
    obs = _obs(np.random.default_rng(8), 40)
    np.testing.assert_array_equal(rebuilt.probabilities(obs), trained.probabilities(obs))


def test_checkpoint_options_refuse_a_state_that_is_not_a_ppo_agent():
    dqn = DQNAgent(M, np.random.default_rng(0), hidden=(16, 16))
    for state in (dqn.policy_state_dict(), dqn.state_dict(), {"format": "evcd.train/1"}, {}, [1, 2]):
        with pytest.raises(CheckpointError, match="PPO"):
            PPOAgent.checkpoint_options(state)  # type: ignore[arg-type]


# -- determinism and random state -----------------------------------------------------------------------


def test_same_seed_same_weights_other_seed_differs():
    def trained(seed):
        agent = make_agent("ppo", M, np.random.default_rng(seed), **RESUME)
        return agent, _play(agent, seed=33, episodes=range(30))

    a, taken_a = trained(40)
    b, taken_b = trained(40)
    c, _ = trained(41)
    assert a.updates > 0
    assert taken_a == taken_b
    _assert_same_agent(a, b)
    assert not _equal(_params(a.actor), _params(c.actor))
    assert not _equal(_params(a.critic), _params(c.critic))


def test_no_global_random_state_is_used():
    torch.manual_seed(1234)
    np.random.seed(1234)
    torch_before = torch.random.get_rng_state()
    np_before = np.random.get_state()

    agent = make_agent("ppo", M, np.random.default_rng(0), **RESUME)
    _play(agent, seed=3, episodes=range(20))
    agent.begin_episode(np.random.default_rng(1))
    obs = _obs(np.random.default_rng(2), 5)
    for o in obs:
        agent.act(o, explore=True)
        agent.act(o, explore=False)
    agent.decide(obs, _episodes(agent, 5), explore=True)
    agent.probabilities(obs)
    agent.update()
    agent.load_state_dict(agent.state_dict())
    agent.stats()
    assert agent.updates > 1

    assert torch.equal(torch.random.get_rng_state(), torch_before)
    assert np_state_equal(np.random.get_state(), np_before)


def test_the_initial_weights_do_not_depend_on_torchs_global_generator():
    torch.manual_seed(1)
    a = _agent(seed=5)
    torch.manual_seed(2)
    b = _agent(seed=5)
    assert _equal(_params(a.actor, a.critic), _params(b.actor, b.critic))
    assert not _equal(_params(a.actor), _params(_agent(seed=6).actor))


# -- a toy problem it must learn ------------------------------------------------------------------------


def _bandit(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` observations [D, N, Z] (taken as given: points=None) and the best station of each: the
    smallest Z."""
    obs = rng.uniform(0.0, 5.0, size=(n, OBS_DIM)).astype(np.float32)
    return obs, obs[:, 2 * M :].argmin(axis=1)


def test_it_learns_a_contextual_bandit():
    """One decision per episode: reward 0 for the station with the smallest queue Z, -1 for another
    (terminated after one step). The greedy policy must find the best station on >= 90% of fresh
    observations after 6,400 episodes (a random policy: about 33%)."""
    agent = PPOAgent(M, np.random.default_rng(0), points=None, hidden=(32,), network="mlp", lr=3e-3,
                     rollout_steps=256, minibatch_size=64, epochs=4, reward_scale=1.0,
                     entropy_coef=0.0)  # fmt: skip
    test_obs, test_best = _bandit(np.random.default_rng(1), 2000)

    def accuracy() -> float:
        return float(np.mean(agent.decide(test_obs, _episodes(agent, 2000), explore=False) == test_best))

    assert accuracy() < 0.6
    rng = np.random.default_rng(2)
    batch = 64
    for b in range(100):
        obs, best = _bandit(rng, batch)
        episodes = _episodes(agent, batch, seed=b)
        actions = agent.decide(obs, episodes, explore=True)
        for j, episode in enumerate(episodes):
            reward = 0.0 if actions[j] == best[j] else -1.0
            agent.observe(Transition(obs[j], int(actions[j]), reward, obs[j], True, False), episode)
            agent.end_episode(episode)
    assert agent.updates == 25
    assert accuracy() >= 0.9
