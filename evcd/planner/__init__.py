"""The clairvoyant fleet planner: a fleet episode as a scheduling problem, solved with CP-SAT.

It knows what no dispatcher knows, the episode's future: when each guided EV asks, how long it would
drive to each station and charge there, the background EVs' sessions, the charger outages. Its
optimum is a bound on what a dispatcher could reach in the model (:mod:`evcd.env.fleet.plan_inputs`
reads an episode into it, :mod:`evcd.loops.fleet_bound` plays its plan in SUMO).

- :mod:`evcd.planner.model`: the problem (:class:`PlanProblem`: stations, jobs, options), checked;
- :mod:`evcd.planner.solver`: OR-Tools' CP-SAT on it (:func:`solve`, :class:`PlanSettings`,
  :class:`PlanResult`); OR-Tools is the optional extra ``bound`` (``pip install -e .[bound]``),
  imported when a problem is solved.

Plain Python, no simulation.
"""

from evcd.planner.model import Blocked, Job, Option, PlanProblem, PlanStation
from evcd.planner.solver import INSTALL_HINT, MissingSolverError, PlanResult, PlanSettings, solve

__all__ = [
    "INSTALL_HINT",
    "Blocked",
    "Job",
    "MissingSolverError",
    "Option",
    "PlanProblem",
    "PlanResult",
    "PlanSettings",
    "PlanStation",
    "solve",
]
