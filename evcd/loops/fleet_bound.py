"""The clairvoyant bound of the fleet: how far the best dispatcher could go, and the plan played.

    bound = FleetBound(PlanSettings(time_limit_s=30))          # refuses a bad setting, or no OR-Tools
    played = bound.play(FleetRunner(fleet), specs)              # FleetEpisodes of the played plans
    bound.report()["fleet_bound"]["episodes"][0]                 # bound, model, played, gap, status

Per episode: read it (:func:`~evcd.env.fleet.plan_inputs.read_episode`, one SUMO run with every
guided EV on its own station), solve the planner's model (:func:`~evcd.planner.solver`, CP-SAT), then
play the best plan found in SUMO through the runner as any dispatcher is played
(:class:`~evcd.agents.planned.PlannedAgent`, ``agent=planned``). Two numbers, both honest: the
solver's proven lower bound of the model's optimum (``bound``: the guided EVs' mean travel time,
departure to charge start) and the plan's travel time played in SUMO (``played``: the fleet's
``guided_travel``); their difference measures the model. A plan cannot be played where the model is
infeasible or no plan was found in time: the episode is then played with every EV on its own station
(the plain day) and its row says why.

The model keeps: the guided EVs' request times (first tick) and drive times then, their energy at
each station, the stations' points, the FIFO order of arrivals (background sessions included, whose
starts the guided EVs can delay), the outages as points out of service, and the fleet's truncation
after ``max_travel_time`` as a deadline. It drops (so the played plan can differ from the model, either
way): traffic the guided EVs make or meet after their request (drive times are the request's
estimates, which leave out slowing into the car park: a few seconds per EV on the test grid), the
ticks (an EV is sent at its first tick and never again), the car parks' capacity, an outage
interrupting a charge (SUMO puts the EV back at the queue's head; the model keeps a started charge on
its point and never starts one that an outage would interrupt), the order of arrivals within one
second, and the background EVs' own travel (their arrival times are the plain day's).

Like :class:`~evcd.loops.hindsight.HindsightBound` it knows the future: a measurement built from two
runs of each episode, played where the loops would play an agent.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar

import numpy as np

from evcd.agents import Agent, agent_names, check_agent_task, make_agent_for_env
from evcd.agents.planned import PlannedAgent
from evcd.env.fleet.plan_inputs import EpisodeInputs, read_episode
from evcd.env.runners.base import EpisodeSpec
from evcd.env.runners.fleet import FleetEpisode, FleetRunner
from evcd.loops.stats import finite_mean
from evcd.planner.schedule import floor_value
from evcd.planner.solver import PlanResult, PlanSettings, cp_model, solve

log = logging.getLogger(__name__)

#: An EV counts as ahead of the model when it started charging more than this before its model start.
AHEAD_S = 1.0


@dataclass(frozen=True)
class BoundEpisode:
    """One episode's bound (times in s: means over the episode's guided EVs).

    Attributes:
        index, day: the episode (its number in the run, its day's demand seed).
        guided: guided EVs in the model; ``planned``: those it placed (they decide).
        status: the solver's (:data:`~evcd.planner.solver.STATUSES`).
        bound: the proven lower bound of the model's mean travel time.
        model: the mean travel time of the best plan in the model.
        played: the fleet's ``guided_travel`` with that plan played in SUMO (EVs that charged).
        plain: the guided EVs' mean travel time with every EV on its own station (the reading run).
        floor: the model's mean were no guided EV delayed by another
            (:func:`~evcd.planner.schedule.floor_value`): where ``bound`` is no higher, the solver
            proved nothing about the guided EVs' competition for the points.
        played_minus_bound, played_minus_model: the model's gaps.
        ahead: guided EVs that started charging in SUMO more than :data:`AHEAD_S` before the model
            said (where the model is not exact, it can err towards SUMO).
        truncated: guided EVs of the played plan that did not charge.
        solve_s, read_s, play_s: wall times of the solver, the reading run and the played run.
        message: the solver's line.
    """

    index: int
    day: int
    guided: int
    planned: int
    status: str
    bound: float
    model: float
    played: float
    plain: float
    floor: float
    played_minus_bound: float
    played_minus_model: float
    ahead: int
    truncated: int
    solve_s: float
    read_s: float
    play_s: float
    message: str

    def row(self) -> dict[str, Any]:
        """Plain data (JSON, CSV)."""
        return asdict(self)


class FleetBound:
    """The clairvoyant planner's bound and played plan over the fleet episodes it plays (module
    docstring).

    Args:
        settings: the solver's (time limit, workers, FIFO, seed).

    Raises:
        MissingSolverError: OR-Tools is not installed (the message names the extra ``bound``); checked here,
            before SUMO starts.
    """

    name: ClassVar[str] = "fleet_bound"
    #: It never learns (the loops ask this of whatever they play).
    learns: ClassVar[bool] = False
    #: Runs the loops' progress counts per episode: the played plan (the reading run is not counted).
    runs_per_episode: ClassVar[int] = 1

    def __init__(self, settings: PlanSettings | None = None) -> None:
        self.settings = settings or PlanSettings()
        cp_model()  # a missing solver is said before any SUMO run
        self.episodes: list[BoundEpisode] = []
        self.results: list[PlanResult] = []

    def __repr__(self) -> str:
        return f"FleetBound({', '.join(f'{k}={v!r}' for k, v in asdict(self.settings).items())})"

    def play(
        self,
        runner: FleetRunner,
        specs: Sequence[EpisodeSpec],
        on_episode: Callable[[FleetEpisode], None] | None = None,
    ) -> list[FleetEpisode]:
        """Read, solve and play each of ``specs`` (module docstring); the played plans' episodes, in
        spec order (``on_episode`` sees each)."""
        env = runner.env
        played = []
        for spec in specs:
            inputs = read_episode(env, spec.reset_seed, spec.options)
            result = solve(inputs.problem, self.settings, hint=inputs.own)
            plan = {v: s for v, s in result.stations.items() if v in inputs.requests}
            if result.status not in ("optimal", "feasible"):
                log.warning("fleet episode %d (day %d): %s; played with every EV on its own station",
                            spec.index, inputs.day, result.message)  # fmt: skip
            agent = PlannedAgent(len(env.stations), np.random.default_rng(0), plan=plan, fleet=env)
            episode = runner.episode(spec, agent)
            self.results.append(result)
            self.episodes.append(_bound_episode(spec.index, inputs, result, episode, env.outcomes()))
            log.info("fleet episode %d (day %d): bound %.1f s, model %.1f s, played %.1f s (%s)", spec.index,
                     inputs.day, result.mean_bound, result.mean_objective, episode.travel_time,
                     result.status)  # fmt: skip
            played.append(episode)
            if on_episode is not None:
                on_episode(episode)
        return played

    def report(self) -> dict[str, Any]:
        """Per episode its :class:`BoundEpisode` row, and the means over episodes of the bound, the
        model, the played plan and the model's gaps."""
        if not self.episodes:
            return {}
        rows = [e.row() for e in self.episodes]
        keys = (
            "bound",
            "model",
            "played",
            "plain",
            "floor",
            "played_minus_bound",
            "played_minus_model",
            "solve_s",
        )
        means = {k: finite_mean([r[k] for r in rows]) for k in keys}
        statuses = sorted({r["status"] for r in rows})
        return {"fleet_bound": {"episodes": rows, "mean": means, "statuses": statuses,
                                "settings": asdict(self.settings)}}  # fmt: skip


