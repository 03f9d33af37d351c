"""The clairvoyant planner (evcd.planner) without SUMO: a hand-computed optimum, the solver against a
naive enumeration of every assignment played through the FIFO by hand, the FIFO relaxation, and the
bad inputs (missing solver, time limit, infeasible model, nobody to plan, malformed problems)."""

from __future__ import annotations

import itertools
import math
import sys

import numpy as np
import pytest

from evcd.planner import (
    Blocked,
    Job,
    MissingSolverError,
    Option,
    PlanProblem,
    PlanSettings,
    PlanStation,
    solve,
)
from evcd.planner.schedule import fifo_starts, floor_value, greedy_plan, lower_starts, plan_value

TWO = (PlanStation("s0", 1), PlanStation("s1", 1))


def ev(name: str, s0: tuple[float, float], s1: tuple[float, float], depart: float = 0.0, **kw) -> Job:
    """A guided EV with an (arrival, duration) at each of the two stations."""
    return Job(name, (Option(0, *s0), Option(1, *s1)), depart=depart, **kw)


# Two stations of one point each; three EVs departing at 0 that all reach s0 first (each one's own
# best, what greedy does: nearest by road). a and b charge 300 s, c 150 s.
#   everybody at s0 (FIFO a 30, c 35, b 45):        a 30, c 330, b 480          -> 840
#   one after the other, each where it starts soonest (a: s0; c: s0 330 or s1 60 -> s1;
#   b: s0 330 or s1 after c, 210 -> s1):           a 30, c 60, b 210           -> 300
#   the optimum, a (first and nearest!) to s1:      a 55, c 35, b 35 + 150 = 185 -> 275
HAND = PlanProblem(
    TWO,
    (ev("a", (30, 300), (55, 300)), ev("b", (45, 300), (70, 300)), ev("c", (35, 150), (60, 150))),
    start=0.0,
)


def test_the_hand_case_optimum_differs_from_each_evs_own_best_and_from_deciding_in_turn():
    result = solve(HAND)
    assert result.status == "optimal"
    assert dict(result.stations) == {"a": 1, "b": 0, "c": 0}
    assert dict(result.starts) == {"a": 55.0, "b": 185.0, "c": 35.0}
    assert result.objective == result.bound == 275.0
    assert result.mean_bound == pytest.approx(275.0 / 3) and result.gap == 0.0
    assert plan_value(HAND, {"a": 0, "b": 0, "c": 0}) == 840.0  # each EV's own best
    assert greedy_plan(HAND) == {"a": 0, "c": 1, "b": 1}  # in turn, each where it starts soonest
    assert plan_value(HAND, greedy_plan(HAND)) == 300.0
    assert floor_value(HAND) == 30 + 45 + 35  # each at s0 as if alone: the competition costs 165 s
    assert "optimal: 3 guided EVs, mean travel 91.7 s, proven bound 91.7 s" in result.message


def test_travel_counts_from_departure_and_the_started_and_background_sessions_take_points():
    problem = PlanProblem(
        TWO,
        (
            Job("held", (Option(0, 0, 100),), started=-20.0),  # holds s0's point until 80
            Job("bg", (Option(1, 10, 500),)),  # background at s1 from 10 to 510 (not counted)
            ev("x", (20, 50), (30, 50), depart=5.0),  # s0 at 80 (75 s) or s1 at 510 (505 s)
        ),
        start=0.0,
    )
    result = solve(problem)
    assert (result.status, result.stations["x"], result.starts["x"]) == ("optimal", 0, 80.0)
    assert result.objective == 75.0
    assert result.guided == 1 and result.starts["bg"] == 10.0


def test_fifo_keeps_the_order_of_arrivals_and_dropping_it_relaxes_the_model():
    # one point: the long background session arrived first; without FIFO the EV would jump the queue
    problem = PlanProblem(
        (PlanStation("s0", 1),),
        (Job("bg", (Option(0, 10, 1000),)), Job("x", (Option(0, 20, 10),), depart=0.0)),
        start=0.0,
    )
    kept, relaxed = solve(problem), solve(problem, PlanSettings(fifo=False))
    assert (kept.objective, kept.bound) == (1010.0, 1010.0)
    assert (relaxed.objective, relaxed.bound) == (20.0, 20.0)  # a lower bound of the FIFO model


