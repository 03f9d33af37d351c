"""The rules of an episode, written once: :class:`~evcd.env.ChargingNavEnv` and the batched engine
(:mod:`evcd.env.runners`) both call them, so that the two cannot drift apart.

- **Moving.** The target counts as moving once its odometer advanced :data:`MOVED_M` since the last
  mark; a target parked at a station (waiting in the queue) is never stuck (:class:`Motion`).
- **A slot** lasts ``decision_interval`` s, or ends at the time cap (:func:`slot_deadline`).
- **End of a slot.** First *stuck* (no movement for ``stuck_limit`` s), then the time cap
  (``max_travel_time`` s after departure): :func:`slot_end_reason`.
- **Insertion.** A target SUMO has not inserted within ``max_insert_delay`` gets another origin,
  departing at once, at most :data:`MAX_INSERT_TRIES` origins in all (:func:`another_origin`).
- **The end.** The last step's ``info`` carries the same keys whichever runner played the episode
  (:func:`final_info`): ``reason``, ``charged``, ``travel_time``, ``queue_wait``, ``arrival``,
  ``departure``, ``origin``, ``day``, ``switches``, ``station`` and ``station_id``, and ``error``
  after a SUMO error.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from evcd.env.target import OriginSampler, TargetPlan
from evcd.scenario.stations_file import Station
from evcd.sim.charge_record import ChargeRecord

#: The target counts as moving once its odometer advanced this much (m) since the last mark.
MOVED_M = 1.0
#: Origins tried before the target is given up as impossible to insert.
MAX_INSERT_TRIES = 5
#: Tolerance of time comparisons (s): simulation times are sums of steps.
TIME_EPS = 1e-9
#: Why an episode ends: the target started charging, or one of the truncations.
REASONS = ("charging", "teleported", "vanished", "stuck", "max_travel_time", "sumo_error", "not_inserted")
#: The ends where the target can no longer be observed: its last slot has no true next observation,
#: so the runners hand learners no transition for it (the episode ends with ``agent.end_episode``
#: alone). Bootstrapping from the observation before the slot would mislabel the state, and cutting
#: the bootstrap would make an abort look like the end of all cost (a teleport would pay).
UNOBSERVED = ("teleported", "vanished", "sumo_error", "not_inserted")


@dataclass
class Motion:
    """When the target last moved: the odometer at the last mark and the time of the mark."""

    odometer: float
    since: float

    def update(self, now: float, odometer: float | None, parked: bool) -> None:
        """Mark ``now`` if the target moved at least :data:`MOVED_M` or is parked at a station.

        Args:
            now: the end of the slot (s of day).
            odometer: the target's odometer (m), or ``None`` where its vehicle is not in the simulation
                (the batched engine's targets wait beside the queue).
            parked: the target waits at a station (in its car park): waiting is not being stuck.
        """
        if parked:
            self.since = now
            if odometer is not None:
                self.odometer = odometer
        elif odometer is not None and odometer - self.odometer >= MOVED_M:
            self.odometer, self.since = odometer, now


def slot_deadline(now: float, departure: float, decision_interval: float, max_travel_time: float) -> float:
    """When a slot that starts at ``now`` ends: one decision interval later, or at the time cap."""
    return min(now + decision_interval, departure + max_travel_time)


def slot_end_reason(
    motion: Motion, now: float, departure: float, stuck_limit: float, max_travel_time: float
) -> str | None:
    """Why the episode ends at the end of a slot (after :meth:`Motion.update`), or ``None``:
    ``"stuck"`` before ``"max_travel_time"``."""
    if now - motion.since >= stuck_limit:
        return "stuck"
    if now - departure >= max_travel_time - TIME_EPS:
        return "max_travel_time"
    return None


def another_origin(
    plan: TargetPlan, origins: OriginSampler, rng: np.random.Generator, now: float
) -> TargetPlan:
    """The plan of a target that could not be inserted: another origin drawn from the episode's
    generator, departing ``now`` (its battery and the episode's departure clock are kept)."""
    origin, pos = origins.draw(rng)
    return replace(plan, departure=now, origin=origin, depart_pos=pos)


def final_info(
    *,
    reason: str,
    now: float,
    departure: float,
    origin: str,
    travel: float | None,
    visits: Sequence[tuple[float, float]],
    day: int,
    switches: int,
    station: int | None,
    stations: Sequence[Station],
    error: str = "",
) -> dict[str, Any]:
    """The ``info`` of the step that ends an episode.

    Args:
        reason: one of :data:`REASONS`.
        now: the end of the last step (s of day).
        departure: the target's scheduled departure (s of day): ``travel_time`` counts from it.
        origin: the edge it departed from.
        travel: ``T_travel`` (s) if the target started charging, else ``None``.
        visits: ``(arrival, end of the wait)`` of every station visit (s of day).
        day: the background day's demand seed.
        switches: how often the choice of station changed.
        station: the station chosen last (index), ``None`` before any decision.
        stations: the scenario's stations.
        error: the SUMO error that ended the episode, if any.
    """
    info: dict[str, Any] = {
        "reason": reason,
        "charged": travel is not None,
        "travel_time": travel if travel is not None else now - departure,
        "queue_wait": float(sum(end - arrival for arrival, end in visits)),
        "arrival": visits[-1][0] if visits else None,
        "departure": departure,
        "origin": origin,
        "day": day,
        "switches": switches,
        "station": station,
    }
    if station is not None:
        info["station_id"] = stations[station].id
    if error:
        info["error"] = error
    return info


def visits_of(records: Sequence[ChargeRecord], vehicle: str, now: float) -> list[tuple[float, float]]:
    """``(arrival, end of the wait)`` of each station visit of ``vehicle`` among the controller's
    ``records``: the wait ends at the charge start, when it left the queue, or ``now`` (still waiting)."""
    return [(r.arrival_time, _wait_end(r, now)) for r in records if r.vehicle == vehicle]


def _wait_end(record: ChargeRecord, now: float) -> float:
    if record.start_time is not None:
        return record.start_time
    return record.release_time if record.release_time is not None else now


def check_action(action: Any, n_stations: int, name: str = "action") -> int:
    """``action`` as a station index (a Python or NumPy integer, or a 0-d array, in ``[0, m)``).

    Raises:
        ValueError: ``"<name>=<action>: must be a station index in [0, m)"``.
    """
    value = action.item() if isinstance(action, np.ndarray) and action.ndim == 0 else action
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= value < n_stations:
        raise ValueError(f"{name}={action!r}: must be a station index in [0, {n_stations})")
    return int(value)
