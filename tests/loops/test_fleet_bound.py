"""The fleet's clairvoyant bound on the small grid in SUMO: an episode read into the planner's model,
the hand case's optimum found and played (the best of every assignment played in SUMO), and the bad
inputs (an infeasible model, nobody to guide, no solver, a plan for another fleet)."""

from __future__ import annotations

import itertools
import logging
import math
import sys
from dataclasses import asdict

import numpy as np
import pytest
from omegaconf import OmegaConf

from evcd.agents import make_agent, make_agent_for_env
from evcd.agents.planned import PlannedAgent
from evcd.env.fleet.plan_inputs import read_episode
from evcd.env.runners.fleet import FleetRunner
from evcd.loops.fleet import fleet_spec
from evcd.loops.fleet_bound import FleetBound, fleet_learns, make_fleet_dispatcher
from evcd.planner import MissingSolverError, PlanSettings, solve
from evcd.planner.schedule import greedy_plan, plan_value, up
from tests.conftest import compose_config
from tests.env.handmade import ev

# Both stations get one point (cs1: index 0 on B1C1; cs2: index 1 on C2B2, ~390 m further for all
# three). Every EV's own best is cs1, 2-3 blocks ahead (greedy: nearest by road); a and b charge ~300 s,
# c ~150 s. At their first tick (10 s, c at 20 s) the route observer's drive times say cs1 at ~26 s (a),
# ~33 s (c), ~43 s (b) and cs2 ~27 s later for each. So:
#   everybody at cs1 (a, c, b in that order): c waits for a, b for both        -> ~830 s in all
#   in turn, each where it starts soonest (a cs1; c cs2; b cs2 after c):       -> ~300 s
#   the optimum: a, the first and nearest, to cs2; c charges first at cs1 and b after it: b waits ~140 s
#   for c's short charge, where it would wait ~300 s for a's                     -> ~250 s in the model
HAND = [
    ev("a", 5, "A1B1 B1C1 C1D1", "pa_cs1", target=0.5),
    ev("b", 8, "A0A1 A1B1 B1C1 C1D1", "pa_cs1", target=0.5),
    ev("c", 12, "B0B1 B1C1 C1D1", "pa_cs1", target=0.3),
]
OPTIMUM = {"a": 1, "b": 0, "c": 0}


def hand_fleet(make_small_fleet, **overrides):
    return make_small_fleet(HAND, charging_points=1, **overrides)


def test_the_hand_case_optimum_is_found_and_played_best_of_every_assignment(make_small_fleet):
    env = hand_fleet(make_small_fleet)
    inputs = read_episode(env, 0)
    problem = inputs.problem
    assert set(inputs.requests) == {"a", "b", "c"} and len(problem.jobs) == 3  # no background session
    assert all(r.distance[0] < r.distance[1] for r in inputs.requests.values())  # cs1 nearest for all
    result = solve(problem)
    assert result.status == "optimal" and dict(result.stations) == OPTIMUM
    # the optimum by hand from the model's inputs: a alone at cs2, c first at cs1, b after c
    opt = {job.name: {o.station: o for o in job.options} for job in problem.jobs}
    c_start = up(opt["c"][0].arrival)
    assert up(opt["c"][0].arrival) < up(opt["b"][0].arrival) < c_start + up(opt["c"][0].duration)  # b waits
    starts = {"a": up(opt["a"][1].arrival), "c": c_start, "b": c_start + up(opt["c"][0].duration)}
    assert dict(result.starts) == starts
    assert result.objective == result.bound == sum(starts.values()) - (5 + 8 + 12)
    every = [dict(zip("abc", c, strict=True)) for c in itertools.product(range(2), repeat=3)]
    assert min(plan_value(problem, plan) for plan in every) == result.objective
    in_turn = plan_value(problem, greedy_plan(problem))
    assert plan_value(problem, {"a": 0, "b": 0, "c": 0}) > in_turn > result.objective

    runner = FleetRunner(env)
    bound = FleetBound()
    spec = fleet_spec(0, 0, 1)
    (played,) = bound.play(runner, [spec])
    row = bound.report()["fleet_bound"]["episodes"][0]
    assert row["status"] == "optimal" and row["planned"] == row["guided"] == 3 and row["truncated"] == 0
    assert row["played"] == played.travel_time and row["bound"] == pytest.approx(result.mean_bound)
    assert row["floor"] < row["bound"]  # the solver proved what the EVs' competition costs
    # the model leaves out slowing into the car park: it is a few seconds per EV early, never late
    assert 0.0 <= row["played_minus_model"] < 10.0 and row["ahead"] == 0
    # every assignment played in SUMO: the plan is the best of them
    rng = np.random.default_rng(0)
    by_plan = {
        tuple(plan.values()): runner.episode(spec, PlannedAgent(2, rng, plan=plan, fleet=env)).travel_time
        for plan in every
    }
    assert min(by_plan.values()) == played.travel_time == by_plan[tuple(OPTIMUM.values())]
    assert sorted(by_plan.values())[1] > played.travel_time + 5.0  # not by a hair
    rules = {rule: runner.episode(spec, make_agent_for_env(rule, env, np.random.default_rng(0))).travel_time
             for rule in ("greedy", "queue_aware", "reservation", "central")}  # fmt: skip
    assert rules["greedy"] == by_plan[(0, 0, 0)] > played.travel_time + 5.0  # everybody to cs1
    assert min(rules.values()) >= played.travel_time  # no rule beats the plan (central reaches it here)


