"""FleetRunner: one decide per tick for every agent due, every agent's transitions to observe, with
that agent's own episode state."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from evcd.env.runners.fleet import FleetRunner
from evcd.env.transition import Transition
from evcd.loops.fleet import fleet_spec
from evcd.loops.seeds import TRAIN_STREAM, VALIDATION_STREAM, days_of_seed, episode_spec, episode_specs
from tests.env.handmade import ev


@dataclass
class _State:
    rng: np.random.Generator
    steps: list[Transition] = field(default_factory=list)
    ended: int = 0


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
        assert not episode.ended
        episode.steps.append(transition)

    def end_episode(self, episode: Any = None) -> None:
        episode.ended += 1


def test_every_agent_step_reaches_observe_with_its_own_state(make_small_fleet) -> None:
    north = "A0A1 A1B1 B1C1 C1D1"
    env = make_small_fleet(
        [ev("a", 5, north, "pa_cs1"), ev("b", 6, north, "pa_cs1"), ev("c", 60, "D2C2 C2B2 B2A2", "pa_cs2")]
    )
    agent = Recorder()
    ep = FleetRunner(env).episode(episode_spec(0, 0), agent, learn=True)
    assert len(agent.states) == 3 == ep.measures.guided
    assert ep.transitions == sum(agent.calls) == sum(len(s.steps) for s in agent.states)
    assert max(agent.calls) >= 2  # agents due together are decided together
    outcomes = {o["vehicle"]: o for o in env.outcomes()}
    assert ep.measures.switches == pytest.approx(np.mean([o["switches"] for o in outcomes.values()]))
    assert ep.measures.switches > 0  # every EV was sent from cs1 to cs2
    for state, vid in zip(agent.states, ("a", "b", "c"), strict=True):
        steps = state.steps
        assert [t.action for t in steps] == [0] + [1] * (len(steps) - 1)
        assert all(np.array_equal(s.next_obs, t.obs) for s, t in itertools.pairwise(steps))
        assert steps[-1].terminated and not any(t.terminated for t in steps[:-1])
        assert state.ended == 1  # each EV's end, once, after its last step
        assert -sum(t.reward for t in steps) * 3600 == pytest.approx(outcomes[vid]["travel_time"])
        assert ep.returns[vid] == pytest.approx(sum(t.reward for t in steps))
    again = Recorder()
    FleetRunner(env).episode(episode_spec(0, 0), again, learn=True)
    draws = [s.rng.random() for s in agent.states]
    assert draws == [s.rng.random() for s in again.states]  # each EV's generator comes from the seed
    assert len(set(draws)) == 3


# ---------------------------------------------------------------------------------------- learning
#: Two EVs from the east towards cs2 (1 point, near); cs1 (2 points) is a detour of ~400 m. The
#: second departs while the first still drives to cs2: both at cs2 costs the second a whole charge
#: (~150 s), sending it to cs1 costs ~35 s. Ticks every 10 s.
TWO_EVS = [ev("a", 5, "D2C2 C2B2 B2A2", "pa_cs2"), ev("b", 20, "D2C2 C2B2 B2A2", "pa_cs2")]


class Assign:
    """A fixed assignment of the two EVs (the enumeration of the known optimum)."""

    name = "assign"

    def __init__(self, stations: dict[str, int]) -> None:
        self.stations, self.order = stations, list(stations)
        self.seen = 0

    def new_episode(self, rng: np.random.Generator) -> str:
        self.seen += 1
        return self.order[self.seen - 1]

    def decide(self, obs: np.ndarray, episodes: list[str], explore: bool = False) -> np.ndarray:
        return np.array([self.stations[e] for e in episodes])

    def observe(self, *args: Any) -> None:
        return None

    def end_episode(self, *args: Any) -> None:
        return None


#: The learners of the best-split test, with settings that learn it in its budget.
SPLIT_LEARNERS = {
    "dueling_ddqn": {"hidden": (32, 32), "lr": 3e-3, "batch_size": 32, "gamma": 0.9, "learning_starts": 50,
                     "target_update": 100, "exploration_steps": 600, "reward_scale": 10.0, "loss": "huber"},
    "ppo": {"hidden": (32, 32), "network": "mlp", "lr": 3e-3, "rollout_steps": 64, "minibatch_size": 32,
            "epochs": 4, "gamma": 0.9, "reward_scale": 600.0, "entropy_coef": 0.01},
}  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("learner", ["dueling_ddqn", "ppo"])
def test_the_shared_learner_finds_the_best_split_of_two_evs(
    make_small_fleet, one_torch_thread, learner: str
) -> None:
    from evcd.agents import make_agent_for_env
    from evcd.agents.dqn import DQNConfig

    env = make_small_fleet(TWO_EVS, max_travel_time=900.0)
    totals = {}
    for a, b in itertools.product((0, 1), repeat=2):
        ep = FleetRunner(env).episode(episode_spec(0, 0), Assign({"a": a, "b": b}))
        assert ep.measures.guided_charged == 2
        totals[(a, b)] = ep.measures.guided_travel * 2
    best = min(totals.values())
    assert totals[(1, 1)] - best > 60  # herding at the one-point station is costly
    rule = make_agent_for_env("greedy", env, np.random.default_rng(0))
    greedy = FleetRunner(env).episode(episode_spec(0, 0), rule)
    assert greedy.measures.guided_travel * 2 == pytest.approx(totals[(1, 1)])  # nearest by road: it herds
    settings = SPLIT_LEARNERS[learner]
    if learner == "ppo":
        agent = make_agent_for_env("ppo", env, np.random.default_rng(0), **settings)
    else:
        config = DQNConfig(**settings)
        agent = make_agent_for_env(learner, env, np.random.default_rng(0), config=config)
    assert agent.layout == "DNZH" and len(env.stations) == 2
    specs = episode_specs(0, range(100), TRAIN_STREAM)
    played = FleetRunner(env).run(specs, agent, explore=True, learn=True)  # ~800 agent steps
    # every agent step reached the learner
    assert agent.steps == sum(ep.transitions for ep in played)
    if learner == "ppo":
        assert agent.stats()["updates"] >= 10 and agent.stats()["episodes"] == 2 * len(played)
    else:
        assert len(agent.replay) == agent.steps
    learned = FleetRunner(env).episode(episode_spec(0, 0), agent)
    assert learned.measures.guided_travel * 2 == pytest.approx(best)


def test_evaluation_and_validation_episodes_take_the_days_in_turn() -> None:
    specs = [fleet_spec(5, i, 3, VALIDATION_STREAM) for i in range(7)]
    assert [s.options for s in specs] == [{"day": i % 3} for i in range(7)]
    # the seeds are the episode's own: only the day is fixed
    plain = episode_spec(5, 4, VALIDATION_STREAM)
    assert specs[4].reset_seed == plain.reset_seed and specs[4].index == 4
    assert specs[4].agent_rng().integers(1 << 30) == plain.agent_rng().integers(1 << 30)
    with pytest.raises(ValueError, match="days=0"):
        fleet_spec(5, 0, 0)


@pytest.mark.parametrize(
    "seed,count,expected",
    [
        (0, 1, (101,)),
        (4, 1, (105,)),  # one day per seed: days[seed mod n], as eval.day_per_seed always did
        (6, 1, (102,)),
        (0, 2, (101, 102)),
        (1, 2, (103, 104)),
        (2, 2, (105, 101)),  # a block that wraps round
        (0, 7, (101, 102, 103, 104, 105)),  # more episodes than days: each day once
    ],
)
def test_each_seed_has_its_own_block_of_days(seed: int, count: int, expected: tuple[int, ...]) -> None:
    assert days_of_seed([101, 102, 103, 104, 105], seed, count) == expected


def test_blocks_of_different_seeds_share_no_day_while_days_last() -> None:
    days = list(range(106, 131))
    blocks = [set(days_of_seed(days, s, 5)) for s in range(5)]
    assert set().union(*blocks) == set(days) and sum(map(len, blocks)) == 25
    with pytest.raises(ValueError, match="count=0"):
        days_of_seed(days, 0, 0)
