"""Solve a :class:`~evcd.planner.model.PlanProblem` with OR-Tools' CP-SAT: the best plan found and
the proven lower bound of its objective.

    result = solve(problem, PlanSettings(time_limit_s=30))
    result.status, result.stations["ev3"], result.mean_bound, result.mean_objective

The CP-SAT model, in whole seconds from the problem's start (arrivals and durations rounded up, a
deadline down): per job one start variable; per option an optional interval of the option's duration
on that start, present where the job goes there (exactly one option per job); per station one
cumulative of capacity ``points`` holding those intervals, the started sessions (fixed intervals) and
the blocked points (fixed intervals of their demand); per pair of sessions that may meet at a station,
the earlier arrival starts no later (``fifo``; equal arrivals in the problem's job order); the
objective the guided jobs' summed start, less their departures. With FIFO, each option's start is
also bounded below by the job's start there were it the only guided job with a choice
(:func:`~evcd.planner.schedule.lower_starts`: implied by the rest, but it gives the solver's linear
relaxation the queues the background sessions make), which is what its proven bound starts from.
The search starts from a plan improved by single-EV moves (:func:`search_start`,
:mod:`evcd.planner.search`), so its plan is never worse than that one.

Two numbers, both honest: ``objective``, the model's value of the best plan found (the optimum when
``status == "optimal"``), and ``bound``, the solver's proven lower bound of the model's optimum (equal
to the objective when optimal; at the time limit, the best bound proven so far). Dropping FIFO
(``fifo=False``) relaxes the model: its bound is a lower bound of the FIFO model's too.

Same problem and settings, same result: with one worker, a fixed ``seed`` and a limit in CP-SAT's
deterministic time, the search and where it stops do not depend on the machine's speed or load (only
the wall-clock cap, far above it, could stop it earlier on a machine many times slower).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from evcd.planner.model import Job, PlanProblem, PlanStation, horizon
from evcd.planner.schedule import fifo_starts, greedy_plan, lower_starts, plan_value, up
from evcd.planner.search import improve_plan
from evcd.utils.validation import check_bool, check_int, check_real

#: How a user gets the solver.
INSTALL_HINT = "pip install -e .[bound]"
#: The wall-clock cap on a search, as a multiple of its deterministic limit (PlanSettings.time_limit_s).
WALL_CAP = 20.0
#: The statuses of a :class:`PlanResult`.
STATUSES = ("optimal", "feasible", "infeasible", "unknown", "empty")


class MissingSolverError(ImportError):
    """OR-Tools is not installed (the optional extra ``bound``)."""


def cp_model() -> Any:
    """OR-Tools' ``cp_model`` module.

    Raises:
        MissingSolverError: OR-Tools is not installed; the message names the extra.
    """
    try:
        from ortools.sat.python import cp_model as module
    except ImportError as exc:
        raise MissingSolverError(
            f"the fleet planner needs OR-Tools' CP-SAT, the optional extra 'bound': {INSTALL_HINT} ({exc})"
        ) from exc
    return module


@dataclass(frozen=True)
class PlanSettings:
    """How the planner searches.

    Attributes:
        time_limit_s: how long the solver may search (> 0), in CP-SAT's deterministic time (its count
            of work done, about a second each on one core of a current CPU): a search stopped at the
            limit stops at the same point on every machine and under any load, so the same problem
            and settings give the same plan and bound. At the limit it reports the best plan found and
            the best bound proven. A wall-clock cap of :data:`WALL_CAP` times the limit guards against
            a machine far slower than that.
        workers: CP-SAT's search workers (>= 1; one per process on a machine that runs several).
        fifo: keep the stations' first-come-first-served order (false: a relaxation).
        seed: CP-SAT's random seed.

    Raises:
        ValueError: a setting out of range (the message names it).
    """

    time_limit_s: float = 10.0
    workers: int = 1
    fifo: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        check_real("time_limit_s", self.time_limit_s, low=0.0, low_open=True)
        check_int("workers", self.workers, minimum=1)
        check_bool("fifo", self.fifo)
        check_int("seed", self.seed, minimum=0)


@dataclass(frozen=True)
class PlanResult:
    """What the solver found.

    Attributes:
        status: ``"optimal"`` (proven), ``"feasible"`` (a plan, not proven best at the time limit),
            ``"infeasible"`` (proven: some job cannot start by its deadline), ``"unknown"`` (no plan
            at the time limit) or ``"empty"`` (no guided job: nothing to plan, both sums 0).
        stations: per job placed, the index of its station (every job of a plan).
        starts: per job placed, its start (s of day).
        objective: the guided jobs' summed travel time (s) in the best plan; NaN without one.
        bound: the proven lower bound of that sum in the model (s); NaN if none was proven.
        guided: the number of guided jobs (the means divide by it).
        solve_s: the solver's wall time (s).
        message: one line saying what happened.
    """

    status: str
    stations: Mapping[str, int] = field(default_factory=dict)
    starts: Mapping[str, float] = field(default_factory=dict)
    objective: float = math.nan
    bound: float = math.nan
    guided: int = 0
    solve_s: float = 0.0
    message: str = ""

    @property
    def mean_objective(self) -> float:
        """The guided jobs' mean travel time in the best plan (s)."""
        return self.objective / self.guided if self.guided else math.nan

    @property
    def mean_bound(self) -> float:
        """The proven lower bound of the guided jobs' mean travel time (s)."""
        return self.bound / self.guided if self.guided else math.nan

    @property
    def gap(self) -> float:
        """Proven optimality gap of the mean (s): ``mean_objective - mean_bound`` (0 when optimal)."""
        return self.mean_objective - self.mean_bound

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON), with the means."""
        return {**asdict(self), "stations": dict(self.stations), "starts": dict(self.starts),
                "mean_objective": self.mean_objective, "mean_bound": self.mean_bound}  # fmt: skip


def solve(
    problem: PlanProblem, settings: PlanSettings | None = None, hint: Mapping[str, int] | None = None
) -> PlanResult:
    """The best plan of ``problem`` within ``settings`` (module docstring).

    Args:
        problem: the stations and jobs.
        settings: time limit, workers, FIFO, seed (default :class:`PlanSettings`).
        hint: a station per guided job to start the search from besides the greedy plan (both improved
            by single-EV moves first: :func:`search_start`).

    Raises:
        MissingSolverError: OR-Tools is not installed (the message names the extra).
    """
    settings = settings or PlanSettings()
    cp = cp_model()
    guided = problem.guided
    if not guided:
        return PlanResult("empty", objective=0.0, bound=0.0, message="no guided EV: nothing to plan")
    origin = math.floor(problem.start)
    model = cp.CpModel()
    # with FIFO a session starts no earlier than it would with no other guided EV at its station
    lower = lower_starts(problem) if settings.fifo else {}
    placed = _Placed(model, origin, math.floor(horizon(problem)) - origin, len(problem.stations))
    for job in problem.jobs:
        if not placed.add(job, lower):
            return PlanResult("infeasible", guided=len(guided), message=f"infeasible: job {job.name!r} can "
                              "reach no station before its deadline")  # fmt: skip
    for s, st in enumerate(problem.stations):
        intervals = [e[3] for e in placed.at_station[s]]
        demands = [1] * len(intervals)
        held = [(up(j.started - origin), up(j.options[0].duration)) for j in problem.jobs
                if j.started is not None and j.options[0].station == s]  # fmt: skip
        for t0, length, points in _blocked_profile(st, held, origin):
            intervals.append(model.NewFixedSizeIntervalVar(t0, length, f"blocked_{st.id}_{t0}"))
            demands.append(points)
        model.AddCumulative(intervals, demands, st.points)
        if settings.fifo:
            _fifo(model, placed.at_station[s])
    model.Minimize(sum(placed.starts[job.name] for job in guided))
    offset = origin * len(guided) - sum(float(job.depart) for job in guided)  # type: ignore[arg-type]
    placed.hint(problem, search_start(problem, hint))
    solver = cp.CpSolver()
    solver.parameters.max_deterministic_time = settings.time_limit_s
    solver.parameters.max_time_in_seconds = WALL_CAP * settings.time_limit_s
    solver.parameters.num_workers = settings.workers
    solver.parameters.random_seed = settings.seed
    code = solver.Solve(model)
    if code == cp.MODEL_INVALID:
        raise RuntimeError(f"the planner built an invalid CP-SAT model: {model.Validate()}")
    named = {cp.OPTIMAL: "optimal", cp.FEASIBLE: "feasible", cp.INFEASIBLE: "infeasible"}
    status = named.get(code, "unknown")
    result: dict[str, Any] = {"guided": len(guided), "solve_s": float(solver.WallTime())}
    if status in ("optimal", "feasible"):
        result["stations"] = {n: next(s for s, lit in opts.items() if _value(solver, lit))
                              for n, opts in placed.literals.items()}  # fmt: skip
        result["starts"] = {n: float(solver.Value(v) + origin) for n, v in placed.starts.items()}
        result["objective"] = float(solver.ObjectiveValue()) + offset
    if status != "infeasible":
        result["bound"] = float(solver.BestObjectiveBound()) + offset
    return PlanResult(status, message=_message(status, result, settings), **result)


def search_start(problem: PlanProblem, hint: Mapping[str, int] | None = None) -> dict[str, int]:
    """The plan the solver's search starts from: the greedy plan (:func:`greedy_plan`) and ``hint``,
    each improved by single-EV moves (:func:`~evcd.planner.search.improve_plan`), the better of the
    two in the model (ties: the greedy one)."""
    starts = [greedy_plan(problem), *([dict(hint)] if hint is not None else [])]
    plans = [improve_plan(problem, p) for p in starts]
    return min(plans, key=lambda p: plan_value(problem, p))


class _Placed:
    """The CP-SAT variables of the jobs placed so far: per job its start and a presence literal per
    option station (``1`` where it has one option), and per station its sessions' entries
    ``(arrival, start, literal, interval)`` in the problem's job order."""

    def __init__(self, model: Any, origin: int, last: int, n_stations: int) -> None:
        self.model, self.origin, self.last = model, origin, last
        self.starts: dict[str, Any] = {}
        self.literals: dict[str, dict[int, Any]] = {}
        self.at_station: list[list[tuple[float, Any, Any, Any]]] = [[] for _ in range(n_stations)]

    def add(self, job: Job, lower: Mapping[tuple[str, int], float]) -> bool:
        """Place ``job`` (``lower``: a lower bound of its start per option station, s of day); false
        if no option is reachable before its deadline."""
        model, origin = self.model, self.origin
        if job.started is not None:  # fixed: it enters its station's cumulative with the blocked points
            self.starts[job.name] = up(job.started - origin)
            self.literals[job.name] = {job.options[0].station: 1}
            return True
        deadline = math.inf if job.deadline is None else math.floor(job.deadline + 1e-9) - origin
        latest = int(min(self.last, deadline))
        earliest: dict[int, int] = {}
        for o in job.options:
            t = max(up(o.arrival - origin), up(lower.get((job.name, o.station), origin) - origin), 0)
            if t <= latest:
                earliest[o.station] = t
        if not earliest:
            return False
        start = model.NewIntVar(min(earliest.values()), latest, f"start_{job.name}")
        literals: dict[int, Any] = {}
        for o in job.options:
            if o.station not in earliest:
                continue
            size = up(o.duration)
            if len(earliest) == 1:
                literal: Any = 1
                interval = model.NewFixedSizeIntervalVar(start, size, f"{job.name}@{o.station}")
            else:
                literal = model.NewBoolVar(f"{job.name}->{o.station}")
                name = f"{job.name}@{o.station}"
                interval = model.NewOptionalFixedSizeIntervalVar(start, size, literal, name)
                model.Add(start >= earliest[o.station]).OnlyEnforceIf(literal)
            literals[o.station] = literal
            self.at_station[o.station].append((o.arrival, start, literal, interval))
        if len(literals) > 1:
            model.AddExactlyOne(literals.values())
            model.Add(start >= sum(earliest[s] * lit for s, lit in literals.items()))  # for the LP
        self.starts[job.name], self.literals[job.name] = start, literals
        return True

    def hint(self, problem: PlanProblem, plan: Mapping[str, int]) -> None:
        """Hint a whole solution: ``plan``'s stations and their FIFO starts (:func:`fifo_starts`)."""
        plan = {n: s for n, s in plan.items() if s in self.literals.get(n, {})}
        for name, start in fifo_starts(problem, plan).items():
            var = self.starts.get(name)
            if var is not None and not isinstance(var, int):
                self.model.AddHint(var, int(start) - self.origin)
        for name, station in plan.items():
            for s, literal in self.literals[name].items():
                if not isinstance(literal, int):
                    self.model.AddHint(literal, s == station)


