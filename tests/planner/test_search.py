"""The plan the solver starts from (evcd.planner.search): single-EV moves down to a local optimum,
checked against every single move played through the FIFO by hand."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.planner.schedule import greedy_plan, plan_value
from evcd.planner.search import improve_plan
from evcd.planner.solver import search_start, solve
from tests.planner.test_planner import HAND, random_problem


def single_moves(problem, plan):
    """Every plan one guided EV away from ``plan``."""
    for job in problem.guided:
        for option in job.options:
            if option.station != plan[job.name]:
                yield {**plan, job.name: option.station}


@pytest.mark.parametrize("blocked", [False, True])
def test_single_moves_end_where_no_single_move_helps_and_never_worse_than_the_start(blocked):
    improved = 0
    for seed in range(25):
        problem = random_problem(np.random.default_rng(seed), blocked)
        own = {job.name: 0 for job in problem.guided}  # everybody at the first station
        for start in (own, greedy_plan(problem)):
            plan = improve_plan(problem, start)
            value = plan_value(problem, plan)
            assert value <= plan_value(problem, start), seed
            assert all(plan_value(problem, p) >= value - 1e-6 for p in single_moves(problem, plan)), seed
            assert improve_plan(problem, start) == plan  # same problem and start, same plan
            improved += value < plan_value(problem, start)
    assert improved > 0  # the moves do something on these problems


def test_a_local_optimum_is_not_the_optimum_and_the_solver_goes_past_it():
    # the hand case's greedy plan (a to s0, c and b to s1: 300 s) is a local optimum: the optimum (275 s)
    # moves two EVs from it. From everybody at s0 (840 s), single moves find the optimum; the search
    # starts from the better of the two, and the solver from the greedy plan alone still proves it.
    assert improve_plan(HAND, greedy_plan(HAND)) == greedy_plan(HAND)
    own = {"a": 0, "b": 0, "c": 0}
    assert improve_plan(HAND, own) == {"a": 1, "b": 0, "c": 0}
    assert plan_value(HAND, search_start(HAND, own)) == 275.0
    assert plan_value(HAND, search_start(HAND)) == 300.0
    assert solve(HAND).objective == solve(HAND).bound == 275.0
