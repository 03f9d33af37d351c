"""Q-networks: output shapes, the layer sizes and activations the config asks for, the dueling
combination ``V + A - mean(A)`` checked against the two streams, the station network (its trunk per
station by hand; a station's Q reads that station's features only), and the validation of sizes."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from evcd.agents.networks import DuelingQNetwork, QNetwork, StationQNetwork, check_hidden, make_q_network


def _seeded(obs_dim, n_actions, hidden, dueling, seed=0):
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return make_q_network(obs_dim, n_actions, hidden, dueling)


def _obs(batch, obs_dim, seed=1):
    return torch.randn(batch, obs_dim, generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("dueling", [False, True])
@pytest.mark.parametrize(("batch", "obs_dim", "n_actions"), [(1, 15, 5), (7, 9, 3), (4, 3, 1)])
def test_output_shape(dueling, batch, obs_dim, n_actions):
    net = _seeded(obs_dim, n_actions, (8, 6), dueling)
    q = net(_obs(batch, obs_dim))
    assert q.shape == (batch, n_actions)
    assert q.dtype == torch.float32
    assert torch.isfinite(q).all()


@pytest.mark.parametrize("dueling", [False, True])
def test_make_q_network_picks_the_class(dueling):
    net = make_q_network(6, 2, [4], dueling)
    assert type(net) is (DuelingQNetwork if dueling else QNetwork)


@pytest.mark.parametrize("dueling", [False, True])
@pytest.mark.parametrize("hidden", [(16,), (32, 8), (5, 7, 3)])
def test_hidden_sizes_are_the_layer_sizes(dueling, hidden):
    obs_dim, n_actions = 9, 3
    net = _seeded(obs_dim, n_actions, list(hidden), dueling)
    trunk = list(net.trunk)
    linears = [m for m in trunk if isinstance(m, nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == list(
        zip((obs_dim, *hidden[:-1]), hidden, strict=True)
    )
    # Linear, ReLU, Linear, ReLU, ...: a ReLU after every hidden layer
    assert len(trunk) == 2 * len(hidden)
    assert all(isinstance(m, nn.Linear) for m in trunk[0::2])
    assert all(isinstance(m, nn.ReLU) for m in trunk[1::2])
    if dueling:
        assert (net.value.in_features, net.value.out_features) == (hidden[-1], 1)
        assert (net.advantage.in_features, net.advantage.out_features) == (hidden[-1], n_actions)
    else:
        assert (net.head.in_features, net.head.out_features) == (hidden[-1], n_actions)
    all_linears = [m for m in net.modules() if isinstance(m, nn.Linear)]
    assert len(all_linears) == len(hidden) + (2 if dueling else 1)


def test_plain_forward_is_the_mlp_by_hand():
    """``head(relu(W2 relu(W1 x + b1) + b2))`` with the network's own weights."""
    net = _seeded(5, 4, (6, 3), dueling=False)
    x = _obs(10, 5)
    l1, l2 = net.trunk[0], net.trunk[2]
    h = torch.relu(x @ l1.weight.T + l1.bias)
    h = torch.relu(h @ l2.weight.T + l2.bias)
    expected = h @ net.head.weight.T + net.head.bias
    torch.testing.assert_close(net(x), expected)


def test_relu_clips_negative_features():
    """With a trunk that maps every input to negatives, every ReLU output is 0 and Q is the head bias."""
    net = _seeded(4, 3, (5,), dueling=False)
    with torch.no_grad():
        net.trunk[0].weight.zero_()
        net.trunk[0].bias.fill_(-1.0)
    q = net(_obs(6, 4))
    torch.testing.assert_close(q, net.head.bias.detach().expand(6, 3))


def test_dueling_combines_value_and_centred_advantage():
    net = _seeded(9, 5, (16, 8), dueling=True, seed=3)
    x = _obs(12, 9, seed=4)
    value, advantage = net.streams(x)
    assert value.shape == (12, 1)
    assert advantage.shape == (12, 5)
    by_hand = value + advantage - advantage.mean(dim=1, keepdim=True)
    q = net(x)
    torch.testing.assert_close(q, by_hand)
    # the advantages are identifiable: Q - V averages to 0 over the actions
    torch.testing.assert_close((q - value).mean(dim=1), torch.zeros(12), atol=1e-6, rtol=0)
    # and Q is not simply V + A (the mean is really subtracted)
    assert not torch.allclose(q, value + advantage)


def test_dueling_streams_share_the_trunk():
    net = _seeded(6, 4, (7,), dueling=True)
    x = _obs(3, 6)
    features = net.trunk(x)
    value, advantage = net.streams(x)
    torch.testing.assert_close(value, net.value(features))
    torch.testing.assert_close(advantage, net.advantage(features))


def test_networks_backpropagate_to_every_parameter():
    for dueling in (False, True):
        net = _seeded(6, 3, (8, 4), dueling)
        net(_obs(5, 6)).sum().backward()
        for name, p in net.named_parameters():
            assert p.grad is not None, name


def test_check_hidden_accepts_sequences():
    assert check_hidden([512, 256]) == (512, 256)
    assert check_hidden((3,)) == (3,)
    assert check_hidden(range(1, 4)) == (1, 2, 3)
    out = check_hidden(np.array([4, 2]))
    assert out == (4, 2)
    assert all(type(s) is int for s in out)


