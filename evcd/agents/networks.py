"""Q-networks: a multilayer perceptron and its dueling variant (Wang et al. 2016).

    net = make_q_network(obs_dim=15, n_actions=5, hidden=(512, 256), dueling=True)
    q = net(torch.zeros(1, 15))                   # (batch, n_actions)

Both share the same trunk (``Linear`` + ``ReLU`` per hidden size). The plain network ends in one
linear layer to the Q-values; the dueling one ends in a value head ``V(s)`` and an advantage head
``A(s, a)``, combined as ``V + A - mean_a(A)`` so that the split is identifiable.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from evcd.utils.validation import check_int, is_integer


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


def make_q_network(obs_dim: int, n_actions: int, hidden: Sequence[int], dueling: bool) -> nn.Module:
    """A :class:`DuelingQNetwork` if ``dueling`` else a :class:`QNetwork`.

    Raises:
        ValueError: a non-positive dimension or bad hidden sizes.
    """
    obs_dim = check_int("obs_dim", obs_dim, minimum=1)
    n_actions = check_int("n_actions", n_actions, minimum=1)
    cls = DuelingQNetwork if dueling else QNetwork
    return cls(obs_dim, n_actions, hidden)
