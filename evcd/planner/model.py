"""What the clairvoyant fleet planner is told: stations with their points over time, and jobs.

    problem = PlanProblem(
        stations=(PlanStation("cs1", points=1), PlanStation("cs2", points=1, blocked=(Blocked(1, 0, 900),))),
        jobs=(Job("ev3", (Option(0, arrival=40, duration=300), Option(1, 75, 302)), depart=5, deadline=7205),
              Job("bg7", (Option(0, arrival=20, duration=280),))),
        start=0.0,
    )

A *job* is one charging session that needs a point: a guided EV the planner places (several
:class:`Option`\\ s, one per station it can reach: when it would join that station's queue and how long
it would then hold a point), a guided EV whose station is fixed (one option), or a background EV's
session (one option, ``depart=None``: it does not count in the objective). A job that already holds a
point at the problem's start has ``started`` (its start is fixed). Times are seconds of day.

The model (:mod:`evcd.planner.solver` builds it) places every job at one of its options' stations and
gives it a start: not before its arrival, nor before the problem's ``start`` (the episode's), nor after
its ``deadline``; at most ``points`` sessions hold a point of a station at once, less the points
``blocked`` (out of service) at that time; and, where FIFO is kept, two sessions at one station start
in the order they arrived (strictly earlier arrival, earlier or equal start). It minimises the guided
jobs' total travel time, ``start - depart``.

Every check raises ``ValueError`` naming the job or station; nothing here needs OR-Tools.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from evcd.utils.validation import check_int, is_real, require


@dataclass(frozen=True)
class Option:
    """A station a job can charge at: its index in :attr:`PlanProblem.stations`, when the job would
    join that station's queue (``arrival``, s of day) and how long it would hold a point there
    (``duration``, s)."""

    station: int
    arrival: float
    duration: float


@dataclass(frozen=True)
class Job:
    """One charging session to place (module docstring).

    Attributes:
        name: unique; a guided EV's is its vehicle id.
        options: the stations it can charge at (empty: it can reach none, the model is infeasible).
        depart: its departure (s of day) if it is a guided EV: ``start - depart`` counts in the
            objective; ``None`` for a background session.
        deadline: the latest start (s of day; the fleet truncates a guided EV after
            ``max_travel_time``), or ``None``.
        started: when it got its point, for a session holding one at the problem's start (one option;
            its start is fixed).
    """

    name: str
    options: tuple[Option, ...]
    depart: float | None = None
    deadline: float | None = None
    started: float | None = None

    @property
    def guided(self) -> bool:
        """Whether it counts in the objective (a guided EV)."""
        return self.depart is not None


@dataclass(frozen=True)
class Blocked:
    """``points`` of a station out of service over ``[start, end)`` (s of day): a charger outage."""

    points: int
    start: float
    end: float


@dataclass(frozen=True)
class PlanStation:
    """A station: its id, its charging points and the points out of service when (``blocked``)."""

    id: str
    points: int
    blocked: tuple[Blocked, ...] = ()


@dataclass(frozen=True)
class PlanProblem:
    """Stations and jobs (module docstring); ``start``: the episode's start (s of day), before which
    no job gets a point unless it holds one already.

    Raises:
        ValueError: a malformed problem (the message names the station or job): no station, a
            station without points, blocked points outside ``[1, points]`` or a bad period, repeated
            names, an option at an unknown station or with a time that is not a finite number (a
            negative duration included), a started job with several options or starting after
            ``start``, more started jobs at a station than it has points.
    """

    stations: tuple[PlanStation, ...]
    jobs: tuple[Job, ...]
    start: float

    def __post_init__(self) -> None:
        require(is_real(self.start), f"PlanProblem: start={self.start!r} must be a finite number")
        require(len(self.stations) > 0, "PlanProblem: no station")
        ids = [st.id for st in self.stations]
        require(len(set(ids)) == len(ids), f"PlanProblem: station ids must be unique: {ids}")
        for st in self.stations:
            _check_station(st)
        names = [job.name for job in self.jobs]
        repeated = sorted({n for n in names if names.count(n) > 1})
        require(not repeated, f"PlanProblem: job names must be unique; repeated: {repeated[:5]}")
        for job in self.jobs:
            _check_job(job, len(self.stations), self.start)
        for s, st in enumerate(self.stations):
            held = [j for j in self.jobs if j.started is not None and j.options[0].station == s]
            for job in held:
                assert job.started is not None
                at = sum(1 for o in held if o.started <= job.started < _end(o))  # type: ignore[operator]
                require(at <= st.points, f"PlanProblem: {at} sessions hold a point of station {st.id!r} "
                                         f"at t={job.started:g} s; it has {st.points}")  # fmt: skip

    @property
    def guided(self) -> tuple[Job, ...]:
        """The jobs that count in the objective."""
        return tuple(job for job in self.jobs if job.guided)


def _end(job: Job) -> float:
    """When a started job releases its point."""
    assert job.started is not None
    return job.started + job.options[0].duration


def _check_station(st: PlanStation) -> None:
    check_int(f"station {st.id!r}: points", st.points, minimum=1)
    for b in st.blocked:
        check_int(f"station {st.id!r}: blocked points", b.points, minimum=1, maximum=st.points)
        require(
            is_real(b.start) and is_real(b.end) and b.start < b.end,
            f"station {st.id!r}: blocked period [{b.start!r}, {b.end!r}) must be finite with start < end",
        )


def _check_job(job: Job, n_stations: int, start: float) -> None:
    where = f"job {job.name!r}"
    for o in job.options:
        check_int(f"{where}: option station", o.station, minimum=0, maximum=n_stations - 1)
        require(is_real(o.arrival), f"{where}: arrival={o.arrival!r} must be a finite number")
        require(is_real(o.duration) and o.duration >= 0,
                f"{where}: duration={o.duration!r} must be a finite number >= 0")  # fmt: skip
    stations = [o.station for o in job.options]
    require(len(set(stations)) == len(stations), f"{where}: one option per station, got stations {stations}")
    for key in ("depart", "deadline", "started"):
        value = getattr(job, key)
        require(value is None or is_real(value), f"{where}: {key}={value!r} must be a finite number or None")
    if job.started is not None:
        require(len(job.options) == 1, f"{where}: a started session has one option, not {len(job.options)}")
        require(job.started <= start, f"{where}: started={job.started:g} after the problem's start {start:g}")


def horizon(problem: PlanProblem) -> float:
    """A time (s of day) by which every job of a feasible problem can have started: the latest
    arrival, blocked end or started session's end, plus every job's longest duration."""
    ends = [problem.start]
    ends += [o.arrival for job in problem.jobs for o in job.options]
    ends += [b.end for st in problem.stations for b in st.blocked]
    ends += [_end(job) for job in problem.jobs if job.started is not None]
    longest = sum(max((o.duration for o in job.options), default=0.0) for job in problem.jobs)
    return max(ends) + longest + 1.0 if math.isfinite(longest) else math.inf