def make_fleet_dispatcher(name: str, env: Any, rng: np.random.Generator, **params: Any) -> Agent | FleetBound:
    """The fleet agent ``name`` for ``env`` (:func:`evcd.agents.make_agent_for_env`), or the clairvoyant
    bound (``fleet_bound``; ``params``: :class:`~evcd.planner.solver.PlanSettings`).

    Raises:
        ValueError: an unknown name or option, or a setting out of range (the message names it).
        MissingSolverError: ``fleet_bound`` without OR-Tools (the message names the extra).
    """
    if name != FleetBound.name:
        check_agent_task(name, "fleet")
        return make_agent_for_env(name, env, rng, **params)
    known = [f.name for f in fields(PlanSettings)]
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ValueError(f"agent {name!r}: unknown options {unknown}; it takes {', '.join(known)}")
    return FleetBound(PlanSettings(**params))


def fleet_dispatcher_names() -> tuple[str, ...]:
    """The names a fleet run can be given: the registered agents that read ``[D, N, Z, H]`` (outside
    packages' included) and the clairvoyant bound."""
    return (*agent_names("fleet"), FleetBound.name)


def fleet_learns(name: str) -> bool:
    """Whether the fleet dispatcher ``name`` learns (``fleet_bound``: no).

    Raises:
        ValueError: a name the fleet does not take (the message lists its agents).
    """
    return name != FleetBound.name and check_agent_task(name, "fleet").learns


def _bound_episode(
    index: int, inputs: EpisodeInputs, result: PlanResult, episode: FleetEpisode, outcomes: Sequence[dict]
) -> BoundEpisode:
    travel = {o["vehicle"]: float(o["travel_time"]) for o in outcomes if o.get("reason") == "charging"}
    depart = {job.name: float(job.depart) for job in inputs.problem.guided}  # type: ignore[arg-type]
    ahead = sum(1 for v, start in result.starts.items()
                if v in travel and v in depart and travel[v] < start - depart[v] - AHEAD_S)  # fmt: skip
    played = episode.travel_time
    plain = finite_mean(list(inputs.plain_travel.values()))
    return BoundEpisode(
        index=index, day=inputs.day, guided=result.guided, planned=len(inputs.requests), status=result.status,
        bound=result.mean_bound, model=result.mean_objective, played=played, plain=plain,
        floor=floor_value(inputs.problem) / result.guided if result.guided else math.nan,
        played_minus_bound=played - result.mean_bound, played_minus_model=played - result.mean_objective,
        ahead=ahead, truncated=int(episode.measures.truncated), solve_s=result.solve_s, read_s=inputs.wall_s,
        play_s=episode.wall_s, message=result.message,
    )  # fmt: skip
