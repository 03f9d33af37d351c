"""What a DQN agent keeps per episode (:class:`DQNEpisode`): the exploration draws, made from the
episode's own generator (so an episode does not depend on those run before it), the n-step window of
its transitions not stored yet, and on the fleet with ``in_turn`` where it was sent and what it
decided on (:mod:`evcd.agents.in_turn`)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from evcd.agents.base import EpisodeState, Transition


@dataclass
class DQNEpisode(EpisodeState):
    """An episode of a DQN agent. Under ``exploration="episode"`` it holds the episode's one
    exploration draw, made at its first decision while exploring.

    Attributes:
        drawn: whether the draw was made.
        random_station: the station the whole episode then drives to; ``None``: it follows the network.
    """

    drawn: bool = False
    random_station: int | None = None
    #: n-step returns: this episode's transitions not stored yet (the last n - 1 at most)
    pending: deque[Transition] = field(default_factory=deque)
    #: the station it was sent to at its last decision (``switch_margin_s`` keeps it; ``in_turn`` counts
    #: it), and with ``in_turn`` (the fleet) the observation it decided on and its last transition,
    #: stored once the observation of its next decision is known
    station: int | None = None
    seen: np.ndarray | None = None
    held: Transition | None = None

    def choose(self, greedy: int, epsilon: float, n_stations: int, exploration: str) -> int:
        """The action of an exploring agent given the greedy one: epsilon-greedy per slot
        (``"slot"``), or one draw at the episode's first decision (``"episode"``)."""
        rng = self.rng
        if exploration == "episode":
            if not self.drawn:  # the episode's first decision: explore it or not
                draw, station = rng.random(), int(rng.integers(n_stations))
                self.drawn = True
                self.random_station = station if draw < epsilon else None
            return greedy if self.random_station is None else self.random_station
        draw, station = rng.random(), int(rng.integers(n_stations))
        return station if draw < epsilon else greedy

    def windows(self, transition: Transition, n_step: int) -> list[tuple[Transition, ...]]:
        """Add ``transition`` to the n-step window; return the windows to store now (each stores its
        first transition with the rewards of the whole window): the full one, and once the episode
        ended every one left."""
        if n_step == 1:
            return [(transition,)]
        pending = self.pending
        pending.append(transition)
        out = []
        if len(pending) == n_step:
            out.append(tuple(pending))
            pending.popleft()
        if transition.terminated or transition.truncated:  # the episode ended: store what is left
            while pending:
                out.append(tuple(pending))
                pending.popleft()
        return out

    def flush(self) -> list[tuple[Transition, ...]]:
        """The windows still pending when the episode ended without a last transition (its target
        could no longer be observed): each is stored bootstrapping from the last true observation."""
        out = []
        while self.pending:
            out.append(tuple(self.pending))
            self.pending.popleft()
        return out