def test_the_same_episode_reads_into_the_same_problem(make_small_fleet):
    env = hand_fleet(make_small_fleet)
    first, second = read_episode(env, 0), read_episode(env, 0)
    assert first.problem == second.problem and first.plain_travel == second.plain_travel


def test_an_infeasible_model_is_played_on_the_evs_own_stations_and_reported(make_small_fleet, caplog):
    # b cannot start charging within 60 s of its departure whatever the plan: the fleet truncates it
    env = hand_fleet(make_small_fleet, max_travel_time=60.0)
    bound = FleetBound(PlanSettings(time_limit_s=5.0))
    with caplog.at_level(logging.WARNING, logger="evcd.loops.fleet_bound"):
        (played,) = bound.play(FleetRunner(env), [fleet_spec(0, 0, 1)])
    row = bound.report()["fleet_bound"]["episodes"][0]
    assert row["status"] == "infeasible" and math.isnan(row["bound"]) and math.isnan(row["model"])
    assert "infeasible" in caplog.text and "played with every EV on its own station" in caplog.text
    assert row["played"] == row["plain"] == played.travel_time  # nobody was sent anywhere


def test_nobody_to_guide_is_refused_before_sumo_starts(make_small_fleet, tmp_path):
    cache = tmp_path / "cache"
    env = make_small_fleet([ev("late", 400, "A0A1 A1B1 B1C1 C1D1", "pa_cs1")], cache_dir=cache)
    with pytest.raises(ValueError, match=r"no charging EV of day 0 departs in departure_window=\[0, 300\) s"):
        FleetBound().play(FleetRunner(env), [fleet_spec(0, 0, 1)])
    assert not cache.exists() and not env.simulation.running


def test_a_missing_solver_is_said_before_any_episode(monkeypatch):
    monkeypatch.setitem(sys.modules, "ortools.sat.python", None)  # as if OR-Tools were not installed
    with pytest.raises(MissingSolverError, match=r"pip install -e \.\[bound\]"):
        FleetBound()


def test_agent_fleet_bound_is_the_planners_settings_in_hydra(make_small_fleet):
    for script in ("evaluate", "train"):
        block = OmegaConf.to_container(compose_config(script, "task=fleet", "agent=fleet_bound").agent)
        assert block.pop("name") == "fleet_bound" and block == asdict(PlanSettings())  # declared alike
    env = hand_fleet(make_small_fleet)  # no SUMO
    bound = make_fleet_dispatcher("fleet_bound", env, np.random.default_rng(0), time_limit_s=3)
    assert isinstance(bound, FleetBound) and bound.settings.time_limit_s == 3
    assert not fleet_learns("fleet_bound") and fleet_learns("dqn")
    with pytest.raises(ValueError, match=r"unknown options \['limit'\]; it takes time_limit_s, workers"):
        make_fleet_dispatcher("fleet_bound", env, np.random.default_rng(0), limit=3)
    with pytest.raises(ValueError, match="'hindsight' is not an agent of task=fleet"):
        make_fleet_dispatcher("hindsight", env, np.random.default_rng(0))


def test_a_plan_is_checked_and_played_only_on_a_fleet(make_small_fleet):
    with pytest.raises(ValueError, match=r"plan\['a'\]=2: must be an integer in \[0, 1\]"):
        make_agent("planned", 2, np.random.default_rng(0), plan={"a": 2})
    agent = make_agent("planned", 2, np.random.default_rng(0), plan={"a": 1})
    with pytest.raises(ValueError, match="plays a fleet's guided EVs by vehicle id"):
        agent.decide(np.zeros((1, 8)), [agent.new_episode(np.random.default_rng(0))])
