"""DQNAgent mechanics with real torch networks: the registry's switches, the DQN and Double DQN
targets checked by hand (terminated vs truncated), epsilon-greedy exploration (slot and episode),
when and how it learns (learning_starts, train_freq, gradient_steps, hard and soft target updates,
priorities, importance weights, MSE / Huber, gradient clipping, reward and observation scaling),
validation, state round trips (in memory and through checkpoint files), determinism and the absence
of global random state (the state dict neither holds nor sets torch's generator)."""

from __future__ import annotations

import copy
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from evcd.agents import make_agent, make_agent_for_env
from evcd.agents.base import Transition
from evcd.agents.dqn import DQNAgent, DQNConfig, DQNEpisode, linear_schedule
from evcd.agents.networks import DuelingQNetwork, QNetwork
from evcd.agents.q_policy import STATE_FORMAT
from evcd.env.observation import unit_divisors
from evcd.env.runners import SingleEnvRunner
from evcd.loops.seeds import TRAIN_STREAM, episode_specs
from evcd.utils.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from tests.agents.states import np_state_equal, saved_options, state_equal
from tests.agents.toy_env import ToyDispatchEnv

M = 3  # stations
OBS_DIM = 3 * M
SMALL = {"hidden": (16, 16), "batch_size": 8, "buffer_size": 64}


#: one torch thread (tiny networks: faster), put back after every test
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _agent(seed: int = 0, n_stations: int = M, **kwargs) -> DQNAgent:
    return DQNAgent(n_stations, np.random.default_rng(seed), **{**SMALL, **kwargs})


def _decide(agent: DQNAgent, obs: np.ndarray, explore: bool = False, seed: int = 0) -> np.ndarray:
    """One decision for each row of ``obs``, each row an episode of its own (generators from ``seed``)."""
    episodes = [agent.new_episode(np.random.default_rng([seed, i])) for i in range(len(obs))]
    return agent.decide(obs, episodes, explore)


def _obs(rng: np.random.Generator, n: int | None = None, dim: int = OBS_DIM) -> np.ndarray:
    shape = (dim,) if n is None else (n, dim)
    return rng.uniform(0.0, 5.0, size=shape).astype(np.float32)


def _transition(rng, terminated=False, truncated=False, reward=None, n_stations=M) -> Transition:
    dim = 3 * n_stations
    return Transition(
        _obs(rng, dim=dim),
        int(rng.integers(n_stations)),
        float(rng.uniform(-3.0, 3.0) if reward is None else reward),
        _obs(rng, dim=dim),
        terminated,
        truncated,
    )


def _transitions(seed: int, n: int, n_stations: int = M) -> list[Transition]:
    rng = np.random.default_rng(seed)
    return [_transition(rng, terminated=bool(rng.random() < 0.3), n_stations=n_stations) for _ in range(n)]


def _params(net: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in net.parameters()]


