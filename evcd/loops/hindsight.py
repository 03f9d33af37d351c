"""The best station in hindsight: a bound on what a dispatcher that picks stations can reach.

    bound = HindsightBound(n_stations=5)
    rows = bound.play(runner, specs)         # each episode driven to every station; the best kept
    extra = bound.report()                   # every station's travel time per episode

Each episode is driven to every station with no further decision (:class:`FixedStationAgent` on the
same episode seed), and the shortest travel time is kept (:func:`best_in_hindsight`). It knows the
future, so it is a measurement built from several runs of each episode, not a policy: the loops play
it where they would play an agent (``agent=hindsight`` in the scripts, :func:`make_dispatcher`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np

from evcd.agents import Agent, agent_class, agent_names, make_agent_for_env
from evcd.agents.heuristics import FixedStationAgent
from evcd.env.runners import EpisodeRow, EpisodeRunner, EpisodeSpec
from evcd.utils.validation import check_int


def best_in_hindsight(by_station: Sequence[Sequence[EpisodeRow]]) -> list[EpisodeRow]:
    """Per episode, the row of the station with the shortest travel time among the runs that ended
    charging (ties: the lowest station index); an episode no station charged in keeps station 0's
    (truncated) row. ``by_station[s][i]`` is episode ``i`` driven to station ``s`` all the way; each
    kept row's ``wall_s`` becomes the sum over the stations (what the bound cost).

    Raises:
        ValueError: no stations, or the stations' rows are not the same episodes in the same order.
    """
    if not by_station:
        raise ValueError("best_in_hindsight: no station runs given")
    seeds = [r.seed for r in by_station[0]]
    for s, rows in enumerate(by_station):
        if [r.seed for r in rows] != seeds:
            raise ValueError(f"best_in_hindsight: station {s}'s runs are not the same episodes as "
                             "station 0's")  # fmt: skip
    best = []
    for runs in zip(*by_station, strict=True):
        charged = [r for r in runs if not r.truncated]
        row = min(charged, key=lambda r: r.travel_time) if charged else runs[0]
        best.append(dataclasses.replace(row, wall_s=float(sum(r.wall_s for r in runs))))
    return best


class HindsightBound:
    """The best station in hindsight over the episodes it plays (see the module docstring). Its rows
    name the best station (``station``, ``station_id``); :meth:`report` adds every station's travel
    time per episode.

    Args:
        n_stations: number of stations.
    """

    name: ClassVar[str] = "hindsight"
    #: It never learns (the loops ask this of whatever they play).
    learns: ClassVar[bool] = False

    def __init__(self, n_stations: int) -> None:
        self.n_stations = check_int("n_stations", n_stations, minimum=1)
        self.by_station: list[list[EpisodeRow]] = []

    @property
    def runs_per_episode(self) -> int:
        """One run per station."""
        return self.n_stations

    def play(
        self,
        runner: EpisodeRunner,
        specs: Sequence[EpisodeSpec],
        on_episode: Callable[[EpisodeRow], None] | None = None,
    ) -> list[EpisodeRow]:
        """Run ``specs`` once per station with :class:`FixedStationAgent`, keep the best per episode;
        ``on_episode`` sees every run."""
        rng = np.random.default_rng(0)  # the fixed-station agents never draw
        self.by_station = [
            runner.run(specs, FixedStationAgent(self.n_stations, rng, s), on_episode=on_episode)
            for s in range(self.n_stations)
        ]
        return best_in_hindsight(self.by_station)

    def report(self) -> dict[str, Any]:
        """Per episode (in spec order) the best station and every station's travel time
        (``None`` where that run was truncated), and per station its mean over charged runs."""
        if not self.by_station:
            return {}
        best = best_in_hindsight(self.by_station)
        runs_of = zip(*self.by_station, strict=True)
        times = [[None if r.truncated else r.travel_time for r in runs] for runs in runs_of]
        means = []
        for rows in self.by_station:
            charged = [r.travel_time for r in rows if not r.truncated]
            means.append(float(np.mean(charged)) if charged else None)
        return {
            "hindsight": {
                "best_station": [None if r.truncated else r.station for r in best],
                "travel_time_by_station": times,
                "mean_by_station": means,
                "truncated_by_station": [sum(r.truncated for r in rows) for rows in self.by_station],
            }
        }


def dispatcher_names() -> tuple[str, ...]:
    """The names a single-target run can be given: the registered agents that read ``[D, N, Z]``
    (outside packages' included) and the hindsight bound."""
    return (*agent_names("single"), HindsightBound.name)


def make_dispatcher(name: str, env: Any, rng: np.random.Generator, **params: Any) -> Agent | HindsightBound:
    """The agent ``name`` for ``env`` (:func:`evcd.agents.make_agent_for_env`), or the hindsight bound.

    Raises:
        ValueError: an unknown name or option (the message names it).
    """
    check_dispatcher(name)
    if name == HindsightBound.name:
        if params:
            raise ValueError(f"agent {name!r}: unknown options {sorted(params)}; it takes none")
        return HindsightBound(int(env.action_space.n))
    return make_agent_for_env(name, env, rng, **params)


def check_dispatcher(name: Any) -> str:
    """``name`` if a run can be given it.

    Raises:
        ValueError: an unknown name (the message lists the known ones).
    """
    if name == HindsightBound.name:
        return name
    known = dispatcher_names()
    if name in agent_names() and name not in known:
        raise ValueError(f"agent {name!r} reads the fleet's observation [D, N, Z, H]: use it with task=fleet")
    if name not in known:
        raise ValueError(f"agent {name!r} is unknown; known agents: {', '.join(known)}")
    return str(name)


def check_rule(name: Any, key: str) -> str:
    """``name`` if it is a rule of the single target (a dispatcher that needs no training: a baseline
    or a validation rule; the hindsight bound included).

    Raises:
        ValueError: naming ``key``, the value and the rules allowed there.
    """
    known = dispatcher_names()
    rules = [d for d in known if not dispatcher_learns(d)]
    if name not in rules:
        kind = "a learner, not a rule" if name in known else "not a rule"
        raise ValueError(f"{key}: {name!r} is {kind}; the rules: {', '.join(rules)}")
    return str(name)


def dispatcher_learns(name: str) -> bool:
    """Whether the dispatcher ``name`` learns (a training phase runs for it).

    Raises:
        ValueError: an unknown name (the message lists the known ones).
    """
    return check_dispatcher(name) != HindsightBound.name and agent_class(name).learns
