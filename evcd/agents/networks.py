"""Q-networks: a multilayer perceptron, its dueling variant (Wang et al. 2016), and a network shared
by the stations.

    net = make_q_network(obs_dim=15, n_actions=5, hidden=(512, 256), dueling=True)
    q = net(torch.zeros(1, 15))                   # (batch, n_actions)

Each has one trunk (``Linear`` + ``ReLU`` per hidden size). The plain network ends in one linear
layer to the Q-values; the dueling one ends in a value head ``V(s)`` and an advantage head
``A(s, a)``, combined as ``V + A - mean_a(A)`` so that the split is identifiable.

``network="station"`` (:class:`StationQNetwork`) reads the observation as the stations' blocks
(``[D, N, Z]`` or the fleet's ``[D, N, Z, H]``: ``obs_dim = blocks x n_actions``) and scores each
station with ONE trunk from that station's own features and its index (one-hot):
``Q(s, a) = f(x_a, a)``. It is the shape of the queue-aware rule (a score per station from its
distance, traffic and queue), learned: what one station teaches holds for the others, where the MLP
must learn it once per input position.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from evcd.utils.validation import check_choice, check_int, is_integer


def check_hidden(hidden: Sequence[int]) -> tuple[int, ...]:
    """``hidden`` as a tuple of positive integers.

    Raises:
        ValueError: empty, or a size that is not an integer >= 1 (the message names it).
    """
    try:
        sizes = tuple(hidden)
    except TypeError:
        raise ValueError(f"hidden={hidden!r}: must be a list of layer sizes, e.g. [512, 256]") from None
    if not sizes:
        raise ValueError("hidden=[]: need at least one hidden layer size, e.g. [512, 256]")
    if not all(is_integer(size) and size >= 1 for size in sizes):
        raise ValueError(f"hidden={list(sizes)!r}: every layer size must be an integer >= 1")
    return tuple(int(s) for s in sizes)


def mlp_trunk(in_dim: int, hidden: Sequence[int]) -> nn.Sequential:
    """``Linear -> ReLU`` for each size in ``hidden``."""
    layers: list[nn.Module] = []
    for size in check_hidden(hidden):
        layers += [nn.Linear(in_dim, size), nn.ReLU()]
        in_dim = size
    return nn.Sequential(*layers)


class QNetwork(nn.Module):
    """``obs -> Q(obs, .)``: an MLP trunk and one linear output per action."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int]) -> None:
        super().__init__()
        sizes = check_hidden(hidden)
        self.trunk = mlp_trunk(obs_dim, sizes)
        self.head = nn.Linear(sizes[-1], n_actions)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values, shape ``(batch, n_actions)``."""
        return self.head(self.trunk(obs))


class DuelingQNetwork(nn.Module):
    """``obs -> V(obs) + A(obs, .) - mean(A(obs, .))``: the trunk feeds a value and an advantage head."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int]) -> None:
        super().__init__()
        sizes = check_hidden(hidden)
        self.trunk = mlp_trunk(obs_dim, sizes)
        self.value = nn.Linear(sizes[-1], 1)
        self.advantage = nn.Linear(sizes[-1], n_actions)

    def streams(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The two heads: ``V`` of shape ``(batch, 1)`` and ``A`` of shape ``(batch, n_actions)``."""
        features = self.trunk(obs)
        return self.value(features), self.advantage(features)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values, shape ``(batch, n_actions)``."""
        value, advantage = self.streams(obs)
        return value + advantage - advantage.mean(dim=-1, keepdim=True)


class StationQNetwork(nn.Module):
    """``Q(s, a) = f(x_a, a)``: one trunk scores every station from its own block of features
    ``x_a`` (its ``D``, ``N``, ``Z``, ...) and its one-hot index.

    Dueling: the trunk's features of station ``a`` give the advantage ``A(s, a)``, their mean over
    the stations gives ``V(s)``; combined as in :class:`DuelingQNetwork`.

    Args:
        obs_dim: observation size, ``blocks x n_actions`` (block-major: all ``D``, then all ``N``, ...).
        n_actions: stations.
        hidden: the trunk's layer sizes.
        dueling: value and advantage heads instead of one output.
    """

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int], dueling: bool = False) -> None:
        super().__init__()
        if obs_dim % n_actions:
            raise ValueError(f"obs_dim={obs_dim}: the station network needs a block of features per "
                             f"station, a multiple of n_actions={n_actions}")  # fmt: skip
        sizes = check_hidden(hidden)
        self.n_actions = n_actions
        self.blocks = obs_dim // n_actions
        self.dueling = dueling
        self.register_buffer("identity", torch.eye(n_actions), persistent=False)
        self.trunk = mlp_trunk(self.blocks + n_actions, sizes)
        self.head = nn.Linear(sizes[-1], 1)  # Q, or the advantage when dueling
        self.value = nn.Linear(sizes[-1], 1) if dueling else None

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values, shape ``(batch, n_actions)``."""
        own = obs.reshape(*obs.shape[:-1], self.blocks, self.n_actions).transpose(-1, -2)
        index = self.identity.expand(*own.shape[:-1], self.n_actions)
        features = self.trunk(torch.cat([own, index], dim=-1))  # (batch, stations, hidden)
        scores = self.head(features).squeeze(-1)
        if self.value is None:
            return scores
        value = self.value(features.mean(dim=-2))
        return value + scores - scores.mean(dim=-1, keepdim=True)


NETWORKS = ("mlp", "station")


def make_q_network(
    obs_dim: int, n_actions: int, hidden: Sequence[int], dueling: bool, network: str = "mlp"
) -> nn.Module:
    """The Q-network: ``network="mlp"``, a :class:`DuelingQNetwork` if ``dueling`` else a
    :class:`QNetwork`; ``"station"``, a :class:`StationQNetwork`.

    Raises:
        ValueError: a non-positive dimension, bad hidden sizes or an unknown ``network``.
    """
    obs_dim = check_int("obs_dim", obs_dim, minimum=1)
    n_actions = check_int("n_actions", n_actions, minimum=1)
    check_choice("network", network, NETWORKS)
    if network == "station":
        return StationQNetwork(obs_dim, n_actions, hidden, dueling)
    cls = DuelingQNetwork if dueling else QNetwork
    return cls(obs_dim, n_actions, hidden)