def random_problem(rng: np.random.Generator, blocked: bool) -> PlanProblem:
    """Two stations of 1-2 points (maybe an outage), 4 guided EVs, 3 background sessions, arrivals
    and durations off whole seconds."""

    def outage() -> tuple[Blocked, ...]:
        out = Blocked(1, float(rng.uniform(0, 200)), float(rng.uniform(250, 500)))
        return (out,) if blocked and rng.random() < 0.5 else ()

    def option(station: int, arrival: float) -> Option:
        return Option(station, arrival, float(rng.uniform(10, 300)))

    stations = tuple(PlanStation(f"s{i}", int(rng.integers(1, 3)), outage()) for i in range(2))
    guided = [
        Job(
            f"g{k}",
            tuple(option(i, float(rng.uniform(0, 300))) for i in range(2)),
            depart=-float(rng.uniform(0, 50)),
        )
        for k in range(4)
    ]
    background = [
        Job(f"b{k}", (option(int(rng.integers(2)), float(rng.integers(0, 300))),)) for k in range(3)
    ]
    return PlanProblem(stations, (*guided, *background), start=0.0)


@pytest.mark.parametrize("blocked", [False, True])
def test_the_solver_finds_the_best_of_every_assignment_played_through_the_fifo_by_hand(blocked):
    for seed in range(25):
        problem = random_problem(np.random.default_rng(seed), blocked)
        names = [job.name for job in problem.guided]
        plans = [dict(zip(names, c, strict=True)) for c in itertools.product(range(2), repeat=len(names))]
        best = min(plan_value(problem, plan) for plan in plans)
        result = solve(problem)
        assert result.status == "optimal", seed
        assert result.objective == pytest.approx(best) == pytest.approx(result.bound), seed
        assert plan_value(problem, {n: result.stations[n] for n in names}) == pytest.approx(best)
        relaxed = solve(problem, PlanSettings(fifo=False))
        assert relaxed.bound <= result.bound + 1e-6, seed
        assert floor_value(problem) <= best + 1e-6, seed  # nobody waiting for another: no plan does better


def test_lower_starts_bound_every_plans_starts():
    for seed in range(10):
        problem = random_problem(np.random.default_rng(100 + seed), blocked=True)
        lower = lower_starts(problem)
        names = [job.name for job in problem.guided]
        for c in itertools.product(range(2), repeat=len(names)):
            plan = dict(zip(names, c, strict=True))
            for name, start in fifo_starts(problem, plan).items():
                station = plan.get(name, next(j for j in problem.jobs if j.name == name).options[0].station)
                assert start >= lower[(name, station)] - 1e-9, (seed, plan, name)


def test_an_outage_begun_while_a_session_holds_the_point_delays_the_next_one_without_infeasibility():
    problem = PlanProblem(
        (PlanStation("s0", 1, (Blocked(1, 50, 200),)),),
        (Job("held", (Option(0, 0, 100),), started=0.0), Job("x", (Option(0, 10, 30),), depart=0.0)),
        start=0.0,
    )
    result = solve(problem)
    assert (result.status, result.starts["x"]) == ("optimal", 200.0)
    assert fifo_starts(problem, {})["x"] == 200.0


def test_same_problem_same_result():
    problem = random_problem(np.random.default_rng(7), blocked=True)
    first, second = solve(problem).to_dict(), solve(problem).to_dict()
    for d in (first, second):
        d.pop("solve_s"), d.pop("message")  # the wall time
    assert first == second


@pytest.mark.slow
def test_a_search_stopped_by_its_limit_stops_at_the_same_point_every_time():
    """The limit is CP-SAT's deterministic time: a search cut short gives the same plan and bound on
    every run, whatever the machine's load (a wall-clock limit would not)."""
    rng = np.random.default_rng(3)
    stations = tuple(PlanStation(f"s{i}", 1) for i in range(5))
    guided = [Job(f"g{k}", tuple(Option(i, float(rng.uniform(0, 900)), float(rng.uniform(600, 1800)))
                                 for i in range(5)), depart=0.0) for k in range(20)]  # fmt: skip
    problem = PlanProblem(stations, tuple(guided), start=0.0)
    runs = [solve(problem, PlanSettings(time_limit_s=0.05)).to_dict() for _ in range(2)]
    assert runs[0]["status"] == "feasible"  # cut short: not proven optimal
    for d in runs:
        d.pop("solve_s"), d.pop("message")  # the wall time
    assert runs[0] == runs[1]


