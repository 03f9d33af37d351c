"""Episodes one after another in one environment (``engine=single``).

A learner sees every transition of an episode (``agent.observe``), then its end
(``agent.end_episode``); the last slot of an episode whose target could no longer be observed
(:data:`~evcd.env.episode_rules.UNOBSERVED`) is not handed over: its next observation is not true.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from evcd.env.episode_rules import UNOBSERVED
from evcd.env.runners.base import (
    EnvRunner,
    EpisodeCallback,
    EpisodeRow,
    EpisodeSpec,
    Policy,
    row_from_info,
)
from evcd.env.transition import Transition


class SingleEnvRunner(EnvRunner):
    """Episodes one after another in one environment (a :class:`~evcd.env.ChargingNavEnv`, or any
    Gymnasium env with a ``Discrete`` action space whose final ``info`` has the keys of
    :class:`~evcd.env.runners.base.EpisodeRow`: ``departure``, ``travel_time``, ``queue_wait``,
    ``reason``, ...).

    Args:
        env: the environment; the runner closes it in :meth:`close`.
    """

    @property
    def n_stations(self) -> int:
        """The environment's number of actions."""
        return int(self.env.action_space.n)

    def run(
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: EpisodeCallback | None = None,
    ) -> list[EpisodeRow]:
        """Play ``specs`` in order (see :meth:`EpisodeRunner.run`)."""
        rows = []
        for spec in specs:
            row = self.episode(spec, agent, explore=explore, learn=learn)
            rows.append(row)
            if on_episode is not None:
                on_episode(row)
        return rows

    def episode(self, spec: EpisodeSpec, agent: Policy, *, explore: bool, learn: bool) -> EpisodeRow:
        """Play one episode to its end; return its row."""
        t0 = time.perf_counter()
        obs, info = self.env.reset(seed=spec.reset_seed, options=spec.options)
        state = agent.new_episode(spec.agent_rng())
        choices: list[int] = []
        total = 0.0
        terminated = truncated = False
        while not (terminated or truncated):
            action = int(agent.decide(np.asarray(obs)[None], [state], explore)[0])
            choices.append(action)
            next_obs, reward, terminated, truncated, info = self.env.step(action)
            if learn and not (truncated and info.get("reason") in UNOBSERVED):
                agent.observe(Transition(obs, action, float(reward), next_obs, terminated, truncated), state)
            obs = next_obs
            total += float(reward)
        if learn:
            agent.end_episode(state)
        return row_from_info(
            spec, info, choices, total, truncated and not terminated, time.perf_counter() - t0
        )
