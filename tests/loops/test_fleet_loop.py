"""play_fleet: one decide per tick for every agent due, every agent's transitions to observe, with
that agent's own episode state."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from evcd.env.transition import Transition
from evcd.loops.fleet import play_fleet
from evcd.loops.seeds import episode_spec
from tests.env.handmade import ev


@dataclass
class _State:
    rng: np.random.Generator
    steps: list[Transition] = field(default_factory=list)


class Recorder:
    """Sends every EV to cs2 after its first decision (cs1 before), records what it is handed."""

    name = "recorder"

    def __init__(self) -> None:
        self.calls: list[int] = []
        self.states: list[_State] = []

    def new_episode(self, rng: np.random.Generator) -> _State:
        self.states.append(_State(rng))
        return self.states[-1]

    def decide(self, obs: np.ndarray, episodes: list[_State], explore: bool = False) -> np.ndarray:
        assert obs.shape == (len(episodes), 8)
        self.calls.append(len(episodes))
        return np.array([1 if e.steps else 0 for e in episodes])

    def observe(self, transition: Transition, episode: Any = None) -> None:
        episode.steps.append(transition)


def test_every_agent_step_reaches_observe_with_its_own_state(make_small_fleet) -> None:
    north = "A0A1 A1B1 B1C1 C1D1"
    env = make_small_fleet(
        [ev("a", 5, north, "pa_cs1"), ev("b", 6, north, "pa_cs1"), ev("c", 60, "D2C2 C2B2 B2A2", "pa_cs2")]
    )
    agent = Recorder()
    ep = play_fleet(env, agent, episode_spec(0, 0), learn=True)
    assert len(agent.states) == 3 == ep.measures.guided
    assert ep.transitions == sum(agent.calls) == sum(len(s.steps) for s in agent.states)
    assert max(agent.calls) >= 2  # agents due together are decided together
    outcomes = {o["vehicle"]: o for o in env.outcomes()}
    for state, vid in zip(agent.states, ("a", "b", "c"), strict=True):
        steps = state.steps
        assert [t.action for t in steps] == [0] + [1] * (len(steps) - 1)
        assert all(np.array_equal(s.next_obs, t.obs) for s, t in itertools.pairwise(steps))
        assert steps[-1].terminated and not any(t.terminated for t in steps[:-1])
        assert -sum(t.reward for t in steps) * 3600 == pytest.approx(outcomes[vid]["travel_time"])
        assert ep.returns[vid] == pytest.approx(sum(t.reward for t in steps))
    again = Recorder()
    play_fleet(env, again, episode_spec(0, 0), learn=True)
    draws = [s.rng.random() for s in agent.states]
    assert draws == [s.rng.random() for s in again.states]  # each EV's generator comes from the seed
    assert len(set(draws)) == 3
