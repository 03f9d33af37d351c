"""The experiments as ``scripts/train.py`` composes them, for Python code outside Hydra's entry points.

    compose_experiment("peak")                          # what `train.py experiment=peak` composes
    compose_experiment("fleet", ["evs=400"])            # with Hydra overrides
    experiment_names()                                  # ('fleet', 'paper', 'peak', 'table')

An experiment is a file of ``conf/experiment/`` (its world: scenario, EV count, window, reward,
observation units, days per split; and its training protocol); this module composes it with the
rest of ``conf/`` exactly as the script does (Hydra's compose API, the same structured configs:
:mod:`evcd.experiments.schema`), so a Python user meets the world a run of the script meets.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig

#: The configuration folder of the repository (``conf/``), next to the package.
CONF_DIR = Path(__file__).resolve().parents[2] / "conf"


def experiment_names(conf_dir: str | Path = CONF_DIR) -> tuple[str, ...]:
    """The experiments ``conf_dir`` defines (``conf/experiment/*.yaml``), sorted."""
    return tuple(sorted(p.stem for p in (Path(conf_dir) / "experiment").glob("*.yaml")))


def check_experiment(name: object, conf_dir: str | Path = CONF_DIR) -> str:
    """``name`` if it is an experiment of ``conf_dir``.

    Raises:
        ValueError: naming it and the known experiments.
    """
    known = experiment_names(conf_dir)
    if name not in known:
        raise ValueError(f"experiment={name!r}: unknown; the experiments: {', '.join(known)}")
    return str(name)


def compose(config_name: str, overrides: Sequence[str] = (), conf_dir: str | Path = CONF_DIR) -> DictConfig:
    """The config ``scripts/<config_name>.py <overrides>`` composes (``train`` or ``evaluate``)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from evcd.experiments.schema import register_configs

    register_configs(conf_dir)
    with initialize_config_dir(config_dir=str(Path(conf_dir).resolve()), version_base="1.3"):
        return hydra_compose(config_name, overrides=list(overrides))


def compose_experiment(
    experiment: str, overrides: Sequence[str] = (), conf_dir: str | Path = CONF_DIR
) -> DictConfig:
    """What ``scripts/train.py experiment=<experiment> <overrides>`` composes.

    Raises:
        ValueError: an unknown experiment (the message lists them).
    """
    return compose("train", [f"experiment={check_experiment(experiment, conf_dir)}", *overrides], conf_dir)
