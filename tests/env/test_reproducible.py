"""Going back in time in a running SUMO: a fresh SUMO, and the same day as from a fresh start.

On a busy grid day (EVs queueing in car parks), the simulation is positioned at a departure, run on
past the next snapshots, then positioned at an earlier departure again (what the batched engine
does between two batches of a sweep, and the environment between two episodes). SUMO 1.28's
loadState leaves a car park's bookkeeping of the replaced run behind (``evcd.env.simulation``), so
the day must come back from a fresh SUMO and be the day a fresh start gives, step by step. Loads
going forward keep the running SUMO and must be exact too. Across processes the same is checked on
whole training runs in ``tests/scripts/test_reproducible_training.py``.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from evcd.env.simulation import EpisodeSimulation, needs_restart
from tests.conftest import FLEET_DEMAND

BUSY = {"demand": FLEET_DEMAND, "departure_window": (1200.0, 3000.0)}


def trajectory(sim: EpisodeSimulation, until: float, every: float = 5.0) -> list[Any]:
    """Every vehicle's lane, position, speed and stop state, and the charging queues, every
    ``every`` seconds from now to ``until``."""
    api, out = sim.api, []
    while sim.time < until:
        now = sim.driver.step(until=sim.time + every)
        vehicles = [
            (v, api.vehicle.getLaneID(v), round(api.vehicle.getLanePosition(v), 6),
             round(api.vehicle.getSpeed(v), 6), api.vehicle.getStopState(v))
            for v in sorted(api.vehicle.getIDList())
        ]  # fmt: skip
        out.append((now, vehicles, json.dumps(sim.controller.state_dict(), sort_keys=True)))
    return out


def first_difference(a: list[Any], b: list[Any]) -> Any:
    return next(((x[0], set(x[1]) ^ set(y[1])) for x, y in zip(a, b, strict=True) if x != y), None)


@pytest.fixture
def busy_sim(make_env) -> EpisodeSimulation:
    env = make_env(**BUSY)
    env.prepare()
    return env.simulation


def test_a_load_restarts_sumo_only_when_it_goes_back_in_time():
    assert needs_restart(now=2500.0, snapshot_time=1200.0)
    assert not needs_restart(now=1200.0, snapshot_time=1200.0)  # nothing simulated since the load
    assert not needs_restart(now=1400.0, snapshot_time=1500.0)  # forward


@pytest.mark.slow
def test_going_back_in_time_replays_the_day_of_a_fresh_sumo(busy_sim):
    sim = busy_sim
    sim.start_at(0, 1250.0)  # the snapshot at 1200
    sim.driver.step(until=2600.0)  # on past the snapshots at 1500 ... 2400, queues at the stations
    restarts, back = sim.restarts, sim.back_restarts
    sim.start_at(0, 1300.0)  # back to the snapshot at 1200
    assert sim.restarts == restarts + 1 and sim.back_restarts == back + 1 and sim.back_restart_s > 0
    back = trajectory(sim, until=2600.0)
    sim.close()
    sim.start_at(0, 1300.0)
    fresh = trajectory(sim, until=2600.0)
    assert first_difference(back, fresh) is None
    parked = {v for _, vehicles, _ in fresh for v, lane, *_ in vehicles if lane == ""}
    assert len(parked) >= 10  # the day is busy: EVs park and queue at the stations


@pytest.mark.slow
def test_a_load_going_forward_keeps_sumo_and_replays_the_day_of_a_fresh_sumo(busy_sim):
    sim = busy_sim
    sim.start_at(0, 1250.0)
    sim.driver.step(until=1400.0)
    restarts, back = sim.restarts, sim.back_restarts
    sim.start_at(0, 1850.0)  # forward: the snapshot at 1800
    assert sim.restarts == restarts and sim.back_restarts == back
    forward = trajectory(sim, until=2800.0)
    sim.close()
    sim.start_at(0, 1850.0)
    fresh = trajectory(sim, until=2800.0)
    assert first_difference(forward, fresh) is None