def _equal(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return len(a) == len(b) and all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def _perturb(net: torch.nn.Module, seed: int, scale: float = 0.5) -> None:
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(scale * torch.randn(p.shape, generator=gen))


def _head(net: torch.nn.Module) -> torch.nn.Linear:
    return net.advantage if isinstance(net, DuelingQNetwork) else net.head


def _set_head_bias(net: torch.nn.Module, bias: list[float]) -> None:
    """Q(s, .) = ``bias`` for the plain network, ``bias - mean(bias)`` for the dueling one."""
    with torch.no_grad():
        head = _head(net)
        head.weight.zero_()
        head.bias.copy_(torch.tensor(bias))
        if isinstance(net, DuelingQNetwork):
            net.value.weight.zero_()
            net.value.bias.zero_()


def _train(agent: DQNAgent, seed: int, episodes: range, explore: bool = True) -> list:
    runner = SingleEnvRunner(ToyDispatchEnv())
    return runner.run(episode_specs(seed, episodes, TRAIN_STREAM), agent, explore=explore, learn=True)


# -- registry and switches ------------------------------------------------------------------------------


@pytest.mark.slow
def test_registry_names_imply_the_switches():
    dqn = make_agent("dqn", M, np.random.default_rng(0), hidden=[8])
    ddqn = make_agent("dueling_ddqn", M, np.random.default_rng(0), hidden=[8])
    assert type(dqn) is DQNAgent
    assert type(ddqn) is DQNAgent
    assert (dqn.double, dqn.dueling) == (False, False)
    assert (ddqn.double, ddqn.dueling) == (True, True)
    assert type(dqn.policy.online) is QNetwork
    assert type(dqn.policy.target) is QNetwork
    assert type(ddqn.policy.online) is DuelingQNetwork
    assert type(ddqn.policy.target) is DuelingQNetwork
    assert dqn.name == "dqn"
    assert ddqn.name == "dueling_ddqn"
    assert dqn.learns
    assert ddqn.learns
    # the switches, not the registry key, decide the name
    assert make_agent("dqn", M, np.random.default_rng(0), hidden=[8], double=True).name == "ddqn"
    assert DQNAgent(M, np.random.default_rng(0), hidden=[8], dueling=True).name == "dueling_dqn"


def test_make_agent_rejects_unknown_options():
    with pytest.raises(ValueError, match="bogus_option"):
        make_agent("dqn", M, np.random.default_rng(0), bogus_option=1)


def test_target_network_starts_as_a_frozen_copy():
    agent = _agent()
    assert _equal(_params(agent.policy.online), _params(agent.policy.target))
    assert all(not p.requires_grad for p in agent.policy.target.parameters())
    assert all(p.requires_grad for p in agent.policy.online.parameters())
    assert agent.policy.online is not agent.policy.target


# -- TD targets -----------------------------------------------------------------------------------------


def _discounts(agent: DQNAgent, rewards: torch.Tensor) -> torch.Tensor:
    """One-step transitions: the bootstrap is worth gamma."""
    return torch.full_like(rewards, agent.config.gamma)


def _batch(seed: int, n: int = 16):
    rng = np.random.default_rng(seed)
    rewards = torch.from_numpy(rng.uniform(-2, 2, n).astype(np.float32))
    next_obs = torch.from_numpy(_obs(rng, n))
    terminated = torch.from_numpy((rng.random(n) < 0.4).astype(np.float32))
    assert 0 < terminated.sum() < n
    return rewards, next_obs, terminated


@pytest.mark.slow
@pytest.mark.parametrize("dueling", [False, True])
def test_double_target_by_hand(dueling):
    agent = _agent(double=True, dueling=dueling, hidden=(8, 8), gamma=0.9)
    _perturb(agent.policy.target, seed=1)
    rewards, next_obs, terminated = _batch(2)
    with torch.no_grad():
        q_online, q_target = agent.policy.online(next_obs), agent.policy.target(next_obs)
    best = q_online.argmax(dim=1)
    expected = rewards + 0.9 * (1 - terminated) * q_target[torch.arange(16), best]
    torch.testing.assert_close(
        agent.td_targets(rewards, next_obs, terminated, _discounts(agent, rewards)), expected
    )
    # the online and target networks really disagree here, so the choice of network matters
    assert not torch.allclose(q_online, q_target)


@pytest.mark.parametrize("dueling", [False, True])
def test_plain_target_is_the_max_of_the_target_network(dueling):
    agent = _agent(double=False, dueling=dueling, hidden=(8, 8), gamma=0.8)
    _perturb(agent.policy.target, seed=3)
    rewards, next_obs, terminated = _batch(4)
    with torch.no_grad():
        q_target, q_online = agent.policy.target(next_obs), agent.policy.online(next_obs)
    expected = rewards + 0.8 * (1 - terminated) * q_target.max(dim=1).values
    got = agent.td_targets(rewards, next_obs, terminated, _discounts(agent, rewards))
    torch.testing.assert_close(got, expected)
    assert not torch.allclose(got, rewards + 0.8 * (1 - terminated) * q_online.max(dim=1).values)


@pytest.mark.parametrize("dueling", [False, True])
def test_double_and_plain_targets_differ_when_the_argmaxes_disagree(dueling):
    """Online prefers action 0, the target network values action 1 most: Double DQN bootstraps from
    ``Q_target(s', 0)``, DQN from ``max Q_target(s', .) = Q_target(s', 1)``."""
    plain = _agent(seed=5, double=False, dueling=dueling, hidden=(8,), gamma=0.5)
    double = _agent(seed=5, double=True, dueling=dueling, hidden=(8,), gamma=0.5)
    for agent in (plain, double):
        _set_head_bias(agent.policy.online, [1.0, 0.0, 0.0])
        _set_head_bias(agent.policy.target, [0.0, 5.0, 2.0])
    rewards, next_obs, terminated = _batch(6)
    with torch.no_grad():
        q_target = double.policy.target(next_obs)
        q_online = double.policy.online(next_obs)
    assert (q_online.argmax(dim=1) == 0).all()
    assert (q_target.argmax(dim=1) == 1).all()
    t_plain = plain.td_targets(rewards, next_obs, terminated, _discounts(plain, rewards))
    t_double = double.td_targets(rewards, next_obs, terminated, _discounts(double, rewards))
    torch.testing.assert_close(t_plain, rewards + 0.5 * (1 - terminated) * q_target[:, 1])
    torch.testing.assert_close(t_double, rewards + 0.5 * (1 - terminated) * q_target[:, 0])
    live = terminated == 0
    assert (t_plain[live] > t_double[live] + 1.0).all()
    torch.testing.assert_close(t_plain[~live], t_double[~live])  # both just the reward
    torch.testing.assert_close(t_plain[~live], rewards[~live])


@pytest.mark.parametrize("double", [False, True])
@pytest.mark.parametrize(
    ("terminated", "truncated", "bootstraps"),
    [(True, False, False), (False, True, True), (False, False, True), (True, True, False)],
)
def test_only_termination_cuts_the_bootstrap(double, terminated, truncated, bootstraps):
    """One stored transition, a batch of one: the returned loss is ``(Q(s, a) - y)^2`` with ``y`` the
    reward alone for a terminated transition and the bootstrapped target for a truncated one."""
    agent = _agent(
        seed=7, double=double, batch_size=1, buffer_size=4, learning_starts=10**6, gamma=0.7,
        reward_scale=0.5, max_grad_norm=None,
    )  # fmt: skip
    _set_head_bias(agent.policy.target, [2.0, 9.0, 4.0])  # Q_target(s', .) is known whatever s'
    _set_head_bias(agent.policy.online, [0.5, 0.0, 3.0])  # and Q_online(s', .) too: argmax 2
    rng = np.random.default_rng(8)
    t = Transition(_obs(rng), 1, 3.0, _obs(rng), terminated, truncated)
    agent.observe(t)
    assert agent.gradient_steps == 0
    bootstrap = (4.0 if double else 9.0) if bootstraps else 0.0
    y = 0.5 * 3.0 + 0.7 * bootstrap
    q = 0.0  # Q_online(s, 1)
    assert agent.learn() == pytest.approx((q - y) ** 2, rel=1e-6)


# -- n-step returns -------------------------------------------------------------------------------------


def _stored(agent: DQNAgent) -> list[tuple]:
    """The replay's transitions in the order stored: (obs[0], reward, next_obs[0], terminated,
    truncated, discount)."""
    s = agent.replay.state_dict()
    columns = (s["obs"][:, 0], s["rewards"], s["next_obs"][:, 0], s["terminated"], s["truncated"],
               s["discounts"])  # fmt: skip
    kinds = (float, float, float, bool, bool, float)
    return [tuple(kind(c[i]) for kind, c in zip(kinds, columns, strict=True)) for i in range(s["size"])]


def _chain(start: int, rewards: list[float], end: str | None) -> list[Transition]:
    """Transitions s_k -> s_k+1 with obs[0] = k (to tell them apart) and the given rewards; the last
    one terminated (``end="terminated"``) or truncated, or neither (``None``)."""
    out = []
    for k, r in enumerate(rewards):
        last = k == len(rewards) - 1
        obs, nxt = np.full(OBS_DIM, start + k, np.float32), np.full(OBS_DIM, start + k + 1, np.float32)
        out.append(Transition(obs, 0, r, nxt, last and end == "terminated", last and end == "truncated"))
    return out


def test_n_step_transitions_by_hand():
    """n = 3, gamma 0.5: each stored transition sums the next three rewards and bootstraps from the
    observation three steps on at 0.125; near the end of an episode it sums what is left, the
    termination cutting the bootstrap and a truncation bootstrapping at gamma ** (steps left)."""
    agent = _agent(n_step=3, gamma=0.5, reward_scale=2.0, learning_starts=10**6)
    terminated = _chain(0, [1.0, 2.0, 4.0, 8.0, 16.0], "terminated")
    for i, t in enumerate(terminated):
        agent.observe(t)
        assert len(agent.replay) == max(0, i - 1) if i < 4 else len(agent.replay) == 5
    assert agent.steps == 5 and not agent.episode.pending
    assert _stored(agent) == [
        (0.0, 2 * (1 + 0.5 * 2 + 0.25 * 4), 3.0, False, False, 0.125),
        (1.0, 2 * (2 + 0.5 * 4 + 0.25 * 8), 4.0, False, False, 0.125),
        (2.0, 2 * (4 + 0.5 * 8 + 0.25 * 16), 5.0, True, False, 0.125),
        (3.0, 2 * (8 + 0.5 * 16), 5.0, True, False, 0.25),
        (4.0, 2 * 16.0, 5.0, True, False, 0.5),
    ]
    # an episode truncated inside the n steps: both transitions bootstrap from its last observation
    for t in _chain(10, [1.0, 3.0], "truncated"):
        agent.observe(t)
    assert _stored(agent)[5:] == [
        (10.0, 2 * (1 + 0.5 * 3), 12.0, False, True, 0.25),
        (11.0, 6.0, 12.0, False, True, 0.5),
    ]


def test_n_step_windows_are_kept_per_episode():
    """Two episodes whose steps interleave (the batched engine): each transition sums its own
    episode's rewards."""
    agent = _agent(n_step=2, gamma=0.5, learning_starts=10**6)
    a, b = agent.new_episode(np.random.default_rng(0)), agent.new_episode(np.random.default_rng(1))
    first, second = _chain(0, [1.0, 2.0, 4.0], "terminated"), _chain(20, [10.0, 20.0], None)
    for ta, tb in zip(first, second, strict=False):
        agent.observe(ta, a)
        agent.observe(tb, b)
    agent.observe(first[2], a)
    assert len(b.pending) == 1 and not a.pending  # b goes on; its last step is not stored yet
    assert _stored(agent) == [
        (0.0, 1 + 0.5 * 2, 2.0, False, False, 0.25),
        (20.0, 10 + 0.5 * 20, 22.0, False, False, 0.25),
        (1.0, 2 + 0.5 * 4, 3.0, True, False, 0.25),
        (2.0, 4.0, 3.0, True, False, 0.5),
    ]


def test_an_episode_ended_without_a_last_transition_stores_its_windows_from_true_observations():
    """The target could no longer be observed after its third decision (the runner hands no
    transition for that slot): ``end_episode`` stores the pending windows, each bootstrapping from the
    last true observation (not terminated, not truncated), at gamma ** (steps in the window)."""
    agent = _agent(n_step=3, gamma=0.5, learning_starts=10**6)
    episode = agent.new_episode(np.random.default_rng(0))
    for t in _chain(0, [1.0, 2.0], None):
        agent.observe(t, episode)
    assert len(agent.replay) == 0 and len(episode.pending) == 2
    agent.end_episode(episode)
    assert not episode.pending
    assert _stored(agent) == [(0.0, 1 + 0.5 * 2, 2.0, False, False, 0.25), (1.0, 2.0, 2.0, False, False, 0.5)]
    agent.end_episode(agent.new_episode(np.random.default_rng(1)))  # an episode without transitions
    assert len(agent.replay) == 2


def test_n_step_target_bootstraps_at_gamma_to_the_n():
    agent = _agent(n_step=3, gamma=0.5, learning_starts=10**6, hidden=(8,))
    _set_head_bias(agent.policy.target, [2.0, 9.0, 4.0])  # max Q_target(s', .) = 9 whatever s'
    for t in _chain(0, [1.0, 1.0, 1.0, 1.0], None):
        agent.observe(t)
    batch = agent.replay.sample(2, np.random.default_rng(0), 1.0)
    targets = agent.td_targets(torch.from_numpy(batch.rewards), agent.policy.inputs(batch.next_obs),
                               torch.from_numpy(batch.terminated.astype(np.float32)),
                               torch.from_numpy(batch.discounts))  # fmt: skip
    torch.testing.assert_close(targets, torch.full((2,), 1.75 + 0.125 * 9.0))


def test_one_step_stores_each_transition_at_once_at_gamma():
    agent = _agent(gamma=0.9, learning_starts=10**6)
    for t in _chain(0, [1.0, 2.0], "terminated"):
        agent.observe(t)
    discount = float(np.float32(0.9))
    assert _stored(agent) == [(0.0, 1.0, 1.0, False, False, discount), (1.0, 2.0, 2.0, True, False, discount)]


# -- exploration ----------------------------------------------------------------------------------------


def test_linear_schedule():
    assert linear_schedule(1.0, 0.1, 10, 0) == 1.0
    assert linear_schedule(1.0, 0.1, 10, 5) == pytest.approx(0.55)
    assert linear_schedule(1.0, 0.1, 10, 10) == pytest.approx(0.1)
    assert linear_schedule(1.0, 0.1, 10, 1000) == pytest.approx(0.1)
    assert linear_schedule(0.4, 1.0, 0, 0) == 1.0
    assert linear_schedule(0.0, 1.0, 4, 1) == pytest.approx(0.25)


def test_epsilon_decays_linearly_per_transition_then_stays():
    agent = _agent(epsilon_start=0.9, epsilon_end=0.2, exploration_steps=7, learning_starts=10**6,
                   beta_start=0.3, beta_steps=5)  # fmt: skip
    rng = np.random.default_rng(0)
    seen = []
    for t in range(12):
        expected = 0.9 + (0.2 - 0.9) * t / 7 if t < 7 else 0.2
        assert agent.epsilon == pytest.approx(expected)
        assert agent.stats()["epsilon"] == pytest.approx(expected)
        assert agent.beta == pytest.approx(min(1.0, 0.3 + 0.7 * t / 5))
        seen.append(agent.epsilon)
        agent.act(_obs(rng), explore=True)  # acting does not advance the schedule
        assert agent.epsilon == pytest.approx(expected)
        agent.observe(_transition(rng))
    assert seen[0] > seen[3] > seen[6] > seen[7] == seen[11]


def test_explore_false_is_argmax_even_at_epsilon_one():
    for exploration in ("slot", "episode"):
        agent = _agent(epsilon_start=1.0, epsilon_end=1.0, exploration=exploration)
        agent.begin_episode(np.random.default_rng(1))
        obs = _obs(np.random.default_rng(2), 200)
        greedy = agent.q_values(obs).argmax(axis=1)
        assert len(set(greedy.tolist())) > 1  # a network whose argmax depends on the observation
        assert [agent.act(o, explore=False) for o in obs] == greedy.tolist()
        np.testing.assert_array_equal(_decide(agent, obs, explore=False), greedy)


@pytest.mark.slow
def test_epsilon_one_is_uniform():
    agent = _agent(epsilon_start=1.0, epsilon_end=1.0)
    agent.begin_episode(np.random.default_rng(3))
    obs = _obs(np.random.default_rng(4))
    n = 6000
    actions = np.array([agent.act(obs, explore=True) for _ in range(n)])
    counts = np.bincount(actions, minlength=M)
    assert counts.sum() == n
    # each station 1/3 of the draws: 4 standard deviations is about 0.024
    np.testing.assert_allclose(counts / n, 1 / M, atol=0.03)
    batch = _decide(agent, np.repeat(obs[None], n, axis=0), explore=True)
    np.testing.assert_allclose(np.bincount(batch, minlength=M) / n, 1 / M, atol=0.03)


def test_intermediate_epsilon_mixes_random_and_greedy():
    """Epsilon 0.6: a random station (which is the greedy one a third of the time) with probability
    0.6, so the action differs from the greedy one with probability 0.6 * 2/3 = 0.4."""
    agent = _agent(epsilon_start=0.6, epsilon_end=0.6)
    agent.begin_episode(np.random.default_rng(5))
    obs = _obs(np.random.default_rng(6), 5000)
    greedy = agent.q_values(obs).argmax(axis=1)
    actions = np.array([agent.act(o, explore=True) for o in obs])
    assert np.mean(actions != greedy) == pytest.approx(0.4, abs=0.03)


def test_epsilon_zero_is_argmax():
    for exploration in ("slot", "episode"):
        agent = _agent(epsilon_start=0.0, epsilon_end=0.0, exploration=exploration)
        agent.begin_episode(np.random.default_rng(7))
        obs = _obs(np.random.default_rng(8), 300)
        greedy = agent.q_values(obs).argmax(axis=1)
        assert len(set(greedy.tolist())) > 1
        assert [agent.act(o, explore=True) for o in obs] == greedy.tolist()
        np.testing.assert_array_equal(_decide(agent, obs, explore=True), greedy)


@pytest.mark.parametrize("exploration", ["slot", "episode"])
def test_exploration_draws_come_from_the_episode_generator(exploration):
    """Agents built from different seeds (different networks, different own generators) act alike at
    epsilon 1 given the same episode generator; another episode generator gives other actions."""
    obs = _obs(np.random.default_rng(9), 50)

    def episode_actions(agent_seed, episode_seed):
        agent = _agent(seed=agent_seed, epsilon_start=1.0, epsilon_end=1.0, exploration=exploration)
        actions = []
        for e in range(10):  # a generator per episode, as the runner hands them out
            agent.begin_episode(np.random.default_rng([episode_seed, e]))
            actions += [agent.act(o, explore=True) for o in obs[:5]]
        return actions

    assert episode_actions(0, 11) == episode_actions(1, 11)
    assert episode_actions(0, 11) != episode_actions(0, 12)
    # the generator handed in is the one consumed
    agent = _agent(epsilon_start=1.0, epsilon_end=1.0, exploration=exploration)
    gen = np.random.default_rng(13)
    before = copy.deepcopy(gen.bit_generator.state)
    own = copy.deepcopy(agent.learn_rng.bit_generator.state)
    agent.begin_episode(gen)
    agent.act(obs[0], explore=True)
    assert gen.bit_generator.state != before
    assert agent.learn_rng.bit_generator.state == own


def test_episode_exploration_keeps_one_random_station_per_episode():
    agent = _agent(epsilon_start=1.0, epsilon_end=1.0, exploration="episode")
    obs = _obs(np.random.default_rng(14), 8)
    stations = []
    for e in range(600):
        agent.begin_episode(np.random.default_rng([15, e]))
        actions = {agent.act(o, explore=True) for o in obs}
        assert len(actions) == 1
        stations.append(actions.pop())
    np.testing.assert_allclose(np.bincount(stations, minlength=M) / 600, 1 / M, atol=0.07)


@pytest.mark.slow
def test_episode_exploration_follows_the_network_in_a_non_exploring_episode():
    """Epsilon 0.5: about half the episodes keep one random station; the others are exactly the
    greedy sequence (which changes station here, so the two kinds cannot be confused)."""
    agent = _agent(epsilon_start=0.5, epsilon_end=0.5, exploration="episode")
    obs = _obs(np.random.default_rng(16), 12)
    greedy = agent.q_values(obs).argmax(axis=1).tolist()
    assert len(set(greedy)) > 1
    explored = 0
    n = 1000
    for e in range(n):
        agent.begin_episode(np.random.default_rng([17, e]))
        actions = [agent.act(o, explore=True) for o in obs]
        if actions != greedy:
            assert len(set(actions)) == 1
            explored += 1
    assert explored / n == pytest.approx(0.5, abs=0.06)


def test_episode_exploration_in_a_batch_keeps_each_episodes_draw():
    """Several episodes decided together, slot after slot: each keeps its own draw (a random station
    for the whole episode, or the network's choice), made at its first decision and recorded in its
    state, exactly as when each episode is played alone."""
    agent = _agent(epsilon_start=0.5, epsilon_end=0.5, exploration="episode")
    k, slots = 40, 6
    obs = _obs(np.random.default_rng(30), slots * k).reshape(slots, k, OBS_DIM)
    together = [agent.new_episode(np.random.default_rng([31, e])) for e in range(k)]
    batched = np.stack([agent.decide(obs[s], together, explore=True) for s in range(slots)], axis=1)
    for e, episode in enumerate(together):
        assert episode.drawn
        if episode.random_station is not None:
            assert set(batched[e].tolist()) == {episode.random_station}
        agent.begin_episode(np.random.default_rng([31, e]))
        assert batched[e].tolist() == [agent.act(obs[s, e], explore=True) for s in range(slots)]
    kinds = {episode.random_station is None for episode in together}
    assert kinds == {True, False}  # both kinds of episode occur at epsilon 0.5


def test_decide_matches_act_when_not_exploring():
    for dueling in (False, True):
        agent = _agent(dueling=dueling, seed=18)
        obs = _obs(np.random.default_rng(19), 64)
        batch = _decide(agent, obs, explore=False)
        assert batch.shape == (64,)
        assert batch.dtype.kind == "i"
        assert batch.tolist() == [agent.act(o) for o in obs]
        assert all(type(agent.act(o)) is int for o in obs[:3])


def test_a_new_episode_state_is_explicit():
    agent = _agent(exploration="episode")
    episode = agent.new_episode(np.random.default_rng(0))
    assert isinstance(episode, DQNEpisode)
    assert (episode.drawn, episode.random_station) == (False, None)
    assert agent.begin_episode() is agent.episode and agent.episode.rng is agent.rng


def test_observations_are_scaled_before_the_network():
    scale = np.array([1e-3] * M + [0.1] * M + [0.5, 1.0, 0.25], dtype=np.float32)
    agent = _agent(points=[2, 1, 4])
    np.testing.assert_array_equal(agent.policy.inputs.scale, scale)
    obs = np.random.default_rng(20).uniform(0, 3000, size=(10, OBS_DIM)).astype(np.float32)
    with torch.no_grad():
        expected = agent.policy.online(torch.from_numpy(obs * scale)).numpy()
        unscaled = agent.policy.online(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(agent.q_values(obs), expected, rtol=1e-6)
    np.testing.assert_allclose(agent.q_values(obs[0]), expected[0], rtol=1e-6)
    assert not np.allclose(expected, unscaled)
    assert [agent.act(o) for o in obs] == expected.argmax(axis=1).tolist()


def test_the_network_sees_the_same_input_on_raw_and_normalised_observations():
    """The agent reads the environment's units off it (points, normalisation): whether the environment
    normalises or not, the network's input is D in km, N in tens and Z in multiples of the points."""
    stations = [SimpleNamespace(points=2), SimpleNamespace(points=1), SimpleNamespace(points=4)]
    agents = {}
    for normalized in (False, True):
        env = SimpleNamespace(stations=stations, config=SimpleNamespace(normalize_obs=normalized),
                              action_space=SimpleNamespace(n=3))  # fmt: skip
        env.unwrapped = env
        agents[normalized] = make_agent_for_env("dqn", env, np.random.default_rng(0), hidden=[4])
        scale = agents[normalized].policy.inputs.scale
        np.testing.assert_allclose(scale, 1 / unit_divisors([2, 1, 4]), rtol=1e-7)
    raw = np.random.default_rng(21).uniform(0, 3000, size=(10, OBS_DIM)).astype(np.float32)
    normalised = (raw / unit_divisors([2, 1, 4])).astype(np.float32)
    np.testing.assert_allclose(agents[True].q_values(normalised), agents[False].q_values(raw), rtol=1e-5)
    with pytest.raises(ValueError, match="points"):
        DQNAgent(M, np.random.default_rng(0), normalized=True)


@pytest.mark.parametrize(
    "obs", [np.zeros(OBS_DIM - 1), np.zeros(OBS_DIM + 1), np.zeros((2, OBS_DIM + 3)), np.zeros(0)]
)
def test_wrong_observation_shape_raises(obs):
    agent = _agent()
    with pytest.raises(ValueError, match="shape"):
        agent.act(obs)
    with pytest.raises(ValueError, match="shape"):
        agent.q_values(obs)
    with pytest.raises(ValueError, match="shape"):
        _decide(agent, np.atleast_2d(obs))
    with pytest.raises(ValueError, match="shape"):
        agent.observe(Transition(obs, 0, 1.0, np.zeros(OBS_DIM), False, False))


# -- learning mechanics ---------------------------------------------------------------------------------


def test_no_gradient_step_before_learning_starts():
    agent = _agent(learning_starts=20, batch_size=4)
    start = _params(agent.policy.online)
    for i, t in enumerate(_transitions(0, 25), start=1):
        agent.observe(t)
        if i < 20:
            assert agent.gradient_steps == 0
            assert _equal(_params(agent.policy.online), start)
        else:
            assert agent.gradient_steps == i - 19
    assert not _equal(_params(agent.policy.online), start)
    assert agent.stats()["transitions"] == 25.0
    assert agent.stats()["gradient_steps"] == 6.0


@pytest.mark.parametrize(("train_freq", "gradient_steps"), [(1, 1), (3, 2), (4, 1), (2, 3)])
def test_gradient_steps_every_train_freq_transitions(train_freq, gradient_steps):
    agent = _agent(learning_starts=10, train_freq=train_freq, gradient_steps=gradient_steps, batch_size=4)
    calls = []
    learn = agent.learn
    agent.learn = lambda: calls.append(agent.steps) or learn()
    for i, t in enumerate(_transitions(1, 40), start=1):
        agent.observe(t)
        rounds = sum(1 for s in range(10, i + 1) if s % train_freq == 0)
        assert agent.gradient_steps == rounds * gradient_steps
    expected = [s for s in range(10, 41) if s % train_freq == 0 for _ in range(gradient_steps)]
    assert calls == expected


def test_hard_target_update_every_target_update_gradient_steps():
    agent = _agent(learning_starts=4, batch_size=4, target_update=5, tau=1.0)
    copied = _params(agent.policy.online)
    assert _equal(_params(agent.policy.target), copied)
    checked = 0
    for t in _transitions(2, 40):
        before = agent.gradient_steps
        agent.observe(t)
        assert agent.gradient_steps == before + (agent.steps >= 4)
        online, target = _params(agent.policy.online), _params(agent.policy.target)
        assert agent.target_updates == agent.gradient_steps // 5
        assert agent.stats()["target_updates"] == agent.gradient_steps // 5
        if agent.gradient_steps and agent.gradient_steps % 5 == 0:
            assert _equal(target, online)
            copied = online
            checked += 1
        else:
            assert _equal(target, copied)  # unchanged since the last copy
            if agent.gradient_steps:
                assert not _equal(target, online)
    assert checked == 7  # 37 gradient steps


def test_the_learning_rate_is_constant():
    agent = _agent(lr=3e-3, learning_starts=1, buffer_size=64, batch_size=4)
    for t in _transitions(1, 40):
        agent.observe(t)
    assert agent.gradient_steps > 30
    assert agent.stats()["lr"] == 3e-3
    assert [g["lr"] for g in agent.optimizer.param_groups] == [3e-3]


def test_soft_update_moves_the_target_by_lerp():
    agent = _agent(tau=0.3)
    _perturb(agent.policy.target, seed=21)
    old, online = _params(agent.policy.target), _params(agent.policy.online)
    agent.update_target()
    for t, o, n in zip(old, online, _params(agent.policy.target), strict=True):
        torch.testing.assert_close(n, t + 0.3 * (o - t))
    assert agent.target_updates == 1
    # through learning: target_update=1 lerps after every gradient step, towards the updated online
    agent = _agent(tau=0.25, learning_starts=10**6, target_update=1)
    _perturb(agent.policy.target, seed=22)
    for t in _transitions(3, 10):
        agent.observe(t)
    old = _params(agent.policy.target)
    agent.learn()
    for t, o, n in zip(old, _params(agent.policy.online), _params(agent.policy.target), strict=True):
        torch.testing.assert_close(n, t + 0.25 * (o - t))
    assert agent.target_updates == 1


def _expected_q_y(agent: DQNAgent, batch) -> tuple[torch.Tensor, torch.Tensor]:
    """``Q(s, a)`` and the target ``y`` for a replay batch, by hand (before the gradient step)."""
    c = agent.config
    rows = torch.arange(len(batch.actions))
    obs = torch.from_numpy(batch.obs * agent.policy.inputs.scale)
    next_obs = torch.from_numpy(batch.next_obs * agent.policy.inputs.scale)
    with torch.no_grad():
        q = agent.policy.online(obs)[rows, torch.from_numpy(batch.actions)]
        q_next = agent.policy.target(next_obs)
        best = agent.policy.online(next_obs).argmax(dim=1) if agent.double else q_next.argmax(dim=1)
        boot = q_next[rows, best]
    live = 1 - torch.from_numpy(batch.terminated).float()
    return q, torch.from_numpy(batch.rewards) + c.gamma * live * boot


def _expected_td(agent: DQNAgent, batch) -> torch.Tensor:
    q, y = _expected_q_y(agent, batch)
    return q - y


@pytest.mark.parametrize("double", [False, True])
def test_priorities_follow_the_td_errors(double):
    """Eight transitions at equal priority and a batch of eight: the stratified draw takes each slot
    once, so every priority becomes ``(|td| + eps) ** alpha`` of its TD error."""
    agent = _agent(double=double, batch_size=8, learning_starts=10**6, alpha=0.6, priority_eps=1e-3)
    _perturb(agent.policy.target, seed=23)
    for t in _transitions(4, 8):
        agent.observe(t)
    slots = np.arange(8)
    np.testing.assert_array_equal(agent.replay.priorities(slots), np.ones(8))
    batch = agent.replay.sample(8, copy.deepcopy(agent.learn_rng), agent.beta)
    np.testing.assert_array_equal(np.sort(batch.indices), slots)
    td = _expected_td(agent, batch).numpy().astype(np.float64)
    agent.learn()
    expected = np.zeros(8)
    expected[batch.indices] = (np.abs(td) + 1e-3) ** 0.6
    np.testing.assert_allclose(agent.replay.priorities(slots), expected, rtol=1e-5)
    assert not np.allclose(agent.replay.priorities(slots), 1.0)
    assert agent.replay.max_priority == pytest.approx(max(1.0, expected.max()))


def test_alpha_zero_is_uniform_replay():
    agent = _agent(batch_size=8, learning_starts=10**6, alpha=0.0)
    for t in _transitions(5, 20):
        agent.observe(t)
    for _ in range(5):
        agent.learn()
    np.testing.assert_array_equal(agent.replay.priorities(np.arange(20)), np.ones(20))
    batch = agent.replay.sample(8, copy.deepcopy(agent.learn_rng), agent.beta)
    np.testing.assert_array_equal(batch.weights, np.ones(8, np.float32))


@pytest.mark.parametrize("loss", ["mse", "huber"])
@pytest.mark.parametrize("double", [False, True])
def test_loss_is_the_importance_weighted_mean_by_hand(loss, double):
    """On a replay with unequal priorities, ``learn()`` returns ``mean(w_i * l(td_i))`` with the batch
    it draws; ``l`` is the square (MSE) or Huber (quadratic below 1, linear above)."""
    agent = _agent(double=double, loss=loss, batch_size=16, learning_starts=10**6, alpha=0.7,
                   beta_start=0.3, beta_steps=100, points=[1, 2, 4])  # fmt: skip
    _perturb(agent.policy.target, seed=24, scale=0.05)
    for t in _transitions(6, 40):
        agent.observe(t)
    rng = np.random.default_rng(25)
    agent.replay.update_priorities(np.arange(40), rng.uniform(0.05, 4.0, 40))
    batch = agent.replay.sample(16, copy.deepcopy(agent.learn_rng), agent.beta)
    assert batch.weights.min() < 0.9  # the weights matter on this batch
    td = _expected_td(agent, batch)
    assert (td.abs() > 1).any()
    assert (td.abs() < 1).any()
    huber = torch.where(td.abs() < 1, 0.5 * td**2, td.abs() - 0.5)
    per_sample = td**2 if loss == "mse" else huber
    weights = torch.from_numpy(batch.weights)
    expected = float((weights * per_sample).mean())
    got = agent.learn()
    assert got == pytest.approx(expected, rel=1e-5)
    assert got != pytest.approx(float(per_sample.mean()), rel=1e-3)  # unweighted would differ
    other = td**2 if loss == "huber" else huber
    assert got != pytest.approx(float((weights * other).mean()), rel=1e-3)
    assert agent.stats()["loss_total"] == pytest.approx(got)


def test_importance_weights_scale_the_gradient():
    """The gradient of ``learn()``'s loss equals the gradient of the hand-weighted loss (recorded just
    before the optimizer step, without clipping)."""
    agent = _agent(batch_size=16, learning_starts=10**6, alpha=1.0, beta_start=1.0, max_grad_norm=None)
    for t in _transitions(7, 30):
        agent.observe(t)
    agent.replay.update_priorities(np.arange(30), np.random.default_rng(26).uniform(0.01, 5.0, 30))
    batch = agent.replay.sample(16, copy.deepcopy(agent.learn_rng), agent.beta)
    _, y = _expected_q_y(agent, batch)
    shadow = copy.deepcopy(agent.policy.online)
    obs = torch.from_numpy(batch.obs * agent.policy.inputs.scale)
    q = shadow(obs)[torch.arange(16), torch.from_numpy(batch.actions)]
    w = torch.from_numpy(batch.weights)
    assert w.min() < 0.5
    (w * (q - y) ** 2).mean().backward()
    unweighted = copy.deepcopy(agent.policy.online)
    q2 = unweighted(obs)[torch.arange(16), torch.from_numpy(batch.actions)]
    ((q2 - y) ** 2).mean().backward()
    grads = []
    agent.optimizer.register_step_pre_hook(
        lambda *_: grads.append([p.grad.clone() for p in agent.policy.online.parameters()])
    )
    agent.learn()
    assert len(grads) == 1
    for g, want in zip(grads[0], shadow.parameters(), strict=True):
        torch.testing.assert_close(g, want.grad, rtol=1e-4, atol=1e-6)
    pairs = zip(grads[0], unweighted.parameters(), strict=True)
    assert not all(torch.allclose(g, p.grad, rtol=1e-2) for g, p in pairs)


def _grad_norm(params) -> float:
    return float(torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(p.grad) for p in params])))


