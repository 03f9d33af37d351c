"""Rule-based dispatchers: the paper's Random and Greedy baselines and a queue-aware heuristic; the
fixed-station policies and the best station in hindsight built from them (a bound, not a policy).

All of them read the observation ``[D, N, Z]`` of :mod:`evcd.env.observation`. Normalisation
(``normalize_obs=True``) divides ``D`` by a constant (m -> km), so Greedy's argmin is the same with or
without it; the queue-aware heuristic undoes the scaling (it is told whether it is on).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from evcd.agents.base import Agent, split_observation
from evcd.env.observation import D_SCALE_M, N_SCALE
from evcd.env.runner import EpisodeRow, EpisodeRunner, EpisodeSpec


class RandomAgent(Agent):
    """Picks a station uniformly at random at departure (the episode's first :meth:`act`) and keeps
    it for the whole episode (the paper's Random baseline)."""

    name = "random"

    def __init__(self, n_stations: int, rng: np.random.Generator) -> None:
        super().__init__(n_stations, rng)
        self.choice: int | None = None

    def begin_episode(self, rng: np.random.Generator | None = None) -> None:
        """Forget the previous episode's station: the next :meth:`act` draws a new one."""
        super().begin_episode(rng)
        self.choice = None

    def episode_state(self) -> Any:
        """The episode's generator and its station (``None`` before the first decision)."""
        return (self.rng, self.choice)

    def set_episode_state(self, state: Any) -> None:
        """Restore :meth:`episode_state`."""
        self.rng, self.choice = state

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station drawn at departure."""
        split_observation(obs, self.n_stations)  # a wrong-sized observation is a wiring bug: fail
        if self.choice is None:
            self.choice = int(self.rng.integers(self.n_stations))
        return self.choice


class GreedyAgent(Agent):
    """At every slot, the station with the smallest driving distance ``D`` (the paper's Greedy).

    Ties go to the lowest index.
    """

    name = "greedy"

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """``argmin D``."""
        distance, _, _ = split_observation(obs, self.n_stations)
        return int(np.argmin(distance))


class QueueAwareAgent(Agent):
    """At every slot, the station with the smallest estimated time to the start of charging.

    For station ``i`` with ``k`` charging points:

    - drive time ``t = D / speed_mps + N * vehicle_delay_s`` (free-flow time plus a delay per
      vehicle on the route, a crude congestion term);
    - the target starts charging once ``max(0, Z - k + 1)`` of the vehicles there have left; with
      ``k`` points serving one car every ``charge_s`` each, that backlog lasts
      ``b = max(0, Z - k + 1) * charge_s / k``; the queue drains while the target drives, so the
      expected wait is ``max(0, b - t)``.

    Score ``t + max(0, b - t) = max(t, b)``; ties go to the lowest index. A station whose car park
    the target is in (``D == 0``) counts the target in its ``Z``, so it is discounted there.

    Args:
        n_stations: number of stations.
        rng: unused (deterministic), kept for the common interface.
        points: charging points per station (one number for all, or one per station).
        normalized: whether observations are normalised (``normalize_obs=True`` in the env).
        speed_mps: assumed mean driving speed (m/s).
        vehicle_delay_s: assumed delay per vehicle on the route (s).
        charge_s: assumed mean charging time of a vehicle at a point (s). The default is that of
            :class:`~evcd.scenario.demand.DemandConfig`'s defaults: 60 kWh x (0.825 - 0.2) / 100 kW.
    """

    name = "queue_aware"

    def __init__(
        self,
        n_stations: int,
        rng: np.random.Generator,
        points: int | Sequence[int] = 2,
        normalized: bool = False,
        speed_mps: float = 10.0,
        vehicle_delay_s: float = 2.0,
        charge_s: float = 1350.0,
    ) -> None:
        super().__init__(n_stations, rng)
        pts = np.asarray(points)
        if pts.ndim == 0:
            pts = np.full(self.n_stations, pts)
        if pts.shape != (self.n_stations,) or not np.issubdtype(pts.dtype, np.integer) or (pts < 1).any():
            raise ValueError(f"points={points!r}: must be an integer >= 1 or {self.n_stations} of them")
        for key, value in (("speed_mps", speed_mps), ("charge_s", charge_s)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{key}={value!r}: must be a finite number > 0")
        if not (np.isfinite(vehicle_delay_s) and vehicle_delay_s >= 0):
            raise ValueError(f"vehicle_delay_s={vehicle_delay_s!r}: must be a finite number >= 0")
        self.points = pts.astype(np.float64)
        self.normalized = bool(normalized)
        self.speed_mps = float(speed_mps)
        self.vehicle_delay_s = float(vehicle_delay_s)
        self.charge_s = float(charge_s)

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The env's charging points per station and whether it normalises observations."""
        base = env.unwrapped
        return {"points": [st.points for st in base.stations], "normalized": base.config.normalize_obs}

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        """Estimated seconds to the start of charging at each station."""
        d, n, z = (part.astype(np.float64) for part in split_observation(obs, self.n_stations))
        if self.normalized:
            d, n, z = d * D_SCALE_M, n * N_SCALE, z * self.points
        z = np.rint(z) - (d == 0.0)  # the target itself is counted in Z where it waits
        drive = d / self.speed_mps + n * self.vehicle_delay_s
        backlog = np.maximum(0.0, z - self.points + 1.0) * self.charge_s / self.points
        return np.maximum(drive, backlog)

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station with the smallest :meth:`estimate`."""
        return int(np.argmin(self.estimate(obs)))


class FixedStationAgent(Agent):
    """Always the same station (the building block of the best station in hindsight).

    Args:
        n_stations: number of stations.
        rng: unused (the interface's).
        station: the station index.
    """

    name = "fixed"

    def __init__(self, n_stations: int, rng: np.random.Generator, station: int = 0) -> None:
        super().__init__(n_stations, rng)
        is_int = isinstance(station, int | np.integer) and not isinstance(station, bool)
        if not is_int or not 0 <= station < n_stations:
            raise ValueError(f"station={station!r}: must be a station index in [0, {n_stations})")
        self.station = int(station)

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The fixed station."""
        split_observation(obs, self.n_stations)
        return self.station


def best_in_hindsight(by_station: Sequence[Sequence[EpisodeRow]]) -> list[EpisodeRow]:
    """Per episode, the row of the station with the shortest travel time among the runs that ended
    charging (ties: the lowest station index); an episode no station charged in keeps station 0's
    (truncated) row. ``by_station[s][i]`` is episode ``i`` driven to station ``s`` all the way; each
    kept row's ``wall_s`` becomes the sum over the stations (what the bound cost).

    Raises:
        ValueError: no stations, or the stations' rows are not the same episodes in the same order.
    """
    if not by_station:
        raise ValueError("best_in_hindsight: no station runs given")
    seeds = [r.seed for r in by_station[0]]
    for s, rows in enumerate(by_station):
        if [r.seed for r in rows] != seeds:
            raise ValueError(f"best_in_hindsight: station {s}'s runs are not the same episodes as "
                             "station 0's")  # fmt: skip
    best = []
    for runs in zip(*by_station, strict=True):
        charged = [r for r in runs if not r.truncated]
        row = min(charged, key=lambda r: r.travel_time) if charged else runs[0]
        best.append(dataclasses.replace(row, wall_s=float(sum(r.wall_s for r in runs))))
    return best


class HindsightAgent(Agent):
    """The best station in hindsight: each episode is driven to every station with no further
    decision (:class:`FixedStationAgent` on the same episode seed), and the shortest travel time
    is kept (:func:`best_in_hindsight`). It knows the future, so it is a bound on what a dispatcher
    that picks stations can expect, not a policy: it has no :meth:`act`, only :meth:`play`. Its
    rows name the best station (``station``, ``station_id``); :meth:`report` adds every station's
    travel time per episode.

    Args:
        n_stations: number of stations.
        rng: unused (the fixed-station runs are deterministic given the episode seeds).
    """

    name = "hindsight"

    def __init__(self, n_stations: int, rng: np.random.Generator) -> None:
        super().__init__(n_stations, rng)
        self.by_station: list[list[EpisodeRow]] = []

    @property
    def runs_per_episode(self) -> int:
        """One run per station."""
        return self.n_stations

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """Refused: the bound is measured by :meth:`play`, not by acting on observations."""
        raise RuntimeError("hindsight is a bound, not a policy: play it through a runner (agent.play, "
                           "evcd.evaluate.evaluate), which drives every episode to each station")  # fmt: skip

    def play(
        self,
        runner: EpisodeRunner,
        specs: Sequence[EpisodeSpec],
        explore: bool = False,
        learn: bool = False,
        on_episode: Callable[[EpisodeRow], None] | None = None,
    ) -> list[EpisodeRow]:
        """Run ``specs`` once per station with :class:`FixedStationAgent`, keep the best per episode.

        Raises:
            ValueError: ``learn`` is set (the bound does not learn).
        """
        if learn:
            raise ValueError("hindsight does not learn: play it with learn=False")
        self.by_station = [
            runner.run(specs, FixedStationAgent(self.n_stations, self.rng, s), explore=False, learn=False,
                       on_episode=on_episode)
            for s in range(self.n_stations)
        ]  # fmt: skip
        return best_in_hindsight(self.by_station)

    def report(self) -> dict[str, Any]:
        """Per episode (in spec order) the best station and every station's travel time
        (``None`` where that run was truncated), and per station its mean over charged runs."""
        if not self.by_station:
            return {}
        best = best_in_hindsight(self.by_station)
        runs_of = zip(*self.by_station, strict=True)
        times = [[None if r.truncated else r.travel_time for r in runs] for runs in runs_of]
        means = []
        for rows in self.by_station:
            charged = [r.travel_time for r in rows if not r.truncated]
            means.append(float(np.mean(charged)) if charged else None)
        return {
            "hindsight": {
                "best_station": [None if r.truncated else r.station for r in best],
                "travel_time_by_station": times,
                "mean_by_station": means,
                "truncated_by_station": [sum(r.truncated for r in rows) for rows in self.by_station],
            }
        }
