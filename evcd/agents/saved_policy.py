"""A trained policy read back from a checkpoint, for any registered agent.

    policy = saved_policy("outputs/train/<run>")            # the run's latest checkpoint (or a file)
    agent = make_agent_for_env(name, env, rng, **{**agent_class(name).checkpoint_options(policy), **options})
    agent.load_state_dict(policy, policy_only=True)

The trainers write the agent's :meth:`~evcd.agents.Agent.state_dict` under ``"agent"`` in every
checkpoint (and its :meth:`~evcd.agents.Agent.policy_state_dict` in ``best/``); this reads it, whoever
wrote the agent.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from evcd.utils.checkpoint import CheckpointError, load_checkpoint


def saved_policy(path: str | Path) -> Mapping[str, Any]:
    """The agent state saved at ``path``: a training run directory (its latest checkpoint), a
    checkpoint folder or file of the trainers, or a file holding an agent state alone.

    Raises:
        CheckpointError: nothing readable there, or no agent state in it.
    """
    return saved_run(path)[0]


def saved_run(path: str | Path) -> tuple[Mapping[str, Any], Mapping[str, Any] | None]:
    """:func:`saved_policy` and the config of the run that saved it (``None`` where the file holds
    none: a ``best/`` folder, an agent state alone).

    Raises:
        CheckpointError: nothing readable there, or no agent state in it.
    """
    payload = load_checkpoint(path)
    agent = payload.get("agent", payload) if isinstance(payload, Mapping) else None
    if not isinstance(agent, Mapping):
        raise CheckpointError(f"checkpoint {str(path)!r} holds no agent state")
    config = payload.get("config") if agent is not payload else None
    return agent, config if isinstance(config, Mapping) else None