def test_gradient_clipping_bounds_the_norm():
    """Same agent and batch with and without clipping: the clipped gradient is the unclipped one
    scaled down to norm ``max_grad_norm``."""
    recorded = {}
    for clip in (None, 0.05):
        agent = _agent(seed=27, batch_size=16, learning_starts=10**6, max_grad_norm=clip)
        for t in _transitions(8, 30):
            agent.observe(t._replace(reward=t.reward * 100))  # big TD errors, big gradients
        grads = []
        agent.optimizer.register_step_pre_hook(
            lambda *_, a=agent, g=grads: g.append([p.grad.clone() for p in a.policy.online.parameters()])
        )
        agent.learn()
        recorded[clip] = grads[0]
    raw = math.sqrt(sum(float((g**2).sum()) for g in recorded[None]))
    clipped = math.sqrt(sum(float((g**2).sum()) for g in recorded[0.05]))
    assert raw > 1.0
    assert clipped == pytest.approx(0.05, rel=1e-3)
    for g_raw, g_clip in zip(recorded[None], recorded[0.05], strict=True):
        torch.testing.assert_close(g_clip, g_raw * (0.05 / raw), rtol=1e-3, atol=1e-8)


def test_reward_scale_multiplies_stored_rewards():
    agent = _agent(reward_scale=0.01, learning_starts=10**6)
    rng = np.random.default_rng(28)
    rewards = [250.0, -40.0, 7.0]
    for r in rewards:
        agent.observe(_transition(rng, reward=r))
    stored = agent.replay.state_dict()["rewards"][:3]
    np.testing.assert_allclose(stored, np.array(rewards) * 0.01, rtol=1e-6)


