"""A plan improved by moving one guided EV at a time: the start the solver searches from.

    plan = improve_plan(problem, own)     # every single-EV move that lowers the summed travel time, taken

With FIFO at every station a plan is a station per guided EV: the schedule follows
(:func:`~evcd.planner.schedule.fifo_starts`), and so does its value in the model. A local search
over those assignments is cheap (one station's FIFO recomputed per move tried) and, on heavy fleet
episodes, finds in a fraction of a second plans that CP-SAT's own search, started from every EV on
its own station, takes minutes to reach: on Jurong West's fleet table world at share 1 (56 guided
EVs) 208 s per EV against CP-SAT's 281 s after 10 deterministic seconds. Handed to the solver as its
hint it is where the search starts, so the solver's plan is never worse than it.

The moves: each guided EV with more than one station, in the order of its earliest arrival, to each
of its other stations, the first that lowers the plan's value taken; passes repeat until none does
(a local optimum: no single move improves). Deterministic: the same problem and start give the
same plan.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from evcd.planner.model import Job, PlanProblem
from evcd.planner.schedule import fifo_starts

#: A move is taken when it lowers the summed travel time by more than this (s): no cycling on ties.
MIN_GAIN_S = 1e-6


def improve_plan(problem: PlanProblem, plan: Mapping[str, int], max_passes: int = 100) -> dict[str, int]:
    """``plan`` (a station per guided job with a choice) after single-job moves until none lowers the
    guided jobs' summed travel time in the model, or ``max_passes`` passes (module docstring).

    Jobs of ``plan`` at a station they have no option for raise ``ValueError``; a guided job with a
    choice missing from ``plan`` is placed first at its station of earliest arrival.
    """
    movable = sorted((j for j in problem.guided if len(j.options) > 1),
                     key=lambda j: (min(o.arrival for o in j.options), j.name))  # fmt: skip
    current = {**{j.name: min(j.options, key=lambda o: o.arrival).station for j in movable}, **plan}
    costs = {s: _station_cost(problem, s, current) for s in range(len(problem.stations))}
    for _ in range(max_passes):
        moved = False
        for job in movable:
            here = current[job.name]
            for option in job.options:
                there = option.station
                if there == here:
                    continue
                trial = {**current, job.name: there}
                new_here = _station_cost(problem, here, trial)
                new_there = _station_cost(problem, there, trial)
                if new_here + new_there < costs[here] + costs[there] - MIN_GAIN_S:
                    current, costs[here], costs[there], moved = trial, new_here, new_there, True
                    here = there
        if not moved:
            break
    return current


def _station_cost(problem: PlanProblem, station: int, plan: Mapping[str, int]) -> float:
    """The summed travel time of the guided jobs ``plan`` puts at ``station`` (``inf`` where one starts
    after its deadline), from that station's FIFO alone."""
    jobs = tuple(j for j in problem.jobs if _station_of(j, plan) == station)
    local = PlanProblem(stations=problem.stations, jobs=jobs, start=problem.start)
    starts = fifo_starts(local, {j.name: station for j in jobs if len(j.options) > 1})
    total = 0.0
    for job in jobs:
        if job.depart is None:
            continue
        start = starts[job.name]
        if job.deadline is not None and start > math.floor(job.deadline + 1e-9):
            return math.inf
        total += start - float(job.depart)
    return total


def _station_of(job: Job, plan: Mapping[str, int]) -> int | None:
    return job.options[0].station if len(job.options) == 1 else plan.get(job.name)
