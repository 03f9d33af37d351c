"""How loops reach episodes: one interface (:class:`EpisodeRunner`), three runners.

    runner = make_runner(ChargingNavEnv(evs=400), engine="batched")   # or "single"
    rows = runner.run(specs, agent, explore=True, learn=True)

- :mod:`evcd.env.runners.base`: the interface and what goes through it (:class:`EpisodeSpec` in,
  :class:`EpisodeRow` out, the :class:`Policy` an agent offers);
- :mod:`evcd.env.runners.single`: one :class:`~evcd.env.ChargingNavEnv` episode after another;
- :mod:`evcd.env.runners.batched`: many episodes co-simulated in one SUMO run of their day (planning),
  with :mod:`~evcd.env.runners.batch` (the simulation loop), :mod:`~evcd.env.runners.live` (a
  target's state) and :mod:`~evcd.env.runners.ghost` (its place in a station's queue);
- :mod:`evcd.env.runners.fleet`: fleet episodes (``task=fleet``), every guided EV decided by one
  dispatcher (:class:`FleetRunner`; its rows are :class:`FleetEpisode` rows).
"""

from __future__ import annotations

from typing import Any

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.runners.base import (
    EpisodeCallback,
    EpisodeRow,
    EpisodeRunner,
    EpisodeSpec,
    Policy,
    row_from_info,
)
from evcd.env.runners.batched import DEFAULT_BATCH_EPISODES, BatchedRunner
from evcd.env.runners.fleet import FleetEpisode, FleetRunner
from evcd.env.runners.single import SingleEnvRunner
from evcd.utils.validation import check_choice, check_int

#: The runners ``engine=`` names.
ENGINES = ("batched", "single")


def check_engine(engine: Any, batch_episodes: Any) -> tuple[str, int]:
    """``(engine, batch_episodes)`` checked without starting anything.

    Raises:
        ValueError: an unknown engine or a batch size that is not an integer >= 1.
    """
    engine = str(check_choice("engine", engine, ENGINES))
    return engine, check_int("batch_episodes", batch_episodes, minimum=1)


def make_runner(
    env: ChargingNavEnv, engine: str = "batched", batch_episodes: int = DEFAULT_BATCH_EPISODES
) -> EpisodeRunner:
    """The runner ``engine`` names over ``env``: ``"batched"`` (:class:`BatchedRunner`) or
    ``"single"`` (:class:`SingleEnvRunner`, one episode after another).

    Raises:
        ValueError: an unknown engine or a bad ``batch_episodes``.
    """
    engine, batch_episodes = check_engine(engine, batch_episodes)
    return SingleEnvRunner(env) if engine == "single" else BatchedRunner(env, batch_episodes)


__all__ = [
    "DEFAULT_BATCH_EPISODES",
    "ENGINES",
    "BatchedRunner",
    "EpisodeCallback",
    "EpisodeRow",
    "EpisodeRunner",
    "EpisodeSpec",
    "FleetEpisode",
    "FleetRunner",
    "Policy",
    "SingleEnvRunner",
    "check_engine",
    "make_runner",
    "row_from_info",
]