def test_learning_changes_only_the_online_network_between_target_updates():
    agent = _agent(learning_starts=10**6, target_update=1000)
    for t in _transitions(9, 20):
        agent.observe(t)
    online, target = _params(agent.policy.online), _params(agent.policy.target)
    losses = [agent.learn() for _ in range(5)]
    assert all(np.isfinite(losses))
    assert not _equal(_params(agent.policy.online), online)
    assert _equal(_params(agent.policy.target), target)
    stats = agent.stats()
    assert stats["gradient_steps"] == 5.0
    assert stats["loss_total"] == pytest.approx(sum(losses))
    assert set(stats) == {"transitions", "gradient_steps", "target_updates", "loss_total", "q_total",
                          "epsilon", "beta", "lr"}  # fmt: skip


# -- validation -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"lr": 0.0}, "lr=0.0"),
        ({"lr": -1e-3}, "lr=-0.001"),
        ({"lr": float("nan")}, "lr=nan"),
        ({"batch_size": 0}, "batch_size=0"),
        ({"batch_size": 32, "buffer_size": 16}, "buffer_size=16"),
        ({"hidden": []}, "hidden=[]"),
        ({"hidden": [8, 0]}, "hidden=[8, 0]"),
        ({"epsilon_start": 1.5}, "epsilon_start=1.5"),
        ({"epsilon_end": -0.1}, "epsilon_end=-0.1"),
        ({"gamma": 1.2}, "gamma=1.2"),
        ({"alpha": -1}, "alpha=-1"),
        ({"beta_start": 2.0}, "beta_start=2.0"),
        ({"tau": 0}, "tau=0"),
        ({"tau": 1.5}, "tau=1.5"),
        ({"loss": "l1"}, "loss='l1'"),
        ({"exploration": "bogus"}, "exploration='bogus'"),
        ({"network": "lstm"}, "network='lstm'"),
        ({"target_update": 0}, "target_update=0"),
        ({"n_step": 0}, "n_step=0"),
        ({"train_freq": 0}, "train_freq=0"),
        ({"gradient_steps": -1}, "gradient_steps=-1"),
        ({"learning_starts": -1}, "learning_starts=-1"),
        ({"exploration_steps": 2.5}, "exploration_steps=2.5"),
        ({"max_grad_norm": 0.0}, "max_grad_norm=0.0"),
        ({"reward_scale": 0}, "reward_scale=0"),
        ({"priority_eps": 0}, "priority_eps=0"),
        ({"double": "yes"}, "double='yes'"),
        ({"points": [2, 2]}, "points"),
        ({"points": [2, 0, 2]}, "points"),
        ({"points": 1.5}, "points"),
        ({"bogus": 1}, "bogus"),
    ],
)
def test_bad_settings_raise_naming_the_value(kwargs, named):
    with pytest.raises(ValueError) as info:
        _agent(**kwargs)
    assert named in str(info.value)
    if not {"points", "double", "bogus"} & set(kwargs):
        with pytest.raises(ValueError) as info:
            DQNConfig(**{**SMALL, **kwargs})
        assert named in str(info.value)
        with pytest.raises(ValueError) as info:
            make_agent("dueling_ddqn", M, np.random.default_rng(0), **{**SMALL, **kwargs})
        assert named in str(info.value)


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="n_stations=0"):
        DQNAgent(0, np.random.default_rng(0))
    with pytest.raises(ValueError, match="rng"):
        DQNAgent(M, 0)  # type: ignore[arg-type]


