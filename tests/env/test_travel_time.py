"""T_travel, the reward and the end of an episode on hand-built days (4 x 4 grid, 1-point cs2)."""

from __future__ import annotations

import libsumo
import pytest

from evcd.env import TARGET_ID
from evcd.sim.driver import SumoDriver
from tests.conftest import run_episode
from tests.env.handmade import TO_CS2, car, ev

CS1, CS2 = 0, 1
NEAR_CS2 = {"departure": 100, "origin": "D2C2", "depart_pos": 20.0}


def blocked_cs2(hold: bool = False) -> list[str]:
    """cs2's only point is taken from t~20 s: for ~5 min (target SoC 0.5), or for good (``hold``)."""
    return [ev("blocker", 0, TO_CS2, "pa_cs2", soc=0.1, target=0.5, hold=hold)]


def test_busy_station_wait_is_part_of_travel_time(make_small_env):
    env = make_small_env(blocked_cs2())
    out = run_episode(env, 0, policy=lambda obs: CS2, options=NEAR_CS2)
    info = out["info"]
    assert out["terminated"] and info["reason"] == "charging" and info["charged"]
    assert info["station_id"] == "cs2" and info["departure"] == 100
    records = {r.vehicle: r for r in env.simulation.controller.records}
    target, blocker = records[TARGET_ID], records["blocker"]
    drive = target.arrival_time - info["departure"]
    assert info["queue_wait"] > 60 and info["queue_wait"] == target.start_time - target.arrival_time
    assert info["travel_time"] == drive + info["queue_wait"]
    # the point passes from the blocker to the target in the same step (FIFO hand-over)
    assert info["departure"] + info["travel_time"] == target.start_time == blocker.release_time
    assert out["rewards"][-1] == pytest.approx(7200.0 / info["travel_time"])
    assert all(r == 0.0 for r in out["rewards"][:-1])


def test_free_station_no_wait(make_small_env):
    env = make_small_env(blocked_cs2())
    out = run_episode(env, 0, policy=lambda obs: CS1, options=NEAR_CS2)
    info = out["info"]
    assert info["reason"] == "charging" and info["station_id"] == "cs1"
    assert info["queue_wait"] == 0.0 and info["travel_time"] == info["arrival"] - info["departure"]


def test_leaving_a_queue_for_another_station(make_small_env):
    env = make_small_env(blocked_cs2(hold=True))
    obs, info = env.reset(seed=0, options=NEAR_CS2)
    ctrl = env.simulation.controller
    for _ in range(5):
        obs, _, terminated, truncated, info = env.step(CS2)
        assert not (terminated or truncated)
    assert ctrl.status(TARGET_ID) == "waiting" and obs[5] == 2  # cs2: blocker + target
    _, _, terminated, truncated, info = env.step(CS1)
    assert ctrl.status(TARGET_ID) != "waiting" and ctrl.occupancy("cs2") == 1
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(CS1)
    assert terminated and info["station_id"] == "cs1" and info["switches"] == 1
    first, second = [r for r in ctrl.records if r.vehicle == TARGET_ID]
    assert first.station == "cs2" and first.start_time is None and second.station == "cs1"
    assert info["queue_wait"] == first.release_time - first.arrival_time > 0  # the wait at cs2 counts
    assert info["travel_time"] == second.start_time - info["departure"]


def test_time_cap_truncates(make_small_env):
    env = make_small_env(blocked_cs2(hold=True), max_travel_time=150)
    out = run_episode(env, 0, policy=lambda obs: CS2, options=NEAR_CS2)
    info = out["info"]
    assert not out["terminated"] and info["reason"] == "max_travel_time" and not info["charged"]
    assert info["travel_time"] == 150 and info["queue_wait"] > 0 and out["rewards"][-1] == 0.0


STOPPED_ON_B1C1 = car("wall", 0, "A1B1 B1C1 C1D1", stop='<stop lane="B1C1_0" endPos="40" duration="100000"/>')


@pytest.mark.parametrize(("teleport", "reason"), [(-1, "stuck"), (45, "teleported")])
def test_blocked_target_is_truncated_not_crashed(make_small_env, teleport, reason):
    env = make_small_env([STOPPED_ON_B1C1], time_to_teleport=teleport, stuck_limit=120)
    env.reset(seed=0, options={"departure": 100, "origin": "A1B1", "depart_pos": 20.0})
    truncated = False
    for _ in range(20):
        _, _, terminated, truncated, info = env.step(CS1)  # behind the stopped car on a 1-lane road
        if terminated or truncated:
            break
    assert truncated and info["reason"] == reason
    assert set(info) >= {"travel_time", "station", "queue_wait", "reason", "departure"}


def test_vanished_target_and_sumo_error_then_reset_works(make_small_env, monkeypatch):
    env = make_small_env(blocked_cs2(), decision_interval=10)
    env.reset(seed=0, options={"departure": 100, "origin": "A3B3"})
    _, _, terminated, _, _ = env.step(CS1)
    assert not terminated
    env.simulation.api.vehicle.remove(TARGET_ID)
    _, reward, terminated, truncated, info = env.step(CS1)
    assert truncated and not terminated and info["reason"] == "vanished" and reward == 0.0
    assert info["travel_time"] > 0 and info["station"] == CS1
    with pytest.raises(RuntimeError, match="reset"):
        env.step(CS1)

    env.reset(seed=1)
    driver = env.simulation.driver

    def broken_step(until=None):
        raise libsumo.TraCIException("simulated SUMO failure")

    monkeypatch.setattr(driver, "step", broken_step)
    _, _, terminated, truncated, info = env.step(CS1)
    assert truncated and info["reason"] == "sumo_error" and "simulated SUMO failure" in info["error"]
    monkeypatch.undo()
    out = run_episode(env, 2)
    assert out["info"]["reason"] == "charging"
    env.close()
    assert SumoDriver.active() is None


def test_target_that_cannot_be_inserted_departs_elsewhere(make_small_env):
    wall = car("wall", 0, "A1B1 B1C1", stop='<stop lane="A1B1_0" endPos="30" duration="100000"/>')
    env = make_small_env([wall], max_insert_delay=30, time_to_teleport=-1)
    _, info = env.reset(seed=0, options={"departure": 100, "origin": "A1B1", "depart_pos": 28.0})
    assert info["origin"] != "A1B1" and info["departure"] >= 130
    assert env.simulation.api.vehicle.getRoadID(TARGET_ID) == info["origin"]
