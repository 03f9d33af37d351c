"""Turning a composed Hydra config into library arguments (shared by ``scripts/*.py``).

Library code takes explicit arguments; these helpers are the one place where the scripts' config
layout (``conf/``) meets them: ``scenario.*`` + top-level ``evs`` -> :class:`DemandConfig`,
``scenario.*`` + ``env.*`` -> :class:`~evcd.env.ChargingNavEnv` keyword arguments, ``agent`` +
``learner`` -> a dispatcher's arguments. Relative paths are resolved against the directory the
script was started from (Hydra's original cwd).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from evcd.agents import agent_class
from evcd.agents.dqn_config import DQNConfig
from evcd.loops.hindsight import check_dispatcher, dispatcher_learns
from evcd.scenario.demand import DemandConfig
from evcd.utils.validation import check_int, is_integer

_TUPLE_FIELDS = ("hourly_profile", "battery_wh", "soc_charging", "soc_other", "target_soc")
_PATH_KEYS = ("route_file", "cache_dir")


def demand_config(cfg: DictConfig) -> DemandConfig:
    """The DemandConfig of a composed config (``scenario.demand`` plus the top-level ``evs``).

    Raises:
        ValueError: a value out of range (the message names it).
    """
    evs = check_int("evs", cfg.evs, minimum=0)
    d = OmegaConf.to_container(cfg.scenario.demand, resolve=True)
    for key in _TUPLE_FIELDS:
        d[key] = tuple(d[key])
    return DemandConfig(evs=evs, **d)


def env_kwargs(cfg: DictConfig) -> dict[str, Any]:
    """Keyword arguments of :class:`~evcd.env.ChargingNavEnv` from ``scenario``, ``evs`` and ``env``.

    With ``env.route_file`` set, the route file is the whole background day: ``evs`` and
    ``scenario.demand`` are left out (the env refuses both together).

    Raises:
        ValueError: a demand value out of range (the env checks the rest when constructed).
    """
    kwargs: dict[str, Any] = OmegaConf.to_container(cfg.env, resolve=True)
    kwargs["departure_window"] = tuple(kwargs["departure_window"])
    kwargs["demand_seeds"] = tuple(kwargs["demand_seeds"])
    for key in _PATH_KEYS:
        if kwargs.get(key) is not None:
            kwargs[key] = to_absolute_path(str(kwargs[key]))
    kwargs["scenario"] = to_absolute_path(str(cfg.scenario.path))
    kwargs["charging_points"] = cfg.scenario.charging_points
    if kwargs.get("route_file") is None:
        kwargs["demand"] = demand_config(cfg)
        kwargs["evs"] = int(cfg.evs)
    return kwargs


def fleet_kwargs(cfg: DictConfig) -> dict[str, Any]:
    """Keyword arguments of :class:`~evcd.env.fleet.FleetEnv` (``task=fleet``): :func:`env_kwargs`
    without the single environment's protocol options, plus ``fleet.guided_share``.

    Raises:
        ValueError: a single-target-only setting (``env.protocol=paper``, ``env.gui=true``), or a
            demand value out of range.
    """
    kwargs = env_kwargs(cfg)
    if kwargs.pop("protocol") != "fast":
        raise ValueError("env.protocol=paper is for the single target (task=single): the fleet runs from "
                         "the day's snapshots (protocol fast)")  # fmt: skip
    if kwargs.pop("gui"):
        raise ValueError("env.gui=true is for the single target (task=single): the fleet runs headless")
    kwargs.pop("day_end")  # the paper protocol's
    kwargs["guided_share"] = OmegaConf.select(cfg, "fleet.guided_share")
    return kwargs


def agent_params(cfg: DictConfig) -> tuple[str, dict[str, Any]]:
    """The dispatcher's name and constructor arguments from ``agent``; a learner that takes the
    ``learner`` block (:attr:`~evcd.agents.Agent.learner_block`: the DQN learners) also gets ``config``,
    the :class:`~evcd.agents.dqn_config.DQNConfig` of the top-level ``learner`` block.

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
    """The :class:`~evcd.agents.dqn_config.DQNConfig` of a composed ``learner`` block (its schema).

    Raises:
        ValueError: a value out of range (the message names it).
    """
    values = OmegaConf.to_container(learner, resolve=True)
    return DQNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def config_days(cfg: DictConfig, key: str) -> tuple[int, ...]:
    """The demand seeds listed at ``key`` (e.g. ``train.days``).

    Raises:
        ValueError: not a non-empty list of integers >= 0.
    """
    days = OmegaConf.to_container(OmegaConf.select(cfg, key), resolve=True)
    if not isinstance(days, list) or not days or not all(is_integer(d) and d >= 0 for d in days):
        raise ValueError(f"{key}={days!r}: must be a non-empty list of demand seeds (integers >= 0), "
                         "e.g. [0]")  # fmt: skip
    return tuple(int(d) for d in days)


def compose_train(conf_dir: str | Path, *overrides: str) -> DictConfig:
    """The config ``scripts/train.py <overrides>`` composes (for tools outside Hydra's entry points,
    such as the benchmark)."""
    from hydra import compose, initialize_config_dir

    from evcd.cli.schema import register_configs

    register_configs(conf_dir)
    with initialize_config_dir(config_dir=str(Path(conf_dir).resolve()), version_base="1.3"):
        return compose("train", overrides=list(overrides))