# ---------------------------------------------------------------------------------------- bad input
def test_an_outage_all_window_at_the_only_station_is_an_infeasible_model_not_an_error():
    only = (PlanStation("s0", 1, (Blocked(1, 0, 10_000),)),)
    job = Job("x", (Option(0, 10, 100),), depart=0.0, deadline=7200.0)
    result = solve(PlanProblem(only, (job,), start=0.0))
    assert result.status == "infeasible" and math.isnan(result.objective) and math.isnan(result.bound)
    assert result.message == "infeasible: some guided EV cannot start charging by its deadline at any station"
    # an EV that reaches its only station after its deadline is infeasible before the solver runs
    late = Job("y", (Option(0, 9000, 100),), depart=0.0, deadline=7200.0)
    result = solve(PlanProblem((PlanStation("s0", 1),), (late,), start=0.0))
    assert result.status == "infeasible" and "'y' can reach no station before its deadline" in result.message


def test_nobody_to_plan_is_a_documented_result():
    result = solve(PlanProblem(TWO, (Job("bg", (Option(0, 10, 100),)),), start=0.0))
    assert (result.status, result.objective, result.bound, result.guided) == ("empty", 0.0, 0.0, 0)
    assert math.isnan(result.mean_bound) and result.message == "no guided EV: nothing to plan"


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"time_limit_s": 0}, r"time_limit_s=0: must be a finite number > 0"),
        ({"time_limit_s": -1.0}, r"time_limit_s=-1.0: must be a finite number > 0"),
        ({"time_limit_s": math.inf}, r"time_limit_s=inf"),
        ({"workers": 0}, r"workers=0: must be an integer >= 1"),
        ({"fifo": "yes"}, r"fifo='yes': must be true or false"),
    ],
)
def test_bad_settings_name_the_setting(settings, message):
    with pytest.raises(ValueError, match=message):
        PlanSettings(**settings)


def test_a_missing_solver_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ortools.sat.python", None)  # as if OR-Tools were not installed
    with pytest.raises(MissingSolverError, match=r"optional extra 'bound': pip install -e \.\[bound\]"):
        solve(HAND)


@pytest.mark.parametrize(
    ("stations", "jobs", "message"),
    [
        ((), (), "no station"),
        ((PlanStation("s0", 0),), (), r"station 's0': points=0: must be an integer >= 1"),
        ((PlanStation("s0", 1, (Blocked(2, 0, 10),)),), (), r"points=2: must be an integer in \[1, 1\]"),
        ((PlanStation("s0", 1, (Blocked(1, 10, 10),)),), (), r"blocked period \[10, 10\)"),
        (TWO, (Job("x", (Option(2, 0, 10),)),), r"job 'x': option station=2: must be an integer in \[0, 1\]"),
        (TWO, (Job("x", (Option(0, math.nan, 10),)),), r"job 'x': arrival=nan"),
        (TWO, (Job("x", (Option(0, 0, -1),)),), r"job 'x': duration=-1 must be a finite number >= 0"),
        (TWO, (Job("x", (Option(0, 0, 1),)), Job("x", (Option(1, 0, 1),))), r"repeated: \['x'\]"),
        (TWO, (Job("x", (Option(0, 0, 1), Option(1, 0, 1)), started=0.0),), "a started session has one"),
        (TWO, (Job("x", (Option(0, 0, 1),), started=5.0),), "started=5 after the problem's start 0"),
        (TWO, (Job("x", (Option(0, 0, 9),), started=0.0), Job("y", (Option(0, 0, 9),), started=0.0)),
         r"2 sessions hold a point of station 's0' at t=0 s; it has 1"),
    ],
)  # fmt: skip
def test_a_malformed_problem_names_the_station_or_job(stations, jobs, message):
    with pytest.raises(ValueError, match=message):
        PlanProblem(stations, jobs, start=0.0)
