"""Turning a composed Hydra config into library arguments (shared by ``scripts/*.py``).

Library code takes explicit arguments; these helpers are the one place where the scripts' config
layout (``conf/``) meets them: ``scenario.*`` + top-level ``evs`` -> :class:`DemandConfig`,
``scenario.*`` + ``env.*`` -> :class:`~evcd.env.ChargingNavEnv` keyword arguments. Relative paths
are resolved against the directory the script was started from (Hydra's original cwd).
:func:`stop_on_bad_setting` is how a script's ``main`` ends a run on a bad setting.
"""

from __future__ import annotations

import logging
import sys
from typing import Any, NoReturn

from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from evcd.scenario.demand import DemandConfig

_TUPLE_FIELDS = ("hourly_profile", "battery_wh", "soc_charging", "soc_other", "target_soc")
_PATH_KEYS = ("route_file", "cache_dir")


def demand_config(cfg: DictConfig) -> DemandConfig:
    """The DemandConfig of a composed config (``scenario.demand`` plus the top-level ``evs``).

    Raises:
        ValueError: a value out of range (the message names it).
    """
    evs = cfg.evs
    if isinstance(evs, bool) or not isinstance(evs, int):
        raise ValueError(f"evs={evs!r}: must be an integer >= 0")
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


def check_integer(value: Any, key: str, minimum: int) -> int:
    """``value`` if it is an integer >= ``minimum``.

    Raises:
        ValueError: naming ``key``, the value and what is allowed.
    """
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{key}={value!r}: must be an integer >= {minimum}")
    return value


def agent_params(cfg: DictConfig) -> tuple[str, dict[str, Any]]:
    """The agent's registry name and constructor arguments from ``agent`` (and, for learning agents,
    the top-level ``learner`` block, which the ``agent`` keys override).

    Raises:
        ValueError: the agent name is unknown (the message lists the known ones).
    """
    from evcd.agents import agent_class

    params: dict[str, Any] = OmegaConf.to_container(cfg.agent, resolve=True)
    name = str(params.pop("name"))
    cls = agent_class(name)
    learner = OmegaConf.select(cfg, "learner")
    if cls.learns and learner is not None:
        params = {**OmegaConf.to_container(learner, resolve=True), **params}
    for key, value in params.items():
        if isinstance(value, list) and key == "hidden":
            params[key] = tuple(value)
    return name, params


def stop_on_bad_setting(exc: Exception, log: logging.Logger) -> NoReturn:
    """End a script's run on ``exc`` (a bad setting, a missing file, a corrupted checkpoint), logged as
    an error.

    A single run exits with code 2: the message names the value, no traceback. In a multirun (``-m``)
    ``exc`` is re-raised instead: Hydra's ``run_job`` catches ``Exception`` (not ``SystemExit``), records
    this job as FAILED and the launcher goes on with the other jobs; once they are done the sweep ends
    with Hydra's error naming the failed job's overrides (exit code 1). A ``SystemExit`` would escape
    ``run_job`` and end the whole sweep at once: the basic launcher stops at that job, and the joblib
    launcher exits with code 2 without finishing (or even starting) the others.
    """
    log.error("%s", exc)
    if HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN:
        raise exc
    sys.exit(2)
