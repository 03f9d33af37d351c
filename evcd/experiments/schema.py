"""The structured configs Hydra composes against: settings declared once, in the library's classes.

    register_configs(conf_dir)      # before @hydra.main composes (the scripts call it at import)

- group ``learner``, option ``defaults``: :class:`~evcd.agents.dqn.DQNConfig` with its own
  defaults. ``conf/train.yaml`` selects it; the presets ``conf/learner/*.yaml`` (``peak``, ``paper``)
  extend it and set only what they change, and the experiments pick a preset. A ``learner.*`` key
  that is not a field of ``DQNConfig``, or a value of the wrong type, is refused when Hydra composes.
- group ``agent``: one option per registered agent that ``conf/agent`` holds no file for (an agent of
  another package, or evcd's PPO): ``name`` and the agent's declared
  :attr:`~evcd.agents.Agent.options` with their defaults (and those its name implies), plus
  ``checkpoint: null`` for a learner (``scripts/evaluate.py agent.checkpoint=...``). So
  ``agent=<name>`` composes for every registered agent, and ``agent.<option>=...`` sets its options.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import OmegaConf

from evcd.agents import agent_class, agent_defaults, agent_names
from evcd.agents.dqn import DQNConfig

#: The ConfigStore option holding DQNConfig's defaults (group ``learner``).
LEARNER_DEFAULTS = "defaults"


def agent_block(name: str) -> dict[str, Any]:
    """The Hydra block ``agent`` of the registered agent ``name``, from its declared options."""
    cls = agent_class(name)
    options = {**cls.options, **{k: v for k, v in agent_defaults(name).items() if k in cls.options}}
    if cls.learns:
        options.setdefault("checkpoint", None)
    return {"name": name, **{k: list(v) if isinstance(v, tuple) else v for k, v in options.items()}}


def register_configs(conf_dir: str | Path) -> None:
    """Put the structured configs into Hydra's ConfigStore (idempotent): the ``learner`` schema, and
    an ``agent`` option for every registered agent without a file in ``<conf_dir>/agent``."""
    store = ConfigStore.instance()
    learner = OmegaConf.structured(DQNConfig)
    OmegaConf.set_readonly(learner, False)  # a frozen dataclass; the presets and overrides set fields
    store.store(group="learner", name=LEARNER_DEFAULTS, node=learner)
    files = Path(conf_dir) / "agent"
    for name in agent_names():
        if not (files / f"{name}.yaml").exists():
            store.store(group="agent", name=name, node=agent_block(name))
