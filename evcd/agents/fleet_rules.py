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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evcd.agents.base import EpisodeState
from evcd.agents.heuristics import QueueAwareAgent


class ReservationAgent(QueueAwareAgent):
    """The queue-aware estimate with the guided EVs already sent to a station counted in its backlog.

    For station ``i``: ``max(t, b)`` as in :class:`~evcd.agents.heuristics.QueueAwareAgent`, where the
    backlog ``b`` counts ``Z + H`` vehicles (those at the station plus the other guided EVs heading
    there) instead of ``Z``. Ties go to the lowest index. It needs the fleet's 4-block observation;
    the constructor arguments are :class:`~evcd.agents.heuristics.QueueAwareAgent`'s.
    """

    name = "reservation"
    obs_blocks = (4,)

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        """Estimated seconds to the start of charging at each station (of each row of a batch), the
        backlog counting ``Z + H``.

        Raises:
            ValueError: ``obs`` is not ``(4m,)`` or ``(k, 4m)`` (the message names the shape).
        """
        d, n, z, h = self.read(obs)
        assert h is not None  # obs_blocks = (4,)
        return self.score(d, n, z + h)


@dataclass
class CentralEpisode(EpisodeState):
    """A guided EV as :class:`CentralAgent` knows it: the station it sent it to at its last decision
    (``None`` before the first)."""

    station: int | None = None


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
    previous decision, :class:`CentralEpisode`) and, for an EV waiting in a car park, from its
    observation (``D == 0`` there, and it is in that station's ``Z``).

    Approximation: at an EV's *first* decision the agent does not know where it was heading (its
    trip's own station, in the others' ``H``), so that station keeps counting it for the EVs assigned
    after it at that tick, one vehicle too many there. The same holds if another dispatcher moved the
    EV since this agent last decided it. Everything else is exact with respect to the observation.

    Deterministic; the constructor arguments are :class:`~evcd.agents.heuristics.QueueAwareAgent`'s.
    """

    name = "central"

    def new_episode(self, rng: np.random.Generator) -> CentralEpisode:
        """A guided EV this agent has not decided yet."""
        return CentralEpisode(rng)

    def decide(
        self, obs: np.ndarray, episodes: Sequence[CentralEpisode], explore: bool = False
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
        d, n, z, h = self.read(batch)
        assert h is not None  # obs_blocks = (4,)
        if batch.ndim != 2 or len(batch) != len(episodes):
            raise ValueError(
                f"observations of shape {batch.shape} for {len(episodes)} episodes: one row each"
            )
        k, m = d.shape
        ahead = z + h  # (k, m): what each EV counts at each station before this tick's assignments
        counted = self._counted_at(d, episodes)
        order = np.argsort(self.score(d, n, ahead).min(axis=1), kind="stable")
        moved = np.zeros(m)  # vehicles added (+1) and removed (-1) per station by the assignments so far
        stations = np.empty(k, dtype=np.int64)
        for j in order:
            s = int(np.argmin(self.score(d[j], n[j], ahead[j] + moved)))
            stations[j] = s
            if counted[j] != s:
                moved[s] += 1.0
                if counted[j] >= 0:
                    moved[counted[j]] -= 1.0
        for episode, s in zip(episodes, stations, strict=True):
            episode.station = int(s)
        return stations

    @staticmethod
    def _counted_at(d: np.ndarray, episodes: Sequence[CentralEpisode]) -> np.ndarray:
        """Per EV, the station at which the others count it now (-1: unknown): where it waits
        (``D == 0``: in that station's ``Z``), else where this agent last sent it (in ``H``)."""
        waiting = d == 0.0
        last = np.array([-1 if e.station is None else e.station for e in episodes], dtype=np.int64)
        return np.where(waiting.any(axis=1), np.argmax(waiting, axis=1), last)
