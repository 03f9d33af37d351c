"""Many episodes in one SUMO run: targets co-simulated in their background day (``engine=batched``).

    runner = BatchedRunner(ChargingNavEnv(evs=400, departure_window=(25200, 36000)), batch_episodes=25)
    rows = runner.run(specs, agent, explore=True, learn=True)

What an episode costs is the city around its target, and the city is the same for every target of
a day: :class:`BatchedRunner` simulates it once for many. It plays the episodes named by
:class:`~evcd.env.runners.base.EpisodeSpec`\\ s, like :class:`~evcd.env.runners.single.SingleEnvRunner`,
with the
semantics of :class:`~evcd.env.ChargingNavEnv`:

- **Plans.** Each episode's background day and target (departure, origin, battery) come from
  :meth:`ChargingNavEnv.draw_episode` with the generator ``env.reset(seed=s)`` would use: the same
  code, so ``engine=single`` and ``engine=batched`` play the same episodes.
- **Batches.** Episodes are grouped by background day, sorted by departure and cut into batches of
  ``batch_episodes``. A batch is one simulation from the latest snapshot before its first departure;
  each target enters at its own departure (its own vehicle, redrawn origin if it cannot be
  inserted, as the environment does), is asked for a station at each of its own decision slots, and
  ends by the episode's rules (:mod:`evcd.env.episode_rules`, shared with the environment): charge
  start, or a truncation (``teleported``, ``vanished``,
  ``stuck``, ``max_travel_time``, ``sumo_error``; ``not_inserted`` where the environment would
  raise). While no target is in flight the simulation jumps ahead by loading a later snapshot.
- **Targets never see each other at stations.** A target waits beside the queue as a
  :class:`~evcd.env.runners.ghost.GhostWait` (it leaves the simulation on arriving, so waiting targets never
  fill a car park), starts charging exactly when the FIFO would give it a point were it the only
  target, and may still leave to drive elsewhere (it re-enters the road at the car park). ``N`` and
  ``Z`` count background vehicles only (``Z`` of its own station counts the waiting target itself,
  as the environment's queue does). On the road the targets are ordinary vehicles.
- **Decisions and transitions.** All targets due at the same second are decided in one
  ``agent.decide`` call (one forward pass for a network agent), each with its own episode state
  (generator, exploration draw). At each second, the transitions that
  ended are handed to ``observe`` first, in the order of the specs, then the due targets decide:
  the same specs, agent state and batch size give the same rows and the same learning.
- **Errors.** A SUMO error in a target's command truncates that episode (``sumo_error``); one that
  breaks the simulation truncates the batch's episodes in flight, and the run goes on from a fresh
  start.

The loop of one batch is :mod:`evcd.env.runners.batch`; a target's state, :mod:`evcd.env.runners.live`.
In the ``paper`` protocol a batch simulates its day from 00:00 (no snapshots) and does not run on to
the end of the day (nothing after the last charge start changes a result).
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Sequence

import numpy as np
from gymnasium.utils import seeding

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.reward import reward_fn
from evcd.env.runners.base import EnvRunner, EpisodeCallback, EpisodeRow, EpisodeSpec, Policy
from evcd.env.runners.batch import BatchSimulation
from evcd.env.runners.live import TARGET_VTYPE, LiveTarget, TargetIds
from evcd.env.target import Target, TargetPlan
from evcd.utils.validation import check_int

#: Default number of targets per simulation. Measured (docs/NOTES.md, the batched engine): the travel
#: times drift from the single environment's as batches grow (25: greedy within 1.4 %; 100: 3 %;
#: 400 targets to one station jam it), while the cost per episode is nearly flat from 25 to 400
#: when a call brings hundreds of episodes (batches are consecutive slices of the departure window).
DEFAULT_BATCH_EPISODES = 25


class BatchedRunner(EnvRunner):
    """Plays episodes many at a time, co-simulated in their background day (module docstring).

    Args:
        env: the environment whose scenario, days, settings and SUMO simulation are used (its
            episode API is not); the runner closes it in :meth:`close`.
        batch_episodes: targets per simulation (>= 1).
    """

    def __init__(self, env: ChargingNavEnv, batch_episodes: int = DEFAULT_BATCH_EPISODES) -> None:
        self.batch_episodes = check_int("batch_episodes", batch_episodes, minimum=1)
        if not isinstance(env.unwrapped, ChargingNavEnv):
            raise ValueError(f"the batched engine needs a ChargingNavEnv, not {type(env.unwrapped).__name__}")
        super().__init__(env.unwrapped)
        self.reward = reward_fn(self.env.config.reward)
        self.ids = TargetIds()
        self.batches = 0  # simulations run (for the benchmark)
        self.sumo_errors = 0

    # ------------------------------------------------------------------ planning
    def plan(self, specs: Sequence[EpisodeSpec]) -> list[tuple[int, TargetPlan]]:
        """Each spec's background day (index) and target plan, as ``env.reset`` would draw them."""
        return [self._draw(spec)[1:] for spec in specs]  # type: ignore[misc]

    def _draw(self, spec: EpisodeSpec) -> tuple[np.random.Generator, int, TargetPlan]:
        rng, _ = seeding.np_random(spec.reset_seed)
        day, plan = self.env.draw_episode(rng, spec.options)
        return rng, day, plan

    def batches_of(self, specs: Sequence[EpisodeSpec]) -> list[list[int]]:
        """The positions in ``specs`` of each batch: by day, then departure, ``batch_episodes`` each."""
        return self._batches(self.plan(specs))

    def _batches(self, plans: Sequence[tuple[int, TargetPlan]]) -> list[list[int]]:
        order = sorted(range(len(plans)), key=lambda i: (plans[i][0], plans[i][1].departure, i))
        out: list[list[int]] = []
        for _, group in itertools.groupby(order, key=lambda i: plans[i][0]):
            members = list(group)
            out += [members[k : k + self.batch_episodes] for k in range(0, len(members), self.batch_episodes)]
        return out

    # ------------------------------------------------------------------ running
    def run(
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: EpisodeCallback | None = None,
    ) -> list[EpisodeRow]:
        """Play ``specs`` (see :meth:`EpisodeRunner.run`); ``on_episode`` gets each row as its
        episode ends (in the order they end); the rows come back in the order of the specs."""
        rows: list[EpisodeRow | None] = [None] * len(specs)
        clock = [time.perf_counter()]

        def finished(live: LiveTarget, row: EpisodeRow) -> None:
            now = time.perf_counter()
            row = dataclasses.replace(row, wall_s=now - clock[0])
            clock[0] = now
            rows[live.order] = row
            if on_episode is not None:
                on_episode(row)

        draws = [self._draw(spec) for spec in specs]  # each plan once; its rng redraws origins
        for members in self._batches([(day, plan) for _, day, plan in draws]):
            batch = []
            for i in members:
                rng, day, plan = draws[i]
                target = Target(plan, self.ids.route(), self.ids.vehicle(), TARGET_VTYPE, battery=False)
                batch.append(LiveTarget(i, specs[i], rng, day, target))
            simulation = BatchSimulation(self.env, batch, agent, explore=explore, learn=learn,
                                         reward=self.reward, ids=self.ids, finished=finished)  # fmt: skip
            simulation.run()
            self.batches += 1
            self.sumo_errors += simulation.sumo_errors
        assert all(r is not None for r in rows)
        return rows  # type: ignore[return-value]
