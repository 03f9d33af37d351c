"""What the fleet notes while SUMO runs between two ticks, and what the centre knows at a tick."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from evcd.env.episode_rules import TIME_EPS
from evcd.env.fleet.guided import GuidedEV, Stage
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SumoDriver

_ON_ITS_WAY = (Stage.INSERTED, Stage.ACTIVE)


def advance(
    driver: SumoDriver, controller: ChargingController, guided: Mapping[str, GuidedEV], until: float
) -> None:
    """Step SUMO to ``until``, noting the guided EVs' insertions, charge starts and teleports (the
    first event that ends an EV wins; the env ends it at the next tick)."""
    api = driver.api
    sim = api.simulation
    now = driver.time
    while now < until - TIME_EPS:
        now = driver.step()
        for vid in sim.getDepartedIDList():
            ev = guided.get(vid)
            if ev is not None and ev.stage is Stage.PENDING:
                ev.on_insert(api, now)
        for record in controller.started_this_step():
            ev = guided.get(record.vehicle)
            if ev is not None and ev.reason is None and ev.stage in _ON_ITS_WAY:
                ev.charge_start = record.start_time
                ev.reason, ev.end = "charging", record.start_time
        if sim.getStartingTeleportNumber():
            for vid in sim.getStartingTeleportIDList():
                ev = guided.get(vid)
                if ev is not None and ev.reason is None and ev.stage in _ON_ITS_WAY:
                    ev.reason, ev.end = "teleported", now


def heading(
    guided: Mapping[str, GuidedEV], controller: ChargingController, n_stations: int
) -> tuple[np.ndarray, dict[str, bool]]:
    """The guided EVs on their way (inserted, not done) still driving to each station, and for each
    of them whether it is driving (not waiting in a car park)."""
    counts = np.zeros(n_stations, dtype=np.int64)
    driving: dict[str, bool] = {}
    for ev in guided.values():
        if ev.stage in _ON_ITS_WAY and ev.reason is None:
            driving[ev.vehicle] = controller.status(ev.vehicle) is None
            if driving[ev.vehicle]:
                counts[ev.station] += 1
    return counts, driving


def guided_ahead(
    guided: Mapping[str, GuidedEV],
    driving: Mapping[str, bool],
    times: Mapping[str, np.ndarray],
    n_stations: int,
) -> dict[str, np.ndarray]:
    """Per EV of ``times``, the observation block ``G`` (:mod:`evcd.env.observation`): per station
    ``i``, the other guided EVs driving to ``i`` whose estimated time to it is shorter than this EV's.

    Args:
        guided: the episode's guided EVs by vehicle id (``station``: where each was last sent).
        driving: the guided EVs on their way and whether each is driving (:func:`heading`'s second
            result): those driving count, the ones waiting in a car park are in ``Z``.
        times: per EV observed at this tick, its route time to each station (s, ``T``; 0 where it
            waits). A driving EV's estimated time to its station is its ``T`` there; one not observed
            (none at a tick, where every EV on its way is an agent) counts as ahead of everybody.
        n_stations: the number of stations.

    An EV is never ahead of itself (its time to its own station is not shorter than itself).
    """
    due: list[list[float]] = [[] for _ in range(n_stations)]
    for vehicle, is_driving in driving.items():
        if is_driving:
            station = guided[vehicle].station
            due[station].append(float(times[vehicle][station]) if vehicle in times else -np.inf)
    sorted_due = [np.sort(np.asarray(d, dtype=np.float64)) for d in due]
    return {
        vehicle: np.array(
            [np.searchsorted(sorted_due[i], t[i], side="left") for i in range(n_stations)], dtype=np.int64
        )
        for vehicle, t in times.items()
    }
