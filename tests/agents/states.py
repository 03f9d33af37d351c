"""Equality of agent states, and the options of a saved DQN policy, for the learners' checkpoint tests
(shared by test_dqn and test_ppo)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from evcd.agents.dqn import DQNAgent
from evcd.agents.saved_policy import saved_policy


def np_state_equal(a: Any, b: Any) -> bool:
    """Two states of numpy's legacy global generator (``np.random.get_state()``) are equal."""
    return a[0] == b[0] and np.array_equal(a[1], b[1]) and tuple(a[2:]) == tuple(b[2:])


def state_equal(a: Any, b: Any) -> bool:
    """Deep equality of state dicts (tensors with torch.equal, arrays with array_equal, NaN == NaN)."""
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, np.ndarray):
        return np.array_equal(a, np.asarray(b))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(state_equal(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(state_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return a == b


def saved_options(path: str | Path) -> dict[str, Any]:
    """The options a DQN policy saved at ``path`` is rebuilt with, read as ``scripts/evaluate.py``
    reads them (:func:`~evcd.agents.saved_policy.saved_policy`, then
    :meth:`~evcd.agents.dqn.DQNAgent.checkpoint_options`)."""
    return DQNAgent.checkpoint_options(saved_policy(path))
