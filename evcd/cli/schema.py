"""The structured configs Hydra composes against: settings declared once, in the library's dataclasses.

    register_configs()      # before @hydra.main composes (the scripts call it at import)

- group ``learner``, option ``defaults``: :class:`~evcd.agents.dqn_config.DQNConfig` with its own
  defaults. ``conf/train.yaml`` selects it; the presets ``conf/learner/*.yaml`` (``peak``, ``paper``)
  extend it and set only what they change, and the experiments pick a preset. A ``learner.*`` key
  that is not a field of ``DQNConfig``, or a value of the wrong type, is refused when Hydra composes.
"""

from __future__ import annotations

from hydra.core.config_store import ConfigStore
from omegaconf import OmegaConf

from evcd.agents.dqn_config import DQNConfig

#: The ConfigStore option holding DQNConfig's defaults (group ``learner``).
LEARNER_DEFAULTS = "defaults"


def register_configs() -> None:
    """Put the structured configs into Hydra's ConfigStore (idempotent)."""
    learner = OmegaConf.structured(DQNConfig)
    OmegaConf.set_readonly(learner, False)  # a frozen dataclass; the presets and overrides set fields
    ConfigStore.instance().store(group="learner", name=LEARNER_DEFAULTS, node=learner)
