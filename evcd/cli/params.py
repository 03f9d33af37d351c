"""Turning a composed Hydra config into a dispatcher's arguments (shared by ``scripts/*.py``):
``agent`` + ``learner`` -> the agent's name and constructor arguments. The environments' arguments
come from :mod:`evcd.experiments.worlds` (which a Python user outside the scripts reads too).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from omegaconf import DictConfig, OmegaConf

from evcd.agents import agent_class
from evcd.agents.dqn import DQNConfig
from evcd.loops.fleet_bound import FleetBound
from evcd.loops.hindsight import HindsightBound, check_dispatcher, dispatcher_learns


def agent_params(cfg: DictConfig) -> tuple[str, dict[str, Any]]:
    """The dispatcher's name and constructor arguments from ``agent``; a learner that takes the
    ``learner`` block (:attr:`~evcd.agents.Agent.learner_block`: the DQN learners) also gets ``config``,
    the :class:`~evcd.agents.dqn.DQNConfig` of the top-level ``learner`` block.

    Raises:
        ValueError: the name is unknown (the message lists the known ones), or a learner value is out
            of range (the message names it).
    """
    params: dict[str, Any] = OmegaConf.to_container(cfg.agent, resolve=True)
    name = check_dispatcher(params.pop("name"))
    learner = OmegaConf.select(cfg, "learner")
    if dispatcher_learns(name) and agent_class(name).learner_block and learner is not None:
        params["config"] = learner_config(learner)
    return name, params


def learner_config(learner: DictConfig) -> DQNConfig:
    """The :class:`~evcd.agents.dqn.DQNConfig` of a composed ``learner`` block (its schema).

    Raises:
        ValueError: a value out of range (the message names it).
    """
    values = OmegaConf.to_container(learner, resolve=True)
    return DQNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def check_learner_overrides(name: str, overrides: Sequence[str]) -> None:
    """Refuse command-line ``learner`` settings (``learner.lr=...``, ``learner=paper``) for a learner
    that does not read the ``learner`` block (e.g. ``ppo``, whose settings are ``agent.*``), so that
    they are not silently ignored. A rule ignores them (a sweep may mix rules with learners).

    Raises:
        ValueError: naming the first such override and where the agent's settings are.
    """
    for override in overrides:
        key = str(override).lstrip("+~").split("=", 1)[0]
        if key != "learner" and not key.startswith("learner."):
            continue
        if name in (HindsightBound.name, FleetBound.name):  # the bounds learn nothing
            return
        learner = agent_class(name)  # an unknown name: ValueError listing the known ones
        if not learner.learns or learner.learner_block:
            return
        raise ValueError(f"{override!r}: agent={name} does not read the DQN learners' `learner` block; "
                         f"its settings are agent.* (e.g. agent.lr=...; python scripts/train.py "
                         f"agent={name} --cfg job lists them)")  # fmt: skip