def test_default_settings_are_valid():
    agent = DQNAgent(M, np.random.default_rng(0))
    assert agent.config == DQNConfig()
    np.testing.assert_array_equal(agent.policy.inputs.scale, np.ones(OBS_DIM, np.float32))
    config = DQNConfig(lr=5e-4, gamma=0.5)
    assert DQNAgent(M, np.random.default_rng(0), config).config is config
    assert DQNAgent(M, np.random.default_rng(0), config, gamma=0.7).config == DQNConfig(lr=5e-4, gamma=0.7)
    assert "dqn" in repr(agent)


# -- state ----------------------------------------------------------------------------------------------

RESUME = {"hidden": (16, 16), "batch_size": 8, "buffer_size": 200, "learning_starts": 20,
          "target_update": 7, "exploration_steps": 300, "lr": 3e-3}  # fmt: skip


def _mid_training(name: str, exploration: str = "slot", **extra) -> DQNAgent:
    agent = make_agent(name, M, np.random.default_rng(30), exploration=exploration, **RESUME, **extra)
    _train(agent, seed=31, episodes=range(25))
    assert agent.gradient_steps > 20
    assert agent.target_updates > 2
    return agent


def _continue(agent: DQNAgent) -> tuple[list, list]:
    """More training (episodes with exploration and learning), direct learn() calls, more observes."""
    rows = _train(agent, seed=31, episodes=range(25, 45))
    losses = [agent.learn() for _ in range(5)]
    for t in _transitions(32, 30):
        agent.observe(t)
    return [r.choices for r in rows], losses


