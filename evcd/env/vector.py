"""Several environments in parallel: one process (one libsumo simulation) per environment.

    if __name__ == "__main__":                   # required in a script: see below
        envs = make_vector_env(4, evs=400)       # AsyncVectorEnv over 4 spawned processes
        obs, infos = envs.reset(seed=0)          # sub-environment i gets seed 0 + i
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())

The background days' snapshots are built (or verified) in this process first, so the workers only
read the cache; processes are *spawned*, not forked, because libsumo's state must not be copied.
A spawned worker imports the main module again: a script that makes the vector environment at its
top level, without the ``if __name__ == "__main__":`` guard, makes it again in every worker, and the
workers die (Gymnasium reports a bare ``ConnectionResetError`` or ``EOFError``). Put the code that
makes and uses the environments under the guard (or in a function it calls).
"""

from __future__ import annotations

import functools
import logging
from typing import Any

import gymnasium

from evcd.env.charging_nav import ChargingNavEnv
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)


def make_vector_env(
    num_envs: int, *, prepare: bool = True, context: str = "spawn", **env_kwargs: Any
) -> gymnasium.vector.AsyncVectorEnv:
    """An :class:`~gymnasium.vector.AsyncVectorEnv` of ``num_envs`` :class:`ChargingNavEnv`\\ s.

    Args:
        num_envs: number of worker processes (>= 1).
        prepare: build the snapshot cache here before the workers start (fast protocol).
        context: multiprocessing start method (``"spawn"``: never fork a process that holds libsumo).
        env_kwargs: :class:`ChargingNavEnv` arguments, the same for every worker.

    Raises:
        ValueError: ``num_envs`` < 1, or an invalid environment argument (checked here, before any
            worker starts).
    """
    check_int("num_envs", num_envs, minimum=1)
    probe = ChargingNavEnv(**env_kwargs)  # validates the arguments; SUMO only runs if it must build
    try:
        if prepare and probe.config.protocol == "fast":
            probe.prepare()
    finally:
        probe.close()
    factory = functools.partial(ChargingNavEnv, **env_kwargs)
    log.info("starting %d environment processes (%s)", num_envs, context)
    return gymnasium.vector.AsyncVectorEnv([factory] * num_envs, context=context)
