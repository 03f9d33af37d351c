"""The clairvoyant planner's cost: how long a fleet episode takes to read and to solve, and how close
the solver gets to a proof at each time limit.

Per evaluation fleet episode of ``seed``: the episode read in SUMO once (every guided EV on its own
station, :func:`~evcd.env.fleet.plan_inputs.read_episode`), then its problem solved at each time limit
(CP-SAT's deterministic seconds, :class:`~evcd.planner.solver.PlanSettings`), all in the same run. The
figures: the solver's wall time per episode (median and max) and its proven optimality gap
``(model - bound) / model`` of the mean travel time (median and max over the episodes where a plan
was found, 0 where proven optimal; ``no_plan`` counts the others) per limit, the reading run's wall
time, and ``bound_column_minutes`` per limit: what the fleet table's bound column costs at this
episode rate (:data:`TABLE_EPISODES` episodes, each read, solved and played, the play costing about
one reading run) on ``jobs`` cores.
"""

from __future__ import annotations

import logging
import math
import statistics
from collections.abc import Mapping, Sequence
from typing import Any

from evcd.env.fleet import FleetEnv
from evcd.env.fleet.plan_inputs import read_episode
from evcd.loops.seeds import episode_spec
from evcd.planner.solver import PlanSettings, cp_model, solve

log = logging.getLogger(__name__)

#: The fleet table's bound column: 5 seeds x 5 held-out episodes x 3 guided shares.
TABLE_EPISODES = 75


def _gap(model: float, bound: float) -> float:
    """The proven optimality gap of a plan; NaN where no plan was found."""
    if not (math.isfinite(model) and math.isfinite(bound)):
        return math.nan
    return (model - bound) / model if model > 0 else 0.0


def _median_max(values: Sequence[float]) -> tuple[float, float]:
    finite = [v for v in values if math.isfinite(v)]
    return (statistics.median(finite), max(finite)) if finite else (math.nan, math.nan)


def planner_cost(
    env_kwargs: Mapping[str, Any],
    episodes: int = 3,
    seed: int = 0,
    time_limits: Sequence[float] = (1.0, 10.0),
    jobs: int = 2,
) -> dict[str, Any]:
    """Read ``episodes`` fleet episodes and solve each at every limit of ``time_limits``.

    Args:
        env_kwargs: :class:`~evcd.env.fleet.FleetEnv` arguments.
        episodes: evaluation episodes of ``seed`` to time (>= 1).
        seed: run seed.
        time_limits: the solver's limits to compare (CP-SAT's deterministic seconds, each > 0).
        jobs: the cores the bound column's estimate spreads its episodes over.

    Raises:
        MissingSolverError: OR-Tools is not installed (before SUMO starts).
        ValueError: a limit <= 0, no episode.
    """
    if episodes < 1:
        raise ValueError(f"episodes={episodes}: must be >= 1")
    settings = [PlanSettings(time_limit_s=limit) for limit in time_limits]  # refuses a limit <= 0 here
    cp_model()
    env = FleetEnv(**env_kwargs)
    rows: list[dict[str, Any]] = []
    try:
        env.prepare()
        for i in range(episodes):
            spec = episode_spec(seed, i)
            inputs = read_episode(env, spec.reset_seed, spec.options)
            for s in settings:
                result = solve(inputs.problem, s, hint=inputs.own)
                rows.append({"episode": i, "day": inputs.day, "guided": result.guided,
                             "time_limit_s": s.time_limit_s, "status": result.status,
                             "solve_s": round(result.solve_s, 3), "read_s": round(inputs.wall_s, 3),
                             "bound": result.mean_bound, "model": result.mean_objective,
                             "gap": _gap(result.mean_objective, result.mean_bound)})  # fmt: skip
                log.info("episode %d (%d guided EVs), limit %g: %s in %.1f s, bound %.1f s, plan %.1f s",
                         i, result.guided, s.time_limit_s, result.status, result.solve_s,
                         result.mean_bound, result.mean_objective)  # fmt: skip
    finally:
        env.close()
    read = [r["read_s"] for r in rows if r["time_limit_s"] == settings[0].time_limit_s]
    by_limit = {}
    for s in settings:
        mine = [r for r in rows if r["time_limit_s"] == s.time_limit_s]
        solve_s = [r["solve_s"] for r in mine]
        gap_median, gap_max = _median_max([r["gap"] for r in mine])
        per_episode = statistics.fmean(read) * 2 + statistics.fmean(solve_s)  # read, solve, play
        by_limit[str(s.time_limit_s)] = {
            "solve_s_median": statistics.median(solve_s), "solve_s_max": max(solve_s),
            "gap_median": gap_median, "gap_max": gap_max,
            "optimal": sum(r["status"] == "optimal" for r in mine),
            "no_plan": sum(not math.isfinite(r["model"]) for r in mine), "episodes": len(mine),
            "bound_column_minutes": per_episode * TABLE_EPISODES / jobs / 60,
        }  # fmt: skip
    return {"read_s_median": statistics.median(read), "limits": by_limit, "jobs": jobs, "episodes": rows}