@pytest.mark.slow
@pytest.mark.parametrize("via", ["memory", "checkpoint"])
@pytest.mark.parametrize(
    ("name", "exploration", "extra"),
    [("dqn", "slot", {}), ("dueling_ddqn", "episode", {}),
     ("dueling_ddqn", "slot", {"n_step": 3, "tau": 0.5})],
)  # fmt: skip
def test_restored_agent_continues_exactly(tmp_path, via, name, exploration, extra):
    original = _mid_training(name, exploration, **extra)
    state = original.state_dict()
    if via == "checkpoint":
        save_checkpoint(tmp_path, {"format": "evcd.train/1", "agent": state, "episode": 25}, "ckpt_25")
        state = load_checkpoint(tmp_path)["agent"]
    restored = make_agent(name, M, np.random.default_rng(999), exploration=exploration, **RESUME, **extra)
    assert not _equal(_params(restored.policy.online), _params(original.policy.online))
    restored.load_state_dict(state)
    assert restored.stats() == original.stats()
    # the current generator too: an episode begun without a new generator explores alike
    obs = _obs(np.random.default_rng(33), 40)
    original.begin_episode()
    restored.begin_episode()
    assert [original.act(o, explore=True) for o in obs] == [restored.act(o, explore=True) for o in obs]

    choices_a, losses_a = _continue(original)
    choices_b, losses_b = _continue(restored)
    assert choices_a == choices_b
    assert losses_a == losses_b
    assert original.stats() == restored.stats()
    assert original.gradient_steps > 100
    assert _equal(_params(original.policy.online), _params(restored.policy.online))
    assert _equal(_params(original.policy.target), _params(restored.policy.target))
    assert state_equal(original.optimizer.state_dict(), restored.optimizer.state_dict())
    assert state_equal(original.replay.state_dict(), restored.replay.state_dict())
    assert original.learn_rng.bit_generator.state == restored.learn_rng.bit_generator.state


