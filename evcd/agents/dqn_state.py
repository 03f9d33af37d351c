"""The saved form of a DQN agent: its format tag, the checks a checkpoint passes before its networks
are loaded, and the network settings read back from a checkpoint (to rebuild the agent that fits it).

:class:`~evcd.agents.dqn.DQNAgent` writes and reads the state (``state_dict`` / ``load_state_dict``);
this module holds what is about the file rather than the agent, so that scripts can ask a checkpoint
what it holds without building anything.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from evcd.utils.checkpoint import CheckpointError, to_numpy

STATE_FORMAT = "evcd.agents.dqn/2"
#: the saved policy settings: how each is read back, and, for those added after the format, the value a
#: checkpoint made before it holds (the MLP, side by side, no rule estimate nor prior)
_SETTINGS: dict[str, tuple[Callable[[Any], Any], tuple[Any, ...]]] = {
    "hidden": (tuple, ()),
    "network": (str, ("mlp",)),
    "dueling": (bool, ()),
    "double": (bool, ()),
    "in_turn": (bool, (False,)),
    "rule_estimate": (bool, (False,)),
    "rule_prior": (bool, (False,)),
    "rule_prior_bound_s": (lambda v: None if v is None else float(v), (None,)),
    "rule_prior_relative": (bool, (False,)),
    "switch_margin_s": (float, (0.0,)),
}
#: the settings a checkpoint's networks must share with the agent that loads them (all but how it
#: decides: a fleet tick in turn or side by side, the switching margin)
CHECKED_SETTINGS = tuple(key for key in _SETTINGS if key not in ("in_turn", "switch_margin_s"))


def check_policy_state(
    state: Any, input_scale: np.ndarray, settings: dict[str, Any], layout: str
) -> np.ndarray:
    """Check that ``state`` is a DQN agent state of this evcd that fits an agent, and return its
    input scale.

    Args:
        state: what ``DQNAgent.state_dict`` wrote.
        input_scale: the agent's own input scale (its shape is the observation size).
        settings: the agent's ``hidden``, ``network``, ``dueling`` and ``double`` (they must match the
            saved ones).
        layout: how the agent's observation is made up, for the message (e.g. ``"3 x 5 stations"``).

    Raises:
        CheckpointError: another format, another observation size, or other network settings (the
            message names which).
    """
    found = state.get("format") if isinstance(state, dict) else type(state).__name__
    if found != STATE_FORMAT:
        earlier = isinstance(found, str) and found.startswith("evcd.agents.dqn/")
        why = " (an earlier evcd's: retrain with this version)" if earlier else ""
        raise CheckpointError(f"not a DQN agent state of this evcd (format {found!r}, expected "
                              f"{STATE_FORMAT!r}){why}")  # fmt: skip
    scale = np.asarray(to_numpy(state["input_scale"]), np.float32)
    if scale.shape != input_scale.shape:
        raise CheckpointError(
            f"the checkpoint was made for observations of size {scale.shape[0]}; this "
            f"environment's are {input_scale.shape[0]} ({layout}; the observation options, env.observe, "
            "add blocks: evaluate with those it was trained with)"
        )
    saved = _network_settings(state["config"])
    for key, value in settings.items():
        if list(np.atleast_1d(saved[key])) != list(np.atleast_1d(value)):
            raise CheckpointError(f"the checkpoint's agent has {key}={saved[key]!r}; this one has "
                                  f"{key}={value!r} (use the same agent settings)")  # fmt: skip
    return scale


def policy_settings(agent: Any) -> dict[str, Any]:
    """The network settings (``hidden``, ``network``, ``double``, ``dueling``, ``rule_estimate``,
    ``rule_prior``, ``rule_prior_bound_s``, ``rule_prior_relative``) of a saved DQN policy and how it
    decides (a fleet tick ``in_turn``, its ``switch_margin_s``), so that a policy can be rebuilt to load
    it and act as it was trained.

    Raises:
        CheckpointError: ``agent`` is not a DQN agent's state.
    """
    if not isinstance(agent, Mapping) or agent.get("format") != STATE_FORMAT:
        raise CheckpointError("the checkpoint does not hold a DQN agent")
    saved = _network_settings(agent["config"])
    return {key: read(saved[key]) for key, (read, _) in _SETTINGS.items()}


def _network_settings(saved: dict[str, Any]) -> dict[str, Any]:
    """A saved agent config, with the settings a checkpoint made before they existed holds
    (:data:`_SETTINGS`)."""
    return {**{key: old[0] for key, (_, old) in _SETTINGS.items() if old}, **saved}
