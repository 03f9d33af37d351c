"""The fleet with a fixed set of agents: K slots that guided EVs occupy while they are on their way,
for multi-agent libraries that need every agent in every step (TorchRL's PettingZoo wrapper reads
every possible agent's observation at reset; SuperSuit's vector conversion needs a fixed agent set).

    from evcd.env.fleet.slots import FleetSlots
    env = FleetSlots(parallel_env(experiment="fleet", split="train"), slots=64)
    obs, infos = env.reset(seed=0)              # obs for slot_0 .. slot_63, every step
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step({a: policy(obs[a]) for a in env.agents})

The view: an EV that becomes an agent of the :class:`~evcd.env.fleet.FleetEnv` takes the lowest free
slot and keeps it until its trip ends; the slot's observation, action and reward are that EV's. A
slot without an EV is *inactive*: its observation is all zeros, its reward 0, its action ignored.
Every slot stays an agent until the episode ends (then all are terminated at once), so an EV's end is
in the slot's ``info`` instead: per slot and step, ``active`` (1.0 if it holds an EV that decides in
this step: the observation is real, the action will count), ``ended`` (1.0 in the step that gives
its EV's last reward: a learner's episode boundary), ``charged`` (1.0 if that EV started charging)
and ``travel_time`` (its trip's, in s, once ended; NaN otherwise). All info values are numbers (a
library stacks them into tensors). A slot freed in a step is not given to a new EV in that same step,
so one step of a slot never mixes two EVs. The episodes are the fleet's own, decision for decision.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from evcd.env.fleet.fleet_env import FleetEnv
from evcd.utils.validation import check_int

#: The numeric keys of every slot's ``info`` (module docstring).
SLOT_INFO = ("active", "ended", "charged", "travel_time")


class FleetSlots(ParallelEnv):
    """``slots`` fixed agents over a :class:`~evcd.env.fleet.FleetEnv` (module docstring).

    Args:
        env: the fleet; closing this closes it.
        slots: the number of slots, at least the most guided EVs on their way at once (a step that
            needs more raises an error naming the number).
    """

    metadata = {"name": "evcd_fleet_slots_v1", "render_modes": [], "is_parallelizable": True}  # noqa: RUF012

    def __init__(self, env: FleetEnv, slots: int) -> None:
        if not isinstance(env, FleetEnv):
            raise TypeError(f"FleetSlots wraps a FleetEnv, not a {type(env).__name__}")
        self.env = env
        self.slots = check_int("slots", slots, minimum=1)
        self.possible_agents = [f"slot_{i}" for i in range(self.slots)]
        self.agents: list[str] = []
        self.render_mode: str | None = None
        self.occupant: list[str | None] = [None] * self.slots  # the EV in each slot
        self._zero = np.zeros(env.observation_space(None).shape, dtype=np.float32)

    @functools.cache  # noqa: B019  (PettingZoo wants the same object per agent)
    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        """The fleet's ``[D, N, Z, H]`` box (zeros are in it: an inactive slot's observation)."""
        return self.env.observation_space(agent)

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gymnasium.spaces.Discrete:
        """``Discrete(m)``: a station index."""
        return self.env.action_space(agent)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, float]]]:
        """The fleet's reset, its first agents in slots 0, 1, ..."""
        obs, _ = self.env.reset(seed=seed, options=options)
        self.occupant = [None] * self.slots
        self._seat(list(obs))
        self.agents = list(self.possible_agents)
        out_obs = {a: self._zero.copy() for a in self.possible_agents}
        infos = {a: _info(0.0) for a in self.possible_agents}
        for i, ev in enumerate(self.occupant):
            if ev is not None:
                out_obs[f"slot_{i}"] = obs[ev]
                infos[f"slot_{i}"] = _info(1.0)
        return out_obs, infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """The occupied slots' actions reach their EVs (the others are ignored); one fleet step."""
        if not self.agents:
            raise RuntimeError("the episode is over (or never began): call reset()")
        fleet_actions = {}
        live = set(self.env.agents)
        for i, ev in enumerate(self.occupant):
            if ev is not None and ev in live:
                slot = f"slot_{i}"
                if slot not in actions:
                    raise ValueError(
                        f"actions: no action for {slot!r}, which holds {ev} (every slot in "
                        "env.agents takes one; an inactive slot's is ignored)"
                    )
                fleet_actions[ev] = actions[slot]
        obs, rewards, terms, truncs, fleet_infos = self.env.step(fleet_actions)
        out_obs = {a: self._zero.copy() for a in self.possible_agents}
        out_rew = dict.fromkeys(self.possible_agents, 0.0)
        infos = {a: _info(0.0) for a in self.possible_agents}
        freed = []
        for i, ev in enumerate(self.occupant):
            if ev is None or ev not in obs:
                continue
            slot = f"slot_{i}"
            out_rew[slot] = float(rewards[ev])
            if terms[ev] or truncs[ev]:
                travel = fleet_infos[ev].get("travel_time")
                infos[slot] = _info(
                    0.0,
                    ended=1.0,
                    charged=float(terms[ev]),
                    travel=math.nan if travel is None else float(travel),
                )
                freed.append(i)
            else:
                out_obs[slot], infos[slot] = obs[ev], _info(1.0)
        seated = set(filter(None, self.occupant))
        self._seat([ev for ev in obs if ev not in seated])  # before the freed slots open
        for i in freed:
            self.occupant[i] = None
        for i, ev in enumerate(self.occupant):
            if ev is not None and ev in obs and ev not in seated:  # joined in this step
                out_obs[f"slot_{i}"], infos[f"slot_{i}"] = obs[ev], _info(1.0)
        over = not self.env.agents
        terminations = dict.fromkeys(self.possible_agents, over)
        truncations = dict.fromkeys(self.possible_agents, False)
        if over:
            self.agents = []
        return out_obs, out_rew, terminations, truncations, infos

    def _seat(self, evs: list[str]) -> None:
        free = [i for i, ev in enumerate(self.occupant) if ev is None]
        if len(evs) > len(free):
            busy = self.slots - len(free)
            raise RuntimeError(
                f"FleetSlots(slots={self.slots}): {len(evs)} guided EVs joined with {busy} "
                f"slots taken; make slots >= {busy + len(evs)}"
            )
        for i, ev in zip(free, evs, strict=False):
            self.occupant[i] = ev

    def close(self) -> None:
        """Close the fleet's simulation."""
        self.env.close()
        self.agents = []


def _info(
    active: float, ended: float = 0.0, charged: float = 0.0, travel: float = math.nan
) -> dict[str, float]:
    return {"active": active, "ended": ended, "charged": charged, "travel_time": travel}