@pytest.mark.slow
def test_state_dict_is_a_snapshot():
    """A state taken mid-training and loaded only after the original went on (into two agents at
    once) still replays the original's continuation: neither the state nor the agents share tensors."""
    original = _mid_training("dueling_ddqn")
    state = original.state_dict()
    choices, losses = _continue(original)
    first = make_agent("dueling_ddqn", M, np.random.default_rng(7), **RESUME)
    second = make_agent("dueling_ddqn", M, np.random.default_rng(8), **RESUME)
    first.load_state_dict(state)
    second.load_state_dict(state)
    assert _continue(first) == (choices, losses)
    assert _continue(second) == (choices, losses)
    assert _equal(_params(first.policy.online), _params(original.policy.online))
    assert _equal(_params(second.policy.online), _params(original.policy.online))


@pytest.mark.slow
def test_a_fresh_agent_does_not_continue_like_the_trained_one():
    """The counter-test of the resume test: without the state, the same continuation differs."""
    original = _mid_training("dqn")
    other = make_agent("dqn", M, np.random.default_rng(999), **RESUME)
    _, losses_a = _continue(original)
    _, losses_b = _continue(other)
    assert losses_a != losses_b
    assert not _equal(_params(original.policy.online), _params(other.policy.online))


def test_state_dict_is_what_torch_loads_with_weights_only(tmp_path):
    agent = _mid_training("dueling_ddqn")
    path = save_checkpoint(tmp_path, agent.state_dict(), "agent")
    loaded = load_checkpoint(path)
    assert loaded["format"] == STATE_FORMAT
    assert loaded["n_stations"] == M
    assert loaded["config"]["hidden"] == [16, 16]
    assert loaded["rng"] == agent.rng.bit_generator.state


def test_the_state_neither_holds_nor_sets_torchs_global_generator():
    """torch's global generator is never used after the networks' initialisation (inside fork_rng):
    a state does not carry it, and loading one leaves it where it was."""
    agent = _mid_training("dqn")
    state = agent.state_dict()
    assert not [k for k in state if "torch" in k]
    torch.manual_seed(77)
    before = torch.random.get_rng_state()
    _agent(seed=1, **RESUME).load_state_dict(state)
    assert torch.equal(torch.random.get_rng_state(), before)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"n_stations": 4}, "size 9"),
        ({"n_stations": 2}, "size 9"),
        ({"hidden": (16, 8)}, "hidden"),
        ({"hidden": (16,)}, "hidden"),
        ({"network": "station"}, "network"),
        ({"dueling": True}, "dueling"),
        ({"double": True}, "double"),
    ],
)
@pytest.mark.parametrize("policy_only", [False, True])
def test_load_into_a_mismatched_agent_raises(kwargs, named, policy_only):
    state = _agent(**RESUME).state_dict()
    other = _agent(seed=2, **{**RESUME, **kwargs})
    before = _params(other.policy.online)
    with pytest.raises(CheckpointError, match=named):
        other.load_state_dict(state, policy_only=policy_only)
    assert _equal(_params(other.policy.online), before)


def test_load_rejects_a_state_that_is_not_a_dqn_agent():
    agent = _agent()
    with pytest.raises(CheckpointError, match="not a DQN agent"):
        agent.load_state_dict({"format": "evcd.train/1"})
    with pytest.raises(CheckpointError, match="earlier evcd"):
        agent.load_state_dict({**agent.state_dict(), "format": "evcd.agents.dqn/1"})
    with pytest.raises(CheckpointError, match="not a DQN agent"):
        agent.load_state_dict([1, 2])  # type: ignore[arg-type]


def test_policy_only_loads_just_the_networks():
    trained = _mid_training("dueling_ddqn")
    fresh = make_agent("dueling_ddqn", M, np.random.default_rng(5), **RESUME)
    optimizer = copy.deepcopy(fresh.optimizer.state_dict())
    fresh.load_state_dict(trained.state_dict(), policy_only=True)
    assert _equal(_params(fresh.policy.online), _params(trained.policy.online))
    assert _equal(_params(fresh.policy.target), _params(trained.policy.target))
    assert fresh.steps == 0
    assert fresh.gradient_steps == 0
    assert len(fresh.replay) == 0
    assert state_equal(fresh.optimizer.state_dict(), optimizer)
    assert fresh.epsilon == fresh.config.epsilon_start
    # and it acts like the trained one
    obs = _obs(np.random.default_rng(6), 50)
    np.testing.assert_array_equal(_decide(fresh, obs), _decide(trained, obs))


def test_a_loaded_policy_sees_what_it_was_trained_on():
    """The checkpoint's input scale wins: a policy trained on raw observations (points 2, 1, 4)
    loaded into an agent for a normalising environment, or one made with other points, or none,
    gives the same Q-values on the same physical observations."""
    trained = _agent(points=[2, 1, 4])
    raw = np.random.default_rng(7).uniform(0, 3000, size=(20, OBS_DIM)).astype(np.float32)
    expected = trained.q_values(raw)
    for kwargs, obs in (
        ({"points": [2, 1, 4], "normalized": True}, (raw / unit_divisors([2, 1, 4])).astype(np.float32)),
        ({"points": [3, 3, 3], "normalized": True}, (raw / unit_divisors([3, 3, 3])).astype(np.float32)),
        ({}, raw),
    ):
        other = _agent(seed=3, **kwargs)
        other.load_state_dict(trained.state_dict(), policy_only=True)
        np.testing.assert_array_equal(other.policy.inputs.scale, trained.policy.inputs.scale)
        # float32: the input is rounded once more on the way (obs / divisors * scale), so a Q-value
        # near 0 may move by the rounding of the largest ones; compare at that scale
        np.testing.assert_allclose(
            other.q_values(obs), expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max()
        )


