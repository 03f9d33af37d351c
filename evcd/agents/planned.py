"""A plan played as a fleet dispatcher: each guided EV to the station a plan names for it.

    agent = make_agent_for_env("planned", fleet, rng, plan={"ev12": 3, "ev40": 0})
    FleetRunner(fleet).episode(spec, agent)

A plan names stations by vehicle id (the clairvoyant planner's, :mod:`evcd.planner`, read off the
episode by :mod:`evcd.loops.fleet_bound`), so the dispatcher reads which guided EVs decide off the
fleet it plays: the rows of a :meth:`~PlannedAgent.decide` call are the fleet's agents at that tick,
in the fleet's order (the runner's contract, :meth:`evcd.agents.base.Agent.decide`). An EV the plan
does not name keeps the station it is heading to (with the empty plan, the default, every EV drives
to its trip's own station: the plain day). It does not look at the observations: it is a
measurement tool, not a policy, and it never learns.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from evcd.agents.base import Agent, EpisodeState
from evcd.utils.validation import check_int, require


class PlannedAgent(Agent):
    """Sends each guided EV of a fleet to ``plan[vehicle]`` (module docstring).

    Args:
        n_stations: number of stations.
        rng: unused (a plan draws nothing); kept for the agents' interface.
        plan: station index per vehicle id (default: none, every EV keeps its station).
        fleet: the :class:`~evcd.env.fleet.FleetEnv` whose guided EVs it sends (read off the
            environment by :meth:`env_kwargs`).

    Raises:
        ValueError: a station index outside ``[0, n_stations)`` (the message names the vehicle).
    """

    name = "planned"
    obs_blocks: ClassVar[tuple[int, ...]] = (4,)
    options: ClassVar[Mapping[str, Any]] = {"plan": {}}
    env_options: ClassVar[tuple[str, ...]] = ("fleet",)

    def __init__(
        self,
        n_stations: int,
        rng: np.random.Generator,
        plan: Mapping[str, int] | None = None,
        fleet: Any = None,
    ) -> None:
        super().__init__(n_stations, rng)
        self.plan = {str(vehicle): check_int(f"plan[{vehicle!r}]", station, minimum=0, maximum=n_stations - 1)
                     for vehicle, station in dict(plan or {}).items()}  # fmt: skip
        self.fleet = fleet

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The fleet itself (the plan is played by vehicle id)."""
        return {"fleet": getattr(env, "unwrapped", env)}

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The planned station of each guided EV deciding now (the fleet's agents, in order).

        Raises:
            ValueError: no fleet was given, or the rows are not the fleet's agents of this tick.
        """
        require(
            self.fleet is not None,
            "agent 'planned' plays a fleet's guided EVs by vehicle id: make it with "
            "make_agent_for_env('planned', fleet, rng, plan=...)",
        )
        due = list(self.fleet.agents)
        k = len(np.atleast_2d(np.asarray(obs)))
        require(len(due) == k == len(episodes), f"agent 'planned': {k} observations for the fleet's "
                                                f"{len(due)} agents at this tick")  # fmt: skip
        guided = self.fleet.guided
        return np.array([self.plan.get(a, guided[a].station) for a in due], dtype=np.int64)
