"""The best station in hindsight: a bound built from fixed-station runs of the same episodes (real SUMO)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from evcd.agents import Agent, agent_names
from evcd.agents.heuristics import FixedStationAgent
from evcd.env import ChargingNavEnv
from evcd.env.runners import EpisodeRow, make_runner
from evcd.loops.evaluate import evaluate
from evcd.loops.hindsight import HindsightBound, best_in_hindsight, dispatcher_names, make_dispatcher
from evcd.loops.run_files import results_dict
from tests.conftest import make_grid_scenario, run_script

#: A small day with queues (most EVs charge), so that the best station is not always the nearest.
SMALL = {
    "evs": 120,
    "demand": {"cars_per_day": 1500, "min_trip_m": 500.0, "charging_share": 0.9},
    "departure_window": (21600.0, 23400.0),
}


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("hindsight")
    env = ChargingNavEnv(scenario=make_grid_scenario(root / "grid"), cache_dir=root / "cache", **SMALL)
    yield env
    env.close()


def row(seed: int, station: int, travel: float, truncated: bool = False, wall: float = 1.0) -> EpisodeRow:
    return EpisodeRow(episode=0, seed=seed, departure=0.0, origin="e", day=0, choices=str(station),
                      station=station, station_id=f"cs{station}", travel_time=travel, queue_wait=0.0,
                      reason="max_travel_time" if truncated else "charging", truncated=truncated,
                      episode_return=0.0, wall_s=wall)  # fmt: skip


# ---------------------------------------------------------------------------------------- the rule
def test_best_is_the_shortest_charged_run_and_costs_every_run():
    by_station = [
        [row(1, 0, 300.0), row(2, 0, 90.0, truncated=True), row(3, 0, 50.0, truncated=True)],
        [row(1, 1, 200.0), row(2, 1, 400.0), row(3, 1, 70.0, truncated=True)],
        [row(1, 2, 200.0), row(2, 2, 500.0), row(3, 2, 60.0, truncated=True)],
    ]
    best = best_in_hindsight(by_station)
    assert [(r.station, r.travel_time, r.truncated) for r in best] == [
        (1, 200.0, False),  # a tie goes to the lower station
        (1, 400.0, False),  # a truncated run never wins, however short
        (0, 50.0, True),  # no station charged: station 0's truncated row
    ]
    assert [r.wall_s for r in best] == [3.0, 3.0, 3.0]


def test_runs_of_different_episodes_are_refused():
    with pytest.raises(ValueError, match="station 1"):
        best_in_hindsight([[row(1, 0, 1.0)], [row(2, 1, 1.0)]])
    with pytest.raises(ValueError, match="no station"):
        best_in_hindsight([])


def test_hindsight_is_a_bound_played_by_the_loops_not_an_agent(env):
    bound = make_dispatcher("hindsight", env, np.random.default_rng(0))
    assert isinstance(bound, HindsightBound) and not isinstance(bound, Agent)
    assert bound.runs_per_episode == 3 and not bound.learns and bound.report() == {}
    assert "hindsight" in dispatcher_names() and "hindsight" not in agent_names()  # not an agent
    with pytest.raises(ValueError, match="takes none"):
        make_dispatcher("hindsight", env, np.random.default_rng(0), speed=1)
    with pytest.raises(ValueError, match=r"'hindsite'.*hindsight"):
        make_dispatcher("hindsite", env, np.random.default_rng(0))


# ---------------------------------------------------------------------------------------- real SUMO
@pytest.mark.slow
@pytest.mark.parametrize("engine", ["single", "batched"])
def test_hindsight_is_never_worse_than_any_fixed_station(env, engine):
    n, episodes, seed = env.action_space.n, 8, 21
    runner = make_runner(env, engine, 4)
    try:
        fixed = [evaluate(runner, FixedStationAgent(n, np.random.default_rng(0), s), episodes, seed,
                          progress=False).rows for s in range(n)]  # fmt: skip
        result = evaluate(runner, HindsightBound(n), episodes, seed, progress=False)
    finally:
        runner.close()
    assert [r.seed for r in result.rows] == [r.seed for r in fixed[0]]
    for i, best in enumerate(result.rows):
        runs = [rows[i] for rows in fixed]
        charged = [r.travel_time for r in runs if not r.truncated]
        assert charged, f"episode {i}: no station charged"
        assert not best.truncated and best.travel_time == min(charged)
        assert all(best.travel_time <= t for t in charged)
        assert best.station == min(range(n), key=lambda s: (runs[s].truncated, runs[s].travel_time))
        # the fixed runs inside the bound are the fixed-station policies' own runs
        assert best == dataclasses.replace(runs[best.station], wall_s=best.wall_s)
    assert len({r.station for r in result.rows}) > 1, "the best station never varies: a weak test case"
    report = result.extra["hindsight"]
    assert report["best_station"] == [r.station for r in result.rows]
    assert report["travel_time_by_station"][0] == [rows[0].travel_time for rows in fixed]
    assert report["mean_by_station"][1] == pytest.approx(np.mean([r.travel_time for r in fixed[1]]))
    out = results_dict(result)
    assert out["hindsight"] == report and out["summary"]["mean_travel_time"] <= min(report["mean_by_station"])


@pytest.mark.slow
def test_hindsight_through_the_training_script(script_overrides, tmp_path):
    out = tmp_path / "run"
    proc = run_script("train.py", *script_overrides, "eval.episodes=3", "eval.bootstrap_resamples=200",
                      "agent=hindsight", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert data["agent"] == "hindsight" and data["training"]["episodes"] == 0
    assert data["hindsight"]["best_station"] == [e["station"] for e in data["episodes"]]
    assert len(data["hindsight"]["travel_time_by_station"]) == 3
    # paired with greedy on the same episodes: never slower where both charged
    assert data["baselines"]["greedy"]["paired"]["agent_slower"] == 0
