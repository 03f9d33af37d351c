"""Rules for the fleet (:mod:`evcd.env.fleet`): dispatchers that know of the centre's own
recommendations.

Both read the fleet's observation ``[D, N, Z, H]``, where ``H[i]`` counts the *other* guided EVs sent
to station ``i`` and still driving, and estimate the time to the start of charging as
:class:`~evcd.agents.heuristics.QueueAwareAgent` does, with those EVs counted in the backlog:

- :class:`ReservationAgent` decides every guided EV on its own: the EVs already sent to a station
  count as if they were there (``Z + H``). EVs deciding at the same tick do not see each other's
  new choices, so several of them can still pick the same short queue together.
- :class:`CentralAgent` assigns the EVs deciding at one tick jointly, one after the other, each
  seeing where the ones before it were sent.

Where the observation holds the fleet's ``G`` (``observe=[..., guided_ahead]``: per station, the
other guided EVs driving there that are due before this one), both count ``G`` instead of ``H``: an EV
due after this one does not delay it. The central rule then counts an EV it assigns at the tick for
the EVs after it only where it is due first (its drive time to the station, ``T`` where observed,
else the queue-aware guess from ``D`` and ``N``, below theirs).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evcd.agents.base import EpisodeState
from evcd.agents.heuristics import Observed, QueueAwareAgent


@dataclass
class FleetRuleEpisode(EpisodeState):
    """A guided EV as a fleet rule knows it: the station it sent it to at its last decision (``None``
    before the first)."""

    station: int | None = None


def counted_at(d: np.ndarray, episodes: Sequence[FleetRuleEpisode]) -> np.ndarray:
    """Per EV (rows of ``d``), the station it is counted at as far as the dispatcher knows (-1:
    unknown): where it waits (``D == 0``: in that station's ``Z``; ``D`` in any unit), else the
    ``station`` its episode state says it was last sent to (``None``: unknown)."""
    waiting = d == 0.0
    last = np.array([-1 if e.station is None else e.station for e in episodes], dtype=np.int64)
    return np.where(waiting.any(axis=1), np.argmax(waiting, axis=1), last)


class ReservationAgent(QueueAwareAgent):
    """The queue-aware estimate with the guided EVs already sent to a station counted in its backlog.

    For station ``i``: ``max(t, b)`` as in :class:`~evcd.agents.heuristics.QueueAwareAgent`, where the
    backlog ``b`` counts ``Z + H`` vehicles (those at the station plus the other guided EVs heading
    there) instead of ``Z``. Ties go to the lowest index. It needs the fleet's 4-block observation;
    the constructor takes the arguments of :class:`~evcd.agents.heuristics.QueueAwareAgent`.
    """

    name = "reservation"
    obs_blocks = (4,)

    def new_episode(self, rng: np.random.Generator) -> FleetRuleEpisode:
        """A guided EV this agent has not decided yet."""
        return FleetRuleEpisode(rng)

    def decide(
        self, obs: np.ndarray, episodes: Sequence[FleetRuleEpisode], explore: bool = False
    ) -> np.ndarray:
        """Per EV the station with the smallest :meth:`estimate` (ties: the lowest index); each EV's
        state records where it is sent."""
        batch = np.atleast_2d(np.asarray(obs))
        stations = self.estimate(batch).argmin(axis=-1).astype(np.int64)
        for episode, s in zip(episodes, stations, strict=True):
            episode.station = int(s)
        return stations if np.ndim(obs) > 1 else stations[0]

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        """Estimated seconds to the start of charging at each station (of each row of a batch), the
        backlog counting ``Z + H`` (``Z + G`` where the observation holds ``G``).

        Raises:
            ValueError: ``obs`` is not ``(4m,)`` or ``(k, 4m)`` (the message names the shape).
        """
        p = self.physical(obs)
        d, n, z, _ = self.read(p)
        return self.score(d, n, z + self.guided(p), **self.known(p))

    def guided(self, obs: Observed) -> np.ndarray:
        """The other guided EVs this rule counts ahead at each station (``obs`` or its
        :meth:`physical` blocks): ``G`` where the observation holds it, else ``H`` (whole vehicles)."""
        p = self.physical(obs)
        return np.rint(p["G"] if "G" in p else p["H"])

    def drive(self, obs: Observed) -> np.ndarray:
        """The drive time to each station (s; ``obs`` or its :meth:`physical` blocks): ``T`` where
        observed, else the queue-aware guess from ``D`` and ``N``."""
        p = self.physical(obs)
        return p["T"] if "T" in p else self.guess_drive(p["D"], p["N"])


class CentralAgent(ReservationAgent):
    """Assigns the guided EVs deciding at one tick jointly, so that they do not all take the same
    short queue.

    The ``k`` rows of one :meth:`decide` call are the EVs of one fleet deciding at one tick. Each EV
    starts from what it observes: the vehicles ahead of it at station ``i`` are ``Z[i] + H[i]``, as
    for :class:`ReservationAgent`. The EVs are then assigned one at a time:

    - **Order**: by their smallest estimate over the stations (the soonest expected start of
      charging first; ties to the lower row). The EV that will reach a charging point first is the
      one the others will queue behind, so the later ones count it, not the reverse.
    - **Updates**: when an EV is sent to station ``s``, every EV assigned after it at this tick counts
      one more vehicle at ``s``; if the EV was already counted elsewhere (sent there at an earlier
      tick, or waiting in that car park), that station counts one fewer. An EV staying where it was
      changes nothing: it is already in the others' ``Z`` or ``H``.

    Where an EV was counted comes from its episode state (the station this agent sent it to at its
    previous decision, :class:`FleetRuleEpisode`) and, for an EV waiting in a car park, from its
    observation (``D == 0`` there, and it is in that station's ``Z``).

    With ``G`` in the observation (module docstring) an EV counts ``Z + G`` ahead, and one assigned
    at the tick counts for a later one only where its drive time there is below the later one's; one
    leaving the station it was driving to stops counting there likewise (one leaving a car park, for
    all).

    Approximation: at an EV's *first* decision the agent does not know where it was heading (its
    trip's own station, in the others' ``H``), so that station keeps counting it for the EVs assigned
    after it at that tick, one vehicle too many there. The same holds if another dispatcher moved the
    EV since this agent last decided it. Everything else is exact with respect to the observation.

    Deterministic; the constructor arguments are :class:`ReservationAgent`'s.
    """

    name = "central"

    def decide(
        self, obs: np.ndarray, episodes: Sequence[FleetRuleEpisode], explore: bool = False
    ) -> np.ndarray:
        """The stations of the ``k`` EVs deciding at this tick, assigned jointly (see the class).

        Args:
            obs: their observations ``[D, N, Z, H]``, shape ``(k, 4m)``.
            episodes: their states (from :meth:`new_episode`, one per guided EV, kept across ticks);
                each records the station it is sent to.
            explore: ignored (a rule).

        Returns:
            ``k`` station indices (int64).

        Raises:
            ValueError: ``obs`` is not ``(k, 4m)`` with one row per episode.
        """
        batch = np.asarray(obs)
        blocks = self.physical(batch)
        d, n, z, h = self.read(blocks)
        assert h is not None  # obs_blocks = (4,)
        if batch.ndim != 2 or len(batch) != len(episodes):
            raise ValueError(
                f"observations of shape {batch.shape} for {len(episodes)} episodes: one row each"
            )
        k, m = d.shape
        ahead = z + self.guided(blocks)  # (k, m): what each EV counts before this tick's assignments
        counted = counted_at(d, episodes)
        known = self.known(blocks)  # the points in service and route times, where observed
        order = np.argsort(self.score(d, n, ahead, **known).min(axis=1), kind="stable")
        # the assignments so far: (station, when the EV is due there, +1 added / -1 removed); with H
        # every one counts for everybody after it (due at -inf), with G only for those due later
        due = self.drive(blocks) if "G" in (self.layout or "") else np.full((k, m), -np.inf)
        moves: list[tuple[int, float, float]] = []
        stations = np.empty(k, dtype=np.int64)
        for j in order:
            row = {key: value[j] for key, value in known.items()}
            moved = np.zeros(m)
            for st, when, sign in moves:
                if when < due[j, st] or when == -np.inf:
                    moved[st] += sign
            s = int(np.argmin(self.score(d[j], n[j], ahead[j] + moved, **row)))
            stations[j] = s
            c = int(counted[j])
            if c != s:
                moves.append((s, float(due[j, s]), 1.0))
                if c >= 0:
                    moves.append((c, -np.inf if d[j, c] == 0.0 else float(due[j, c]), -1.0))
        for episode, s in zip(episodes, stations, strict=True):
            episode.station = int(s)
        return stations