@pytest.mark.parametrize("name", ["dqn", "dueling_ddqn"])
def test_load_a_trainer_checkpoint(tmp_path, name):
    trained = _mid_training(name)
    run_dir = tmp_path / "run"
    payload = {"format": "evcd.train/1", "agent": trained.state_dict(), "episodes_done": 25}
    save_checkpoint(run_dir / "checkpoints", payload, "ckpt_0000025")
    obs = _obs(np.random.default_rng(8), 40)
    for where in (run_dir, run_dir / "checkpoints", run_dir / "checkpoints" / "latest.json"):
        policy = make_agent(name, M, np.random.default_rng(1), **RESUME)
        policy.load(where)
        assert _equal(_params(policy.policy.online), _params(trained.policy.online))
        assert policy.steps == 0  # the policy only
        np.testing.assert_array_equal(_decide(policy, obs), _decide(trained, obs))
    built = make_agent(name, M, np.random.default_rng(2), checkpoint=run_dir, **RESUME)
    assert _equal(_params(built.policy.online), _params(trained.policy.online))
    config = saved_options(run_dir)
    dueling = name == "dueling_ddqn"
    assert config == {
        "hidden": (16, 16),
        "network": "mlp",
        "double": dueling,
        "dueling": dueling,
    }
    # a bare agent state (not wrapped by the trainer) works too
    save_checkpoint(tmp_path / "bare", trained.state_dict(), "agent")
    assert saved_options(tmp_path / "bare") == config
    with pytest.raises(CheckpointError, match="hidden"):
        make_agent(name, M, np.random.default_rng(2), checkpoint=run_dir, **{**RESUME, "hidden": (8,)})


@pytest.mark.parametrize("name", ["dqn", "dueling_ddqn"])
def test_a_station_network_checkpoint_rebuilds_its_network(tmp_path, name):
    trained = make_agent(name, M, np.random.default_rng(3), **{**RESUME, "network": "station"})
    save_checkpoint(tmp_path, trained.state_dict(), "agent")
    config = saved_options(tmp_path)
    assert config["network"] == "station"
    rebuilt = make_agent(name, M, np.random.default_rng(4), checkpoint=tmp_path, **{**RESUME, **config})
    obs = _obs(np.random.default_rng(8), 40)
    np.testing.assert_array_equal(rebuilt.q_values(obs), trained.q_values(obs))


def test_a_checkpoint_from_before_the_network_option_holds_the_mlp(tmp_path):
    state = _agent(**RESUME).state_dict()
    del state["config"]["network"]
    save_checkpoint(tmp_path, state, "agent")
    assert saved_options(tmp_path)["network"] == "mlp"
    _agent(seed=2, **RESUME).load_state_dict(state)
    with pytest.raises(CheckpointError, match="network='mlp'"):
        _agent(seed=2, **{**RESUME, "network": "station"}).load_state_dict(state)


#: what a checkpoint of commit c467250 saved of the settings that have left evcd since, at their defaults
_REMOVED_AT_DEFAULTS = {"lr_end": None, "lr_decay_steps": 10_000, "in_turn": False, "rule_estimate": False,
                        "rule_prior": False, "rule_prior_bound_s": None, "rule_prior_relative": False,
                        "switch_margin_s": 0.0}  # fmt: skip


def test_a_checkpoint_with_removed_settings_at_their_defaults_still_loads(tmp_path):
    trained = _agent(**RESUME)
    state = trained.state_dict()
    state["config"].update(_REMOVED_AT_DEFAULTS)
    save_checkpoint(tmp_path, state, "agent")
    expected = {"hidden": (16, 16), "network": "mlp", "double": False, "dueling": False}
    assert saved_options(tmp_path) == expected
    loaded = _agent(seed=2, **RESUME)
    loaded.load_state_dict(state)
    obs = _obs(np.random.default_rng(8), 20)
    np.testing.assert_array_equal(loaded.q_values(obs), trained.q_values(obs))


@pytest.mark.parametrize(
    ("key", "value"), [("rule_prior", True), ("in_turn", True), ("switch_margin_s", 300.0), ("lr_end", 1e-4)]
)
def test_a_checkpoint_whose_policy_used_a_removed_setting_is_refused_naming_the_commit(tmp_path, key, value):
    state = _agent(**RESUME).state_dict()
    state["config"].update({**_REMOVED_AT_DEFAULTS, key: value})
    save_checkpoint(tmp_path, state, "agent")
    expected = rf"learner\.{key}={value}: this setting left evcd; commit c467250 is the last that has it"
    with pytest.raises(CheckpointError, match=expected):
        saved_options(tmp_path)
    with pytest.raises(CheckpointError, match=expected):
        _agent(seed=2, **RESUME).load_state_dict(state, policy_only=True)
    with pytest.raises(CheckpointError, match=expected):
        _agent(seed=2, **RESUME).load(tmp_path)


def test_a_non_dqn_checkpoint_is_refused(tmp_path):
    save_checkpoint(tmp_path, {"format": "evcd.train/1", "agent": {"format": "greedy"}}, "ckpt_1")
    with pytest.raises(CheckpointError, match="DQN"):
        saved_options(tmp_path)
    with pytest.raises(CheckpointError, match="DQN"):
        _agent().load(tmp_path)
    save_checkpoint(tmp_path / "other", {"weights": torch.ones(3)}, "x")
    with pytest.raises(CheckpointError, match="DQN"):
        saved_options(tmp_path / "other")
    with pytest.raises(CheckpointError):
        saved_options(tmp_path / "missing")


# -- determinism and random state -----------------------------------------------------------------------


@pytest.mark.slow
def test_same_seed_same_weights_other_seed_differs():
    def trained(seed):
        agent = make_agent("dueling_ddqn", M, np.random.default_rng(seed), **RESUME)
        rows = _train(agent, seed=33, episodes=range(20))
        return agent, [r.choices for r in rows]

    a, rows_a = trained(40)
    b, rows_b = trained(40)
    c, _ = trained(41)
    assert a.gradient_steps > 0
    assert rows_a == rows_b
    assert _equal(_params(a.policy.online), _params(b.policy.online))
    assert _equal(_params(a.policy.target), _params(b.policy.target))
    assert not _equal(_params(a.policy.online), _params(c.policy.online))


def test_no_global_random_state_is_used():
    torch.manual_seed(1234)
    np.random.seed(1234)
    torch_before = torch.random.get_rng_state()
    np_before = np.random.get_state()

    for name, exploration in (("dqn", "slot"), ("dueling_ddqn", "episode")):
        agent = make_agent(name, M, np.random.default_rng(0), exploration=exploration, **RESUME)
        agent.begin_episode(np.random.default_rng(1))
        rng = np.random.default_rng(2)
        for t in _transitions(3, 60):
            agent.act(t.obs, explore=True)
            agent.act(t.obs, explore=False)
            agent.observe(t)
        _decide(agent, _obs(rng, 5), explore=True)
        agent.learn()
        agent.update_target()
        agent.state_dict()
        agent.stats()
        assert agent.gradient_steps > 0

    assert torch.equal(torch.random.get_rng_state(), torch_before)
    assert np_state_equal(np.random.get_state(), np_before)


def test_the_station_network_reads_the_fleets_h_per_station():
    """On the fleet's [D, N, Z, H] (obs_blocks=4) the station network scores each station from its
    own four features: the guided EVs heading to station 1 move its Q-value alone (plain DQN)."""
    m = 3
    agent = DQNAgent(m, np.random.default_rng(0), obs_blocks=4, network="station", hidden=(16,))
    obs = _obs(np.random.default_rng(1), 5, dim=4 * m)
    more = obs.copy()
    more[:, 3 * m + 1] += 3.0  # H of station 1
    delta = agent.q_values(more) - agent.q_values(obs)
    assert agent.q_values(obs).shape == (5, m)
    assert (np.abs(delta[:, 1]) > 1e-6).all()
    np.testing.assert_allclose(delta[:, [0, 2]], 0.0, atol=1e-6)