def _fifo(model: Any, entries: list[tuple[float, Any, Any, Any]]) -> None:
    """Sessions that meet at a station start in the order they arrived (``entries`` in the problem's
    job order, which orders equal arrivals)."""
    ordered = sorted(entries, key=lambda e: e[0])
    for i, (_, start, literal, _) in enumerate(ordered):
        for _, other, other_literal, _ in ordered[i + 1 :]:
            condition = [x for x in (literal, other_literal) if not isinstance(x, int)]
            model.Add(start <= other).OnlyEnforceIf(condition)


def _blocked_profile(
    st: PlanStation, fixed: list[tuple[int, int]], origin: int
) -> list[tuple[int, int, int]]:
    """The station's fixed load as ``(start, length, points)`` pieces (whole seconds from ``origin``):
    the started sessions and the blocked points, where both meet never more than the points (a
    session that holds a point when an outage begins keeps it in the model; SUMO interrupts it)."""
    blocked = [(_down(b.start - origin), up(b.end - origin), b.points) for b in st.blocked]
    times = sorted({t for a, b, _ in blocked for t in (a, b)} | {t for a, d in fixed for t in (a, a + d)})
    pieces = []
    for t0, t1 in itertools.pairwise(times):
        held = sum(1 for a, d in fixed if a <= t0 < a + d)
        out = sum(p for a, b, p in blocked if a <= t0 < b)
        load = held + min(out, max(st.points - held, 0))
        if load > 0 and t1 > t0:
            pieces.append((t0, t1 - t0, load))
    return pieces


def _value(solver: Any, literal: Any) -> bool:
    return bool(literal) if isinstance(literal, int) else bool(solver.BooleanValue(literal))


def _down(seconds: float) -> int:
    return math.floor(seconds + 1e-9)


def _message(status: str, result: Mapping[str, Any], settings: PlanSettings) -> str:
    n = result["guided"]
    if status == "infeasible":
        return "infeasible: some guided EV cannot start charging by its deadline at any station"
    if status == "unknown":
        return f"no plan found within time_limit_s={settings.time_limit_s:g} ({n} guided EVs)"
    mean_o, mean_b = result["objective"] / n, result["bound"] / n
    return (f"{status}: {n} guided EVs, mean travel {mean_o:.1f} s, proven bound {mean_b:.1f} s "
            f"({result['solve_s']:.2f} s)")  # fmt: skip
