"""Simulate a span of a scenario's day with its charging stations, recording traffic and queues."""

from __future__ import annotations

import logging
import time as wallclock
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from tqdm.auto import tqdm

from evcd.scenario.scenario import Scenario
from evcd.sim.charging import ChargeRecord, ChargingController
from evcd.sim.driver import SumoDriver
from evcd.sim.outages import Outage
from evcd.sim.road_events import RoadEvents
from evcd.sim.road_player import attach
from evcd.sim.traffic_stats import TrafficRecorder

log = logging.getLogger(__name__)


@dataclass
class DayResult:
    """What a simulated span produced."""

    traffic: TrafficRecorder
    charges: list[ChargeRecord]
    in_network_at_end: int  # vehicles still in the simulation at ``end`` (driving or parked)
    expected_at_end: int  # vehicles in the simulation or still waiting to be inserted at ``end``
    wall_s: float


def simulate_day(
    scenario: Scenario,
    route_file: str | Path,
    seed: int,
    begin: float = 0.0,
    end: float = 86_400.0,
    sample_every: float = 60.0,
    step_length: float = 1.0,
    time_to_teleport: float = 300.0,
    progress: bool = True,
    outages: Sequence[Outage] = (),
    roads: RoadEvents | None = None,
) -> DayResult:
    """Run ``[begin, end)`` of the day in ``route_file`` with the FIFO charging stations.

    Args:
        scenario: the scenario (network, stations, vehicle types).
        route_file: the day's demand (:func:`evcd.scenario.demand.write_demand`).
        seed: SUMO's seed.
        begin: start time (s of day); vehicles departing earlier are not simulated.
        end: end time (s of day).
        sample_every: seconds between samples of traffic and queues.
        step_length: SUMO step (s).
        time_to_teleport: SUMO's jam teleport threshold (s).
        progress: show a progress bar over simulated time.
        outages: the day's charger outages (:mod:`evcd.sim.outages`).
        roads: the day's incidents, rain and road works (:mod:`evcd.sim.road_events`), if any.
    """
    if sample_every <= 0:
        raise ValueError(f"sample_every={sample_every}: must be > 0")
    controller = ChargingController(scenario.stations, outages=outages)
    traffic = TrafficRecorder([s.id for s in scenario.stations])
    ids = traffic.station_ids
    driver = SumoDriver(
        scenario.net_file,
        scenario.additional_files,
        [route_file],
        seed=seed,
        begin=begin,
        end=end,
        step_length=step_length,
        time_to_teleport=time_to_teleport,
        warnings=False,
    )
    t0 = wallclock.perf_counter()
    with (
        driver,
        tqdm(total=end - begin, unit="sim s", disable=not progress, desc="day", mininterval=2.0) as bar,
    ):
        driver.add_listener(controller.update)
        attach(driver, roads or RoadEvents())
        driver.add_listener(traffic.on_step)
        now = driver.time
        while now < end - 1e-6:
            now = driver.step(until=min(now + sample_every, end))
            occ = {sid: controller.occupancy(sid) for sid in ids}
            traffic.sample(
                driver.api,
                now,
                parked=sum(occ.values()),
                waiting={sid: controller.waiting(sid) for sid in ids},
                charging={sid: controller.charging(sid) for sid in ids},
            )
            bar.update(now - bar.n - begin)
        in_network = driver.api.vehicle.getIDCount()
        expected = driver.api.simulation.getMinExpectedNumber()
    wall = wallclock.perf_counter() - t0
    log.info("simulated %.0f-%.0f s in %.1f s wall", begin, end, wall)
    return DayResult(traffic, controller.records, in_network, expected, wall)
