"""evcd's worlds for other people's algorithms: an experiment's environments from Python.

    import gymnasium, evcd
    env = gymnasium.make("evcd/ChargingNav-v1", experiment="peak", split="train")   # the README's world
    test = gymnasium.make("evcd/ChargingNav-v1", experiment="peak", split="eval")   # its held-out days
    from evcd import experiments
    fleet = experiments.parallel_env(experiment="fleet", split="eval", run_seed=0)   # the fleet table's
    turns = experiments.env(experiment="fleet", split="train")                       # its AEC form

``make_env`` is what the Gymnasium id ``evcd/ChargingNav-v1`` makes. With an ``experiment`` (a file of
``conf/experiment/``: :func:`~evcd.experiments.compose.experiment_names`) the environment is the one
``scripts/train.py experiment=<name>`` builds for the ``split`` (:mod:`evcd.experiments.worlds`:
``train``, ``tuning`` or ``eval``, each with its days and departure window) of run ``run_seed``
(which only matters where the experiment gives each seed its own held-out days), so an algorithm
written elsewhere meets the very episodes evcd's learners meet: ``reset(seed=s)`` draws the same
day, departure and origin as an evcd run's episode of reset seed ``s``
(:func:`~evcd.loops.seeds.episode_spec`). Keyword arguments override the experiment's environment
arguments (``evs=300``), ``overrides`` are Hydra overrides of the composition (``["evs=300"]``:
every setting the script takes).

Observations are normalised by default here (``normalize_obs=True``: distances in km, vehicles on
the route in tens, vehicles at a station in multiples of its charging points, and the fleet's ``H``
like ``Z``), what a network wants; evcd's own runs normalise inside their learners and keep the
environment's raw units (metres, vehicles). Pass ``normalize_obs=False`` for the raw units. Neither
changes an episode.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
from pettingzoo import AECEnv
from pettingzoo.utils.conversions import parallel_to_aec

from evcd.env import vector
from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.fleet import FleetEnv
from evcd.env.sweep import SweepVectorEnv
from evcd.experiments.compose import compose_experiment
from evcd.experiments.worlds import split_kwargs, task_of
from evcd.utils.validation import check_int


def _world(
    experiment: str | None, split: str, run_seed: int, overrides: Sequence[str], task: str
) -> dict[str, Any]:
    """The experiment's environment arguments for ``split`` (none without an experiment)."""
    if experiment is None:
        if split != "train" or run_seed or overrides:
            raise ValueError("split, run_seed and overrides choose among an experiment's worlds: give "
                             "experiment=... too (or pass the environment's own arguments)")  # fmt: skip
        return {}
    check_int("run_seed", run_seed, minimum=0)
    cfg = compose_experiment(experiment, overrides)
    if task_of(cfg) != task:
        other = "evcd.experiments.parallel_env" if task == "single" else "evcd.experiments.make_env"
        raise ValueError(f"experiment={experiment!r} is a {task_of(cfg)}-task experiment: make it with "
                         f"{other}")  # fmt: skip
    return split_kwargs(cfg, split, run_seed)


def make_env(
    experiment: str | None = None,
    split: str = "train",
    run_seed: int = 0,
    overrides: Sequence[str] = (),
    **kwargs: Any,
) -> ChargingNavEnv:
    """A :class:`~evcd.env.ChargingNavEnv` in ``experiment``'s world for ``split`` (module docstring),
    or, without an experiment, made from ``kwargs`` alone; observations normalised unless
    ``normalize_obs=False``.

    Raises:
        ValueError: an unknown experiment or split (the message lists the known ones), a fleet
            experiment, or a bad value (before SUMO starts).
    """
    world = _world(experiment, split, run_seed, overrides, "single")
    return ChargingNavEnv(**{**world, "normalize_obs": True, **kwargs})


def parallel_env(
    experiment: str | None = None,
    split: str = "train",
    run_seed: int = 0,
    overrides: Sequence[str] = (),
    **kwargs: Any,
) -> FleetEnv:
    """A :class:`~evcd.env.fleet.FleetEnv` (PettingZoo ``ParallelEnv``) in ``experiment``'s world for
    ``split`` (module docstring; ``experiment="fleet"``: the fleet table's), or from ``kwargs`` alone;
    observations normalised unless ``normalize_obs=False``.

    Raises:
        ValueError: an unknown experiment or split, a single-target experiment, or a bad value.
    """
    world = _world(experiment, split, run_seed, overrides, "fleet")
    return FleetEnv(**{**world, "normalize_obs": True, **kwargs})


def env(
    experiment: str | None = None,
    split: str = "train",
    run_seed: int = 0,
    overrides: Sequence[str] = (),
    **kwargs: Any,
) -> AECEnv:
    """:func:`parallel_env` in PettingZoo's AEC form (:func:`evcd.env.fleet.env`, by PettingZoo's name for
    the AEC factory: the agents due at a tick act in turn, the tick runs when the last has acted; the
    same episodes)."""
    return parallel_to_aec(parallel_env(experiment, split, run_seed, overrides, **kwargs))


def make_vector_env(
    num_envs: int,
    experiment: str | None = None,
    split: str = "train",
    run_seed: int = 0,
    overrides: Sequence[str] = (),
    **kwargs: Any,
) -> gymnasium.vector.AsyncVectorEnv:
    """:func:`evcd.env.make_vector_env` (``num_envs`` spawned processes, one SUMO each) in
    ``experiment``'s world for ``split``, observations normalised unless ``normalize_obs=False``;
    keep the ``if __name__ == "__main__":`` guard in a script (the workers re-import it).

    Raises:
        ValueError: ``num_envs`` < 1, an unknown experiment or split, or a bad value (before any
            worker starts).
    """
    world = _world(experiment, split, run_seed, overrides, "single")
    return vector.make_vector_env(num_envs, **{**world, "normalize_obs": True, **kwargs})


def make_sweep_env(
    num_envs: int,
    experiment: str | None = None,
    split: str = "train",
    run_seed: int = 0,
    overrides: Sequence[str] = (),
    **kwargs: Any,
) -> SweepVectorEnv:
    """The batched engine as a Gymnasium vector environment (:class:`~evcd.env.sweep.SweepVectorEnv`:
    ``num_envs`` targets on one decision clock in one SUMO run per sweep) in ``experiment``'s world
    for ``split``, observations normalised unless ``normalize_obs=False``.

    Raises:
        ValueError: ``num_envs`` < 1, an unknown experiment or split, or a bad value (before SUMO).
    """
    check_int("num_envs", num_envs, minimum=1)
    return SweepVectorEnv(make_env(experiment, split, run_seed, overrides, **kwargs), num_envs)
