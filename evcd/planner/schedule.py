"""What a station's FIFO makes of a given assignment, computed directly (no solver).

    starts = fifo_starts(problem, {"ev3": 0, "ev9": 1})        # the jobs placed, with every fixed one
    stations = greedy_plan(problem)                             # one guided job after the other

At each station the sessions start in the order they arrived (equal arrivals in the problem's job
order, as in the model), each as soon as a point is free for its whole duration (the points less the
blocked ones): the schedule SUMO's controller plays for these arrivals and durations
(:mod:`evcd.sim.charging`, which also lets an outage interrupt a charge). With every point in service
it is the earliest schedule the model of :mod:`evcd.planner.solver` allows for this assignment (each
session starts no later than in any other), so its value is that plan's objective in the model.

Four uses: the greedy plan a search starts from, each job's start were it the only guided job with a
choice at a station (:func:`lower_starts`: a lower bound the model adds, since another session can only
delay it), the floor those starts give the whole plan (:func:`floor_value`), and a naive reference for
the tests.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable, Mapping

from evcd.planner.model import Job, Option, PlanProblem, PlanStation


def fifo_starts(problem: PlanProblem, stations: Mapping[str, int], blocked: bool = True) -> dict[str, float]:
    """The start of every job placed: the guided jobs at ``stations[name]``, the jobs with one option
    at theirs (a guided job missing from ``stations`` is left out, as if it did not charge).

    Args:
        problem: the stations and jobs.
        stations: a station index per guided job placed.
        blocked: honour the blocked points (false: every point in service all the time).

    Arrivals and durations are rounded up to whole seconds, as in the model; sessions arriving at
    the same time keep the order of the problem's jobs.

    Raises:
        ValueError: a job placed at a station it has no option for.
    """
    per_station: list[list[tuple[Job, Option]]] = [[] for _ in problem.stations]
    for job in problem.jobs:
        option = _option(job, stations.get(job.name)) if len(job.options) != 1 else job.options[0]
        if option is not None:
            per_station[option.station].append((job, option))
    out: dict[str, float] = {}
    for st, placed in zip(problem.stations, per_station, strict=True):
        out.update(_station_starts(st, placed, problem.start, blocked))
    return out


def plan_value(problem: PlanProblem, stations: Mapping[str, int]) -> float:
    """The guided jobs' summed travel time (``start - depart``) under :func:`fifo_starts`; ``inf``
    where a guided job is not placed or starts after its deadline."""
    starts = fifo_starts(problem, stations)
    total = 0.0
    for job in problem.guided:
        start = starts.get(job.name)
        if start is None or (job.deadline is not None and start > math.floor(job.deadline + 1e-9)):
            return math.inf
        total += start - float(job.depart)  # type: ignore[arg-type]
    return total


def greedy_plan(problem: PlanProblem) -> dict[str, int]:
    """Each guided job in turn (by its earliest arrival) to the station where it starts soonest given
    the ones placed before it: a plan to start a search from (ties: the lower index)."""
    chosen: dict[str, int] = {}
    order = sorted((j for j in problem.guided if len(j.options) > 1), key=lambda j: min(_arrivals(j)))
    for job in order:
        best: tuple[float, int] | None = None
        for o in job.options:
            start = fifo_starts(problem, {**chosen, job.name: o.station})[job.name]
            if best is None or start < best[0]:
                best = (start, o.station)
        assert best is not None
        chosen[job.name] = best[1]
    return chosen


def lower_starts(problem: PlanProblem) -> dict[tuple[str, int], float]:
    """Per job and station it may charge at, its start were it the only guided job with a choice
    there (every job with one station placed, FIFO, all points in service). In any schedule the model
    with FIFO allows, a job placed there starts no earlier: another session can only delay it, and an
    outage only take points away."""
    fixed = {j.name: j.options[0].station for j in problem.jobs if len(j.options) == 1}
    out = {(n, fixed[n]): t for n, t in fifo_starts(problem, fixed, blocked=False).items()}
    for job in problem.jobs:
        if len(job.options) < 2:
            continue
        for o in job.options:
            starts = fifo_starts(problem, {**fixed, job.name: o.station}, blocked=False)
            out[(job.name, o.station)] = starts[job.name]
    return out


def floor_value(problem: PlanProblem) -> float:
    """The guided jobs' summed travel time were none of them delayed by another job with a choice: each
    at the station where it would start soonest among the jobs without one (:func:`lower_starts`). No
    plan of the model with FIFO does better; a solver's proven bound no higher than this proved nothing
    about the guided EVs' competition for the points."""
    lower = lower_starts(problem)
    return sum(min(lower[job.name, o.station] for o in job.options) - float(job.depart)  # type: ignore[arg-type]
               for job in problem.guided)  # fmt: skip


def _option(job: Job, station: int | None) -> Option | None:
    if station is None:
        return None
    for o in job.options:
        if o.station == station:
            return o
    raise ValueError(f"job {job.name!r} has no option at station {station}")


def _arrivals(job: Job) -> Iterable[float]:
    return (o.arrival for o in job.options)


def up(seconds: float) -> int:
    """Whole seconds, rounded up (an arrival or a duration: SUMO acts at whole steps)."""
    return math.ceil(seconds - 1e-9)


def _station_starts(
    st: PlanStation, placed: list[tuple[Job, Option]], start: float, blocked: bool
) -> dict[str, float]:
    """One station's FIFO schedule (module docstring); ``placed`` in the problem's job order."""
    origin = math.floor(start)
    out: dict[str, float] = {}
    ends: list[float] = []  # end times of the sessions holding a point (a heap)
    running: list[tuple[float, float]] = []  # (start, end) of every session placed, for the blocked test
    held = sorted((j for j, _ in placed if j.started is not None), key=lambda j: j.started)  # type: ignore[arg-type,return-value]
    for job in held:
        s = up(float(job.started) - origin) + origin  # type: ignore[arg-type]
        e = s + up(job.options[0].duration)
        out[job.name] = s
        heapq.heappush(ends, e)
        running.append((s, e))
    last = -math.inf
    queue = sorted(((j, o) for j, o in placed if j.started is None), key=lambda x: x[1].arrival)
    for job, o in queue:
        arrival, duration = up(o.arrival - origin) + origin, up(o.duration)
        t = max(arrival, last, origin)
        while len(ends) >= st.points:
            t = max(t, heapq.heappop(ends))  # wait for a point
        if blocked and st.blocked:
            t = _fits(st, running, t, duration)
        out[job.name] = t
        last = t
        heapq.heappush(ends, t + duration)
        running.append((t, t + duration))
    return out


def _fits(st: PlanStation, running: list[tuple[float, float]], t: float, duration: float) -> float:
    """The earliest time from ``t`` at which one more session of ``duration`` fits the station's points
    less the blocked ones, beside the sessions ``running`` (the candidate times: ``t`` and every end)."""
    candidates = sorted({t, *(e for _, e in running if e > t), *(up(b.end) for b in st.blocked if b.end > t)})
    for c in candidates:
        events = sorted({c, *(s for s, _ in running if c < s < c + duration),
                         *(b.start for b in st.blocked if c < b.start < c + duration)})  # fmt: skip
        if all(_load(st, running, x) < st.points for x in events):
            return c
    return candidates[-1]


def _load(st: PlanStation, running: list[tuple[float, float]], x: float) -> int:
    """Points busy or blocked at time ``x``."""
    busy = sum(1 for s, e in running if s <= x < e)
    return busy + sum(b.points for b in st.blocked if b.start <= x < b.end)
