"""The batched engine against the single environment, on real SUMO (small generated networks)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import libsumo
import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.agents.base import Agent, EpisodeState
from evcd.agents.dqn import DQNAgent
from evcd.agents.heuristics import FixedStationAgent as Fixed
from evcd.env.runners import BatchedRunner, EpisodeSpec, SingleEnvRunner
from evcd.loops.seeds import episode_specs
from evcd.sim.driver import SumoDriver
from tests.env.handmade import TO_CS2, car, ev

CS1, CS2 = 0, 1
NEAR_CS2 = {"departure": 100, "origin": "D2C2", "depart_pos": 20.0}


@dataclass
class Seen(EpisodeState):
    """The observations of one episode of :class:`Recorder`."""

    observations: list[np.ndarray] = field(default_factory=list)


class Recorder(Agent):
    """``plan(slot)`` gives the station of each slot; records every observation of each episode."""

    name = "recorder"

    def __init__(self, n_stations: int, plan: Any) -> None:
        self.seen: list[list[np.ndarray]] = []
        super().__init__(n_stations, np.random.default_rng(0))
        self.seen.clear()  # the construction's own episode is not one
        self.plan = plan

    def new_episode(self, rng: np.random.Generator) -> Seen:
        episode = Seen(rng)
        self.seen.append(episode.observations)
        return episode

    def decide(self, obs: np.ndarray, episodes: Sequence[Seen], explore: bool = False) -> np.ndarray:
        actions = []
        for o, episode in zip(obs, episodes, strict=True):
            episode.observations.append(np.asarray(o).copy())
            actions.append(int(self.plan(len(episode.observations) - 1)))
        return np.array(actions, dtype=np.int64)


def specs_with(options: list[dict[str, Any]]) -> list[EpisodeSpec]:
    return [EpisodeSpec(i, 1000 + i, np.random.SeedSequence(i), options=opt) for i, opt in enumerate(options)]


def both(make, agent_factory, specs, batch_episodes=8, **env_kwargs):
    """Rows of the single environment and of the engine, and the engine."""
    env = make(**env_kwargs)
    single = SingleEnvRunner(env).run(specs, agent_factory(env))
    env.close()
    runner = BatchedRunner(make(**env_kwargs), batch_episodes)
    batched = runner.run(specs, agent_factory(runner.env))
    return single, batched, runner


# ------------------------------------------------------------------------------- plans and equivalence
@pytest.mark.slow
def test_engines_play_the_same_episode_plans(make_env):
    specs = episode_specs(3, range(12))
    env = make_env(demand_seeds=(0, 1))
    plans = BatchedRunner(env).plan(specs)
    for spec, (day, plan) in zip(specs, plans, strict=True):
        _, info = env.reset(seed=spec.reset_seed)
        assert (info["day"], info["departure"], info["origin"]) == (
            env.days[day].demand_seed,
            plan.departure,
            plan.origin,
        )
    assert len({day for day, _ in plans}) == 2  # both days drawn
    batches = BatchedRunner(env, batch_episodes=4).batches_of(specs)
    assert sorted(i for b in batches for i in b) == list(range(12)) and max(map(len, batches)) <= 4
    for batch in batches:  # one day per batch, by departure
        assert len({plans[i][0] for i in batch}) == 1
        assert [plans[i][1].departure for i in batch] == sorted(plans[i][1].departure for i in batch)


@pytest.mark.slow
@pytest.mark.parametrize("policy", ["greedy", 0, 1, 2])
def test_batched_engine_matches_single_environment_per_seed(make_env, policy):
    specs = episode_specs(0, range(40))

    def agent(env):
        if policy == "greedy":
            return make_agent_for_env("greedy", env, np.random.default_rng(0))
        return Fixed(3, np.random.default_rng(0), policy)

    single, batched, runner = both(make_env, agent, specs, batch_episodes=20)
    runner.close()
    assert runner.batches >= 2
    for s, b in zip(single, batched, strict=True):
        assert (s.episode, s.seed, s.departure, s.origin, s.day) == (
            b.episode,
            b.seed,
            b.departure,
            b.origin,
            b.day,
        )
    t_single = np.array([r.travel_time for r in single])
    diff = np.abs(np.array([r.travel_time for r in batched]) - t_single)
    assert diff.mean() <= 0.02 * t_single.mean(), diff
    same = np.mean([s.station == b.station for s, b in zip(single, batched, strict=True)])
    assert same >= 0.95
    assert sum(r.reason == "charging" for r in batched) >= 0.9 * len(specs)


# ------------------------------------------------------------------------------- ghost queues
def queue_at_cs2(k: int, hold_last: bool = False) -> list[str]:
    """``k`` EVs reaching cs2 (1 point) one after another before t=100, each charging for minutes."""
    return [
        ev(f"bg{i}", 5 * i, TO_CS2, "pa_cs2", soc=0.1, target=0.3, hold=hold_last and i == k - 1)
        for i in range(k)
    ]


@pytest.mark.parametrize("k", [1, 3])
def test_target_behind_background_evs_starts_when_the_single_target_would(make_small_env, k):
    specs = specs_with([NEAR_CS2])
    single, batched, runner = both(make_small_env, lambda env: Fixed(2, np.random.default_rng(0), CS2), specs,
                                   vehicles=queue_at_cs2(k))  # fmt: skip
    s, b = single[0], batched[0]
    assert s.reason == b.reason == "charging" and s.station_id == b.station_id == "cs2"
    assert s.queue_wait > 0  # it really waited behind the k EVs
    assert (b.travel_time, b.queue_wait) == (s.travel_time, s.queue_wait)
    ctrl = runner.env.simulation.controller
    assert not any(r.vehicle.startswith("evcd_batch") for r in ctrl.records)  # never in the queue
    runner.close()


def test_two_targets_at_one_station_each_see_only_the_background(make_small_env):
    options = [NEAR_CS2, {**NEAR_CS2, "departure": 110}]
    specs = specs_with(options)
    per_engine = []
    for engine in ("single", "batched"):
        env = make_small_env(queue_at_cs2(2))
        agent = Recorder(2, lambda slot: CS2)
        runner = SingleEnvRunner(env) if engine == "single" else BatchedRunner(env, batch_episodes=2)
        rows = runner.run(specs, agent)
        runner.close()
        per_engine.append((rows, agent.seen))
    (single, seen_single), (batched, seen_batched) = per_engine
    assert [r.travel_time for r in batched] == [r.travel_time for r in single]  # as if each were alone
    assert [r.queue_wait for r in batched] == [r.queue_wait for r in single] and min(
        r.queue_wait for r in batched
    ) > 0
    for obs_s, obs_b in zip(seen_single, seen_batched, strict=True):
        assert len(obs_s) == len(obs_b)
        z_s = [o[2 * 2 + CS2] for o in obs_s]
        z_b = [o[2 * 2 + CS2] for o in obs_b]
        assert (
            z_b == z_s
        )  # Z at cs2: the background (and the target itself once it waits), never the other target
        assert max(z_b) == 3


def test_target_leaves_a_queue_for_another_station(make_small_env):
    blocker = [ev("blocker", 0, TO_CS2, "pa_cs2", soc=0.1, target=0.5, hold=True)]

    def plan(slot):
        return CS2 if slot < 5 else CS1

    out = []
    for engine in ("single", "batched"):
        env = make_small_env(blocker)
        runner = SingleEnvRunner(env) if engine == "single" else BatchedRunner(env, batch_episodes=1)
        out.append(runner.run(specs_with([NEAR_CS2]), Recorder(2, plan))[0])
        runner.close()
    single, batched = out
    assert batched.reason == "charging" and batched.station_id == "cs1" and batched.switches == 1
    assert batched.queue_wait > 0
    assert abs(batched.travel_time - single.travel_time) <= 5  # re-entering the road vs leaving the car park


def test_target_that_cannot_be_inserted_departs_elsewhere(make_small_env):
    wall = car("wall", 0, "A1B1 B1C1", stop='<stop lane="A1B1_0" endPos="30" duration="100000"/>')
    specs = specs_with([{"departure": 100, "origin": "A1B1", "depart_pos": 28.0}])
    single, batched, runner = both(make_small_env, lambda env: Fixed(2, np.random.default_rng(0), CS1), specs,
                                   vehicles=[wall], max_insert_delay=30, time_to_teleport=-1)  # fmt: skip
    runner.close()
    assert batched[0].origin == single[0].origin != "A1B1"
    assert batched[0].departure == single[0].departure >= 130


# ------------------------------------------------------------------------- learning, determinism, errors
def tiny_dqn(env) -> DQNAgent:
    return DQNAgent.from_env(env, np.random.default_rng(7), hidden=[16], learning_starts=5, batch_size=4,
                             buffer_size=100, exploration_steps=50, double=True, dueling=True)  # fmt: skip


@pytest.mark.slow
def test_batched_learning_is_deterministic(make_env):
    specs = episode_specs(5, range(16))
    results = []
    for _ in range(2):
        runner = BatchedRunner(make_env(), batch_episodes=8)
        agent = tiny_dqn(runner.env)
        seen = []
        agent_observe = agent.observe

        def observe(t, episode=None, agent_observe=agent_observe, seen=seen):
            seen.append((t.action, t.reward, t.terminated, t.truncated, t.obs.tobytes()))
            agent_observe(t, episode)

        agent.observe = observe  # type: ignore[method-assign]
        rows = runner.run(specs, agent, explore=True, learn=True)
        runner.close()
        weights = [p.detach().clone() for p in agent.policy.online.parameters()]
        results.append((rows, seen, weights, agent.gradient_steps))
    (rows_a, seen_a, w_a, g_a), (rows_b, seen_b, w_b, g_b) = results
    assert [dataclass_no_wall(r) for r in rows_a] == [dataclass_no_wall(r) for r in rows_b]
    assert seen_a == seen_b and g_a == g_b > 0
    assert sum(r.steps for r in rows_a) == len(seen_a)
    assert all(np.array_equal(a, b) for a, b in zip(w_a, w_b, strict=True))


def dataclass_no_wall(row):
    return {k: v for k, v in row.__dict__.items() if k != "wall_s"}


def test_decide_on_many_episodes_equals_act_on_each(make_env):
    env = make_env()
    for exploration in ("slot", "episode"):
        agents = [
            DQNAgent.from_env(env, np.random.default_rng(1), hidden=[8], exploration=exploration)
            for _ in range(2)
        ]
        obs = np.random.default_rng(2).uniform(0, 3000, size=(6, 9)).astype(np.float32)
        states = [agents[0].new_episode(np.random.default_rng(100 + i)) for i in range(6)]
        batched = agents[0].decide(obs, states, explore=True)
        one_by_one = []
        for i in range(6):
            agents[1].begin_episode(np.random.default_rng(100 + i))
            one_by_one.append(agents[1].act(obs[i], explore=True))
        assert batched.tolist() == one_by_one


@pytest.mark.slow
def test_sumo_failure_truncates_the_batch_in_flight_and_the_next_batch_runs(make_env, monkeypatch):
    specs = episode_specs(1, range(12))
    runner = BatchedRunner(make_env(), batch_episodes=6)
    batches = runner.batches_of(specs)
    calls = {"n": 0}
    real_step = SumoDriver.step

    def failing_step(self, until=None):
        calls["n"] += 1
        if calls["n"] == 400:  # once, in the middle of the first batch
            raise libsumo.TraCIException("simulated SUMO failure")
        return real_step(self, until)

    monkeypatch.setattr(SumoDriver, "step", failing_step)
    greedy = make_agent_for_env("greedy", runner.env, np.random.default_rng(0))
    rows = runner.run(specs, greedy)
    runner.close()
    failed = [r for r in rows if r.reason == "sumo_error"]
    assert failed and runner.sumo_errors == 1
    assert {r.episode for r in failed} <= set(batches[0])
    assert all(r.reason == "charging" for r in rows if r.episode in batches[1])


@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "8"])
def test_bad_batch_size_is_refused(make_env, bad):
    with pytest.raises(ValueError, match="batch_episodes"):
        BatchedRunner(make_env(), bad)


# ------------------------------------------------------------------------- learning from true transitions
@dataclass
class Heard(EpisodeState):
    """What :class:`Listener` was handed of one episode: its transitions, then its end."""

    steps: list[Any] = field(default_factory=list)
    ended: int = 0
    decisions: int = 0


class Listener(Agent):
    """Drives to the nearest station and records every ``observe`` and ``end_episode`` of each episode."""

    name = "listener"
    learns = True

    def __init__(self) -> None:
        self.heard: list[Heard] = []
        super().__init__(2, np.random.default_rng(0))
        self.heard.clear()  # the state act() would use

    def new_episode(self, rng: np.random.Generator) -> Heard:
        self.heard.append(Heard(rng))
        return self.heard[-1]

    def decide(self, obs: np.ndarray, episodes: Sequence[Heard], explore: bool = False) -> np.ndarray:
        for e in episodes:
            assert not e.ended  # no decision after the end
            e.decisions += 1
        return np.asarray(obs)[:, :2].argmin(axis=1)

    def observe(self, transition: Any, episode: Any = None) -> None:
        assert not episode.ended  # every transition comes before the end
        episode.steps.append(transition)

    def end_episode(self, episode: Any = None) -> None:
        episode.ended += 1


STOPPED_ON_B1C1 = car("wall", 0, "A1B1 B1C1 C1D1", stop='<stop lane="B1C1_0" endPos="40" duration="100000"/>')


@pytest.mark.parametrize("engine", ["single", "batched"])
def test_an_aborted_episode_hands_learners_only_true_transitions(make_small_env, engine):
    """A target that teleports (stuck behind a stopped car) can no longer be observed: its last slot
    reaches no learner (its next observation would be the one before the slot), its episode still
    ends with ``end_episode``; an episode that ends charging hands over every slot, the last one
    terminated. Both engines hand over the same transitions."""
    specs = specs_with([{"departure": 100, "origin": "A1B1", "depart_pos": 20.0}, NEAR_CS2])
    env = make_small_env([STOPPED_ON_B1C1], time_to_teleport=45, stuck_limit=600)
    runner = SingleEnvRunner(env) if engine == "single" else BatchedRunner(env, batch_episodes=2)
    agent = Listener()
    rows = runner.run(specs, agent, learn=True)
    runner.close()
    assert [r.reason for r in rows] == ["teleported", "charging"]
    aborted, charged = sorted(agent.heard, key=lambda h: len(h.steps) == h.decisions)
    assert aborted.ended == charged.ended == 1
    assert len(aborted.steps) == aborted.decisions - 1 >= 1  # the teleported slot is not handed over
    assert not any(t.terminated or t.truncated for t in aborted.steps)
    for steps in (aborted.steps, charged.steps):
        assert all(np.array_equal(a.next_obs, b.obs) for a, b in itertools.pairwise(steps))
    assert len(charged.steps) == charged.decisions and charged.steps[-1].terminated
    assert sum(t.reward for t in charged.steps) == pytest.approx(rows[1].episode_return)
