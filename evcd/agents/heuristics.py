"""Rule-based dispatchers: the paper's Random and Greedy baselines, a queue-aware heuristic, and the
fixed-station policies (the building blocks of the best station in hindsight, :mod:`evcd.loops.hindsight`).

All of them read the observation ``[D, N, Z]`` of :mod:`evcd.env.observation`, and take the fleet's
``[D, N, Z, H]`` (:mod:`evcd.env.fleet`) too, ignoring ``H``: which layout a call holds is read off
its size (:meth:`~evcd.agents.base.Agent.blocks_of`). On a fleet they decide every guided EV on its
own, so the queue-aware rule sends EVs that see the same short queue to it together (it herds; the
rules of :mod:`evcd.agents.fleet_rules` count ``H``). Normalisation (``normalize_obs=True``) divides
``D`` by a constant (m -> km), so Greedy's argmin is the same with or without it; the queue-aware
heuristic reads the observation in physical units (it is told the environment's charging points and
whether it normalises).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from evcd.agents.base import Agent, EpisodeState, observation_units, split_observation
from evcd.env.observation import to_physical
from evcd.utils.validation import check_int, check_real

#: The backlog the queue-aware estimate gives a station with no point in service (s): it is chosen
#: only if every station is closed.
CLOSED_S = 1.0e7
#: An observation (one vector or a batch) or its blocks by letter in physical units (``physical``).
Observed = np.ndarray | Mapping[str, np.ndarray]


@dataclass
class RandomEpisode(EpisodeState):
    """An episode of :class:`RandomAgent`: the station drawn at its first decision (``None`` before)."""

    station: int | None = None


class RandomAgent(Agent):
    """Picks a station uniformly at random at departure (the episode's first decision) and keeps
    it for the whole episode (the paper's Random baseline)."""

    name = "random"
    obs_blocks = (3, 4)

    def new_episode(self, rng: np.random.Generator) -> RandomEpisode:
        """An episode whose station is not drawn yet."""
        return RandomEpisode(rng)

    def decide(self, obs: np.ndarray, episodes: Sequence[RandomEpisode], explore: bool = False) -> np.ndarray:
        """Each episode's station, drawn from its generator at its first decision."""
        self.blocks_of(obs)  # a wrong-sized observation is a wiring bug: fail
        for episode in episodes:
            if episode.station is None:
                episode.station = int(episode.rng.integers(self.n_stations))
        return np.array([e.station for e in episodes], dtype=np.int64)


class GreedyAgent(Agent):
    """At every slot, the station with the smallest driving distance ``D`` (the paper's Greedy).

    Ties go to the lowest index.
    """

    name = "greedy"
    obs_blocks = (3, 4)

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """``argmin D`` of each observation."""
        self.blocks_of(obs)
        return np.argmin(self.parts(obs)["D"], axis=-1).astype(np.int64)


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
    the target is in (``D == 0``) counts the target in its ``Z``, so it is discounted there. On the
    fleet's observation ``H`` is ignored (:class:`~evcd.agents.fleet_rules.ReservationAgent` counts it).
    Where the observation has the options' blocks (:mod:`evcd.env.observation`), it reads them as a
    navigation service would: ``k`` is the points in service (``P``; a station with none scores
    :data:`CLOSED_S`) and ``t`` the route's current travel time (``T``).

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
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {"speed_mps": 10.0, "vehicle_delay_s": 2.0, "charge_s": 1350.0}
    env_options = ("points", "normalized")

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
        self.points = pts.astype(np.float64)
        self.normalized = bool(normalized)
        self.speed_mps = check_real("speed_mps", speed_mps, low=0.0, low_open=True)
        self.vehicle_delay_s = check_real("vehicle_delay_s", vehicle_delay_s, low=0.0)
        self.charge_s = check_real("charge_s", charge_s, low=0.0, low_open=True)

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The env's charging points per station and whether it normalises observations."""
        return observation_units(env)

    def read(self, obs: Observed) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """``(D, N, Z, H)`` of ``obs`` (one observation or a batch, or its :meth:`physical` blocks) in
        metres and vehicles (float64): ``Z`` in whole vehicles without the target (where ``D == 0``, it
        waits there and counts itself), ``H`` in whole vehicles, ``None`` for a 3-block observation.

        Raises:
            ValueError: ``obs`` has none of the shapes of :attr:`obs_blocks` (the message names them).
        """
        p = self.physical(obs)
        d = p["D"]
        z = np.rint(p["Z"]) - (d == 0.0)  # the target itself is counted in Z where it waits
        return d, p["N"], z, np.rint(p["H"]) if "H" in p else None

    def physical(self, obs: Observed) -> Mapping[str, np.ndarray]:
        """Every block of ``obs`` by letter in metres, vehicles and seconds (float64); blocks already
        read (a mapping) are returned as they are, so that one estimate converts an observation once."""
        if isinstance(obs, Mapping):
            return obs
        layout = self.layout or ("DNZH" if self.blocks_of(obs) == 4 else "DNZ")
        physical = to_physical(obs, self.points, self.normalized, layout)
        return dict(zip(layout, split_observation(physical, self.n_stations, layout), strict=True))

    def score(
        self,
        d: np.ndarray,
        n: np.ndarray,
        ahead: np.ndarray,
        points: np.ndarray | None = None,
        drive: np.ndarray | None = None,
    ) -> np.ndarray:
        """Estimated seconds to the start of charging, ``max(t, b)`` (see the class), from the
        physical ``D`` and ``N`` and the vehicles ``ahead`` of the target at each station (its
        backlog counts them instead of ``Z``). ``points``: the points in service (the observation's
        ``P``; default the stations' points; a station with none is never chosen while another has
        some); ``drive``: the route's travel time (its ``T``; default ``t`` from ``D`` and ``N``)."""
        if drive is None:
            drive = self.guess_drive(d, n)
        k = self.points if points is None else np.asarray(points, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            backlog = np.where(
                k > 0, np.maximum(0.0, ahead - k + 1.0) * self.charge_s / np.maximum(k, 1.0), CLOSED_S
            )
        return np.maximum(drive, backlog)

    def guess_drive(self, d: np.ndarray, n: np.ndarray) -> np.ndarray:
        """The drive time ``t = D / speed_mps + N * vehicle_delay_s`` (s) guessed from the physical
        ``D`` and ``N`` where the observation has no route time ``T``."""
        return d / self.speed_mps + n * self.vehicle_delay_s

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        """Estimated seconds to the start of charging at each station (of each row of a batch),
        reading the points in service (``P``) and the route's travel time (``T``) where the
        observation has them."""
        p = self.physical(obs)
        d, n, z, _ = self.read(p)
        return self.score(d, n, z, **self.known(p))

    def known(self, obs: Observed) -> dict[str, np.ndarray]:
        """What the observation options tell the estimate (``obs`` or its :meth:`physical` blocks):
        ``points`` (``P``) and ``drive`` (``T``), where the observation has them."""
        p = self.physical(obs)
        out = {}
        if "P" in p:
            out["points"] = np.rint(p["P"])
        if "T" in p:
            out["drive"] = p["T"]
        return out

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The station with the smallest :meth:`estimate`, per observation."""
        return np.argmin(self.estimate(obs), axis=-1).astype(np.int64)


class ForecastQueueAgent(QueueAwareAgent):
    """:class:`QueueAwareAgent` on the forecast queue at arrival instead of the queue now: its backlog
    counts the observation's ``F`` (the vehicles forecast at each station when the target would get
    there, :mod:`evcd.env.observation`), so that learners face a rule that looks ahead too. It needs
    the environment's ``observe`` to hold ``forecast`` (and reads ``P`` and ``T`` where observed).
    A station whose car park the target is in counts the vehicles there now (the target waits in
    its queue, ahead of anybody arriving later). On the fleet with ``G`` observed (the other guided
    EVs due at each station before this one, ``observe=[..., guided_ahead]``) it counts ``F + G``: the
    forecast of the station's own queue and the centre's EVs due first.

    The constructor takes :class:`QueueAwareAgent`'s arguments.
    """

    name = "queue_forecast"

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        """Estimated seconds to the start of charging at each station, the backlog counting ``F``.

        Raises:
            ValueError: an observation without ``F`` (the message says how to add it).
        """
        p = self.physical(obs)
        if "F" not in p:
            raise ValueError(
                f"{self.name} reads the forecast block F: make the environment with observe=[..., forecast] "
                f"(env.observe); this observation's layout is {self.layout or 'DNZ'}"
            )
        d, n, z, _ = self.read(p)
        ahead = np.where(d == 0.0, z, p["F"] + (np.rint(p["G"]) if "G" in p else 0.0))
        return self.score(d, n, ahead, **self.known(p))


class FixedStationAgent(Agent):
    """Always the same station (the building block of the best station in hindsight,
    :mod:`evcd.loops.hindsight`).

    Args:
        n_stations: number of stations.
        rng: unused (the interface's).
        station: the station index.
    """

    name = "fixed"
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {"station": 0}

    def __init__(self, n_stations: int, rng: np.random.Generator, station: int = 0) -> None:
        super().__init__(n_stations, rng)
        self.station = check_int("station", station, minimum=0, maximum=self.n_stations - 1)

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The fixed station, for every episode."""
        self.blocks_of(obs)
        return np.full(len(episodes), self.station, dtype=np.int64)