@pytest.mark.parametrize(
    ("hidden", "named"),
    [
        ([], "hidden=[]"),
        ((), "hidden=[]"),
        ([0], "0"),
        ([64, -1], "-1"),
        ([64, 2.5], "2.5"),
        ([64.0], "64.0"),
        ([True, 4], "True"),
        (["64"], "'64'"),
        (None, "None"),
        (7, "7"),
    ],
)
def test_check_hidden_rejects(hidden, named):
    with pytest.raises(ValueError, match="hidden") as info:
        check_hidden(hidden)
    assert named in str(info.value)
    with pytest.raises(ValueError, match="hidden"):
        make_q_network(6, 2, hidden, dueling=False)
    with pytest.raises(ValueError, match="hidden"):
        make_q_network(6, 2, hidden, dueling=True)


@pytest.mark.parametrize("dueling", [False, True])
@pytest.mark.parametrize(
    ("key", "obs_dim", "n_actions", "named"),
    [
        ("obs_dim", 0, 3, "obs_dim=0"),
        ("obs_dim", -4, 3, "obs_dim=-4"),
        ("obs_dim", 6.0, 3, "obs_dim=6.0"),
        ("obs_dim", True, 3, "obs_dim=True"),
        ("n_actions", 6, 0, "n_actions=0"),
        ("n_actions", 6, -1, "n_actions=-1"),
        ("n_actions", 6, 2.5, "n_actions=2.5"),
        ("n_actions", 6, False, "n_actions=False"),
        ("n_actions", 6, "3", "n_actions='3'"),
    ],
)
def test_make_q_network_rejects_bad_dimensions(dueling, key, obs_dim, n_actions, named):
    with pytest.raises(ValueError, match=key) as info:
        make_q_network(obs_dim, n_actions, (4,), dueling)
    assert named in str(info.value)


# ---------------------------------------------------------------- the station network
def _station(obs_dim, n_actions, hidden, dueling, seed=0):
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return make_q_network(obs_dim, n_actions, hidden, dueling, network="station")


@pytest.mark.parametrize("dueling", [False, True])
def test_make_q_network_picks_the_station_network(dueling):
    net = make_q_network(12, 4, [8], dueling, network="station")
    assert type(net) is StationQNetwork
    assert (net.blocks, net.n_actions) == (3, 4)
    # the trunk reads one station's block and its one-hot index
    assert net.trunk[0].in_features == 3 + 4


@pytest.mark.parametrize("dueling", [False, True])
@pytest.mark.parametrize(("batch", "blocks", "n_actions"), [(1, 3, 5), (6, 4, 3), (2, 3, 1)])
def test_station_network_output_shape(dueling, batch, blocks, n_actions):
    q = _station(blocks * n_actions, n_actions, (8, 6), dueling)(_obs(batch, blocks * n_actions))
    assert q.shape == (batch, n_actions)
    assert torch.isfinite(q).all()


def test_station_network_is_the_shared_trunk_by_hand():
    """Q(s, a) = head(trunk([D_a, N_a, Z_a, onehot(a)])), the observation read block-major."""
    m, blocks = 4, 3
    net = _station(blocks * m, m, (5, 3), dueling=False)
    x = _obs(2, blocks * m)
    for a in range(m):
        own = x[:, [a, m + a, 2 * m + a]]  # D_a, N_a, Z_a
        index = torch.zeros(2, m)
        index[:, a] = 1.0
        expected = net.head(net.trunk(torch.cat([own, index], dim=1))).squeeze(1)
        torch.testing.assert_close(net(x)[:, a], expected)


def test_a_stations_q_value_reads_only_its_own_features():
    """Changing station b's features moves Q(s, b) alone (plain); with the dueling heads, V(s)
    moves every value alike, so the differences between the other stations stay."""
    m = 5
    x = _obs(3, 3 * m)
    changed = x.clone()
    changed[:, [1, m + 1, 2 * m + 1]] += 2.0  # station 1's D, N, Z
    plain = _station(3 * m, m, (16, 8), dueling=False)
    delta = plain(changed) - plain(x)
    assert (delta[:, 1].abs() > 1e-6).all()
    torch.testing.assert_close(delta[:, [0, 2, 3, 4]], torch.zeros(3, 4))
    dueling = _station(3 * m, m, (16, 8), dueling=True)
    before, after = dueling(x), dueling(changed)
    others = [0, 2, 3, 4]
    torch.testing.assert_close(after[:, others] - after[:, [0]], before[:, others] - before[:, [0]])


def test_station_network_backpropagates_to_every_parameter():
    for dueling in (False, True):
        net = _station(9, 3, (8, 4), dueling)
        net(_obs(5, 9)).sum().backward()
        for name, p in net.named_parameters():
            assert p.grad is not None, name


def test_station_network_rejects_an_observation_not_made_of_station_blocks():
    with pytest.raises(ValueError, match=r"obs_dim=10.*n_actions=3"):
        make_q_network(10, 3, (4,), dueling=False, network="station")
    with pytest.raises(ValueError, match="network='lstm': must be one of mlp, station"):
        make_q_network(9, 3, (4,), dueling=False, network="lstm")
