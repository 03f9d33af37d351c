"""From a composed experiment to the worlds of its splits: environment arguments and days.

    cfg = compose_experiment("peak")                              # conf/train.yaml + experiment=peak
    kwargs = split_kwargs(cfg, "eval", seed=0)                    # ChargingNavEnv(**kwargs)
    fleet = split_kwargs(compose_experiment("fleet"), "train", seed=0)   # FleetEnv(**fleet)

One reading of ``conf/`` for everybody: ``scripts/train.py`` builds its training, validation and
evaluation environments with :func:`split_kwargs`, and so do :func:`evcd.experiments.make_env` and
:func:`evcd.experiments.parallel_env` for a user outside the scripts, so the two cannot drift.

A split is a set of background days with its departure window:

- ``train``: ``train.days`` (``train.departure_window``, else ``env.departure_window``);
- ``tuning``: ``train.validation.days`` (the periodic validation's, and the days settings are chosen
  on; ``train.validation.departure_window``, else ``env.departure_window``);
- ``eval``: ``eval.days``, the held-out days of the reported numbers; with ``eval.day_per_seed`` the
  run seed's own block of them (:func:`~evcd.loops.seeds.days_of_seed`: one day for the single
  target, one per evaluation episode for the fleet).

Relative paths are resolved against the directory the process was started from (Hydra's original
working directory inside a Hydra app); a relative ``scenario.path`` that is not there is taken from
the project root, where the shipped scenarios are.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from evcd.experiments.compose import CONF_DIR
from evcd.loops.seeds import days_of_seed
from evcd.scenario.demand import DemandConfig
from evcd.utils.validation import check_choice, check_int, is_integer

#: The splits of an experiment's days.
SPLITS = ("train", "tuning", "eval")
#: The task of each regime family: a regime named ``fleet*`` is the fleet's.
TASKS = ("single", "fleet")

_TUPLE_FIELDS = ("hourly_profile", "battery_wh", "soc_charging", "soc_other", "target_soc")
_PATH_KEYS = ("route_file", "cache_dir")
_DAYS = {"train": "train.days", "tuning": "train.validation.days", "eval": "eval.days"}
_WINDOWS = {"train": "train.departure_window", "tuning": "train.validation.departure_window"}


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
    """Keyword arguments of :class:`~evcd.env.ChargingNavEnv` from ``scenario``, ``evs``, ``env`` and
    ``perturbations`` (an empty block, ``perturbations=none``: ``None``, every day calm).

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
    kwargs["scenario"] = scenario_path(str(cfg.scenario.path))
    block = OmegaConf.select(cfg, "perturbations")
    kwargs["perturbations"] = (OmegaConf.to_container(block, resolve=True) if block else None) or None
    kwargs["charging_points"] = cfg.scenario.charging_points
    if kwargs.get("route_file") is None:
        kwargs["demand"] = demand_config(cfg)
        kwargs["evs"] = int(cfg.evs)
    return kwargs


def scenario_path(path: str) -> str:
    """``scenario.path`` as an absolute path: a relative one from the working directory (Hydra's
    original one in a script) if it is there, else from the project root (where the shipped
    scenarios are), so that the shipped experiments load from any working directory."""
    here = to_absolute_path(path)
    root = CONF_DIR.parent / path
    if not Path(here).exists() and not Path(path).is_absolute() and root.exists():
        return str(root)
    return here


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
    kwargs["guided_share"] = OmegaConf.select(cfg, "fleet.guided_share")
    return kwargs


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


def task_of(cfg: DictConfig) -> str:
    """The config's task (``single`` or ``fleet``).

    Raises:
        ValueError: another task.
    """
    return str(check_choice("task", str(cfg.task), TASKS))


def split_days(cfg: DictConfig, split: str, seed: int) -> tuple[int, ...]:
    """The background days of ``split`` for run ``seed`` (module docstring).

    Raises:
        ValueError: an unknown split (the message lists them), bad days, or tuning days that share a
            day with the training or evaluation days.
    """
    check_choice("split", split, SPLITS)
    days = config_days(cfg, _DAYS[split])
    if split == "eval" and bool(cfg.eval.day_per_seed):
        count = check_int("eval.episodes", cfg.eval.episodes, minimum=1) if task_of(cfg) == "fleet" else 1
        days = days_of_seed(days, seed, count)
    if split == "tuning":
        shared = set(days) & set(split_days(cfg, "train", seed) + split_days(cfg, "eval", seed))
        if shared:
            raise ValueError(f"train.validation.days share {sorted(shared)} with train.days or eval.days: "
                             "validate on tuning days")  # fmt: skip
    return days


def split_kwargs(cfg: DictConfig, split: str, seed: int) -> dict[str, Any]:
    """The environment arguments of ``split`` of the composed ``cfg`` for run ``seed``: the
    :class:`~evcd.env.ChargingNavEnv` ones, or with ``task=fleet`` the
    :class:`~evcd.env.fleet.FleetEnv` ones, on the split's days and window (no SUMO; the env checks
    the values when made).

    Raises:
        ValueError: an unknown split, bad days, or a setting the task does not take.
    """
    base = fleet_kwargs(cfg) if task_of(cfg) == "fleet" else env_kwargs(cfg)
    window = OmegaConf.select(cfg, _WINDOWS[split]) if split in _WINDOWS else None
    if window is not None:
        base["departure_window"] = tuple(window)
    if base.get("forecast_days") is None:  # the history forecaster learns from the training days
        base["forecast_days"] = split_days(cfg, "train", seed)
    return {**base, "demand_seeds": split_days(cfg, split, seed)}


def check_forecaster(cfg: DictConfig) -> None:
    """Refuse the oracle forecaster: it reads the played day's future, an upper bound for analysis
    (``scripts/evaluate.py``), never a training run or a reported result of one."""
    if "forecast" in list(cfg.env.observe):
        spec = cfg.env.forecaster
        name = spec if isinstance(spec, str) else OmegaConf.select(spec, "name")
        if name == "oracle":
            raise ValueError(
                "env.forecaster=oracle reads the day's own future: an upper bound for analysis with "
                "scripts/evaluate.py, never in a training run (use history or trend)"
            )
