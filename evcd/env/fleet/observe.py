"""What every guided EV observes at a fleet tick: the single environment's blocks from the route
observer (:mod:`evcd.env.observation`), with the fleet's ``H`` after ``[D, N, Z]`` and its ``G`` last
(:mod:`evcd.env.fleet`'s docstring says what they count).

    views = TickObserver(observer, stations, layout, normalize).observe(api, controller, guided, agents)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from evcd.env.fleet.events import guided_ahead, heading
from evcd.env.fleet.guided import GuidedEV
from evcd.env.observation import Observation, RouteObserver, check_layout, unit_divisors
from evcd.scenario.stations_file import Station
from evcd.sim.charging import ChargingController


class TickObserver:
    """The fleet's observations at one tick.

    Args:
        observer: the world's route observer (``[D, N, Z]`` and the options' blocks it makes).
        stations: the stations, in action order.
        layout: the fleet's layout (``"DNZH"`` and its options' letters).
        normalize: whether the vectors are normalised (``H`` and ``G`` in multiples of the points).
    """

    def __init__(
        self, observer: RouteObserver, stations: Sequence[Station], layout: str, normalize: bool
    ) -> None:
        self.observer = observer
        self.stations = tuple(stations)
        self.layout = check_layout(layout)
        self.normalize = normalize
        self._index = {st.id: i for i, st in enumerate(self.stations)}
        m = len(self.stations)
        self._units = unit_divisors([st.points for st in self.stations], "DNZH")[3 * m :]

    def observe(
        self, api: Any, controller: ChargingController, guided: Mapping[str, GuidedEV], agents: Sequence[str]
    ) -> dict[str, Observation]:
        """The observations of ``agents`` (guided EVs on their way, at their last ``road`` and ``pos``)."""
        m = len(self.stations)
        counts, driving = heading(guided, controller, m)
        seen: dict[str, Observation] = {}
        for agent in agents:
            ev = guided[agent]
            record = controller.current(agent)
            at = None if record is None else self._index[record.station]
            seen[agent] = self.observer.observe(api, controller, ev.road, ev.pos, at)
        ahead = (
            guided_ahead(guided, driving, {a: o.extra["T"] for a, o in seen.items()}, m)
            if "G" in self.layout
            else {}
        )
        out: dict[str, Observation] = {}
        for agent, obs in seen.items():
            h = counts.copy()
            if driving.get(agent):
                h[guided[agent].station] -= 1  # the others heading there
            base = 3 * m  # [D, N, Z], H, the observer's options' blocks, then G
            parts = [obs.vector[:base], self._per_points(h), obs.vector[base:]]
            extra = dict(obs.extra)
            if agent in ahead:
                extra["G"] = ahead[agent]
                parts.append(self._per_points(ahead[agent]))
            vector = np.concatenate(parts)
            out[agent] = Observation(obs.distance, obs.vehicles, obs.occupancy, obs.routes, vector, extra)
        return out

    def _per_points(self, counts: np.ndarray) -> np.ndarray:
        """A block of guided-EV counts (``H``, ``G``) in the observation's units (float32)."""
        return (counts / self._units if self.normalize else counts).astype(np.float32)
