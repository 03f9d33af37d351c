"""The agent interface, the registry and the rule-based dispatchers (pure: no SUMO)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from evcd.agents import Agent, Transition, agent_class, agent_names, make_agent, make_agent_for_env
from evcd.agents.heuristics import GreedyAgent, QueueAwareAgent, RandomAgent
from evcd.env.observation import D_SCALE_M, N_SCALE


def obs_of(d, n=None, z=None) -> np.ndarray:
    d = np.asarray(d, dtype=np.float64)
    n = np.zeros_like(d) if n is None else np.asarray(n, dtype=np.float64)
    z = np.zeros_like(d) if z is None else np.asarray(z, dtype=np.float64)
    return np.concatenate([d, n, z]).astype(np.float32)


def normalized(obs: np.ndarray, points) -> np.ndarray:
    """The env's normalisation (evcd.env.observation.RouteObserver.vector), applied to a raw vector."""
    d, n, z = np.split(obs.astype(np.float64), 3)
    return np.concatenate([d / D_SCALE_M, n / N_SCALE, z / np.asarray(points, float)]).astype(np.float32)


def random_obs(rng: np.random.Generator, m: int) -> np.ndarray:
    return obs_of(rng.uniform(0, 5000, m), rng.integers(0, 40, m), rng.integers(0, 6, m))


# ---------------------------------------------------------------------------------------- registry
def test_registry_builds_every_agent_by_name():
    for name in agent_names("single"):
        agent = make_agent(name, 4, np.random.default_rng(0))
        assert isinstance(agent, Agent) and agent.name == name and agent.n_stations == 4
        assert agent_class(name) is type(agent)
    assert {"random", "greedy", "queue_aware"} <= set(agent_names("single"))


def test_unknown_agent_is_named_with_the_known_ones():
    with pytest.raises(ValueError, match=r"'dqnn'.*random, greedy"):
        make_agent("dqnn", 3, np.random.default_rng(0))


def test_unknown_option_is_named():
    with pytest.raises(ValueError, match=r"greedy.*\['speed'\]"):
        make_agent("greedy", 3, np.random.default_rng(0), speed=3)
    with pytest.raises(ValueError, match="charge_s"):
        make_agent("queue_aware", 3, np.random.default_rng(0), charge_s=-1.0)


@pytest.mark.parametrize("n", [0, -1, 2.5, True, "3"])
def test_bad_station_count(n):
    with pytest.raises(ValueError, match="n_stations"):
        make_agent("greedy", n, np.random.default_rng(0))


def test_the_global_generator_is_refused():
    with pytest.raises(ValueError, match="rng"):
        make_agent("random", 3, np.random)  # type: ignore[arg-type]


def test_make_agent_for_env_reads_points_and_scaling():
    stations = [SimpleNamespace(points=p) for p in (2, 3, 1)]
    env = SimpleNamespace(action_space=SimpleNamespace(n=3), stations=stations,
                          config=SimpleNamespace(normalize_obs=True))  # fmt: skip
    env.unwrapped = env
    agent = make_agent_for_env("queue_aware", env, np.random.default_rng(0), charge_s=600.0)
    assert isinstance(agent, QueueAwareAgent)
    assert agent.points.tolist() == [2, 3, 1] and agent.normalized and agent.charge_s == 600.0
    assert make_agent_for_env("greedy", env, np.random.default_rng(0)).n_stations == 3


def test_heuristics_ignore_the_learning_hook():
    agent = make_agent("greedy", 2, np.random.default_rng(0))
    obs = obs_of([10.0, 5.0])
    agent.observe(Transition(obs, 1, 0.0, obs, False, False))
    assert agent.act(obs) == 1


@pytest.mark.parametrize("name", ["random", "greedy", "queue_aware"])
def test_wrong_observation_size_is_an_error(name):
    agent = make_agent(name, 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"expected \(9,\)"):
        agent.act(np.zeros(6, dtype=np.float32))


# ---------------------------------------------------------------------------------------- random
def first_choice(seed: int, m: int) -> int:
    agent = RandomAgent(m, np.random.default_rng(seed))
    agent.begin_episode()
    return agent.act(obs_of(np.arange(m) * 100.0))


def test_random_is_uniform_over_seeds():
    m, seeds = 5, 5000
    counts = np.bincount([first_choice(s, m) for s in range(seeds)], minlength=m)
    expected = seeds / m
    chi2 = float(((counts - expected) ** 2 / expected).sum())
    assert chi2 < 18.47, (counts, chi2)  # chi-square, 4 degrees of freedom, p = 0.001


def test_random_is_uniform_over_episodes_of_one_generator():
    m, episodes = 4, 4000
    agent = RandomAgent(m, np.random.default_rng(123))
    picks = []
    for _ in range(episodes):
        agent.begin_episode()
        picks.append(agent.act(obs_of(np.ones(m))))
    counts = np.bincount(picks, minlength=m)
    chi2 = float(((counts - episodes / m) ** 2 / (episodes / m)).sum())
    assert chi2 < 16.27, (counts, chi2)  # 3 degrees of freedom, p = 0.001


def test_random_keeps_its_first_choice_for_the_whole_episode():
    rng = np.random.default_rng(7)
    agent = RandomAgent(5, np.random.default_rng(0))
    for _ in range(50):
        agent.begin_episode()
        first = agent.act(random_obs(rng, 5))
        assert all(agent.act(random_obs(rng, 5), explore=True) == first for _ in range(20))


def test_random_draws_again_each_episode_and_follows_the_episode_generator():
    agent = RandomAgent(5, np.random.default_rng(0))
    picks = set()
    for _ in range(40):
        agent.begin_episode()
        picks.add(agent.act(obs_of(np.ones(5))))
    assert len(picks) == 5
    # a generator handed to begin_episode decides, whatever the agent drew before
    a, b = RandomAgent(5, np.random.default_rng(1)), RandomAgent(5, np.random.default_rng(2))
    a.begin_episode(np.random.default_rng(99))
    b.begin_episode(np.random.default_rng(99))
    assert a.act(obs_of(np.ones(5))) == b.act(obs_of(np.ones(5)))


def test_random_never_touches_the_global_generator():
    np.random.seed(5)
    before = np.random.get_state()[1].copy()
    first_choice(0, 5)
    assert (np.random.get_state()[1] == before).all()


# ---------------------------------------------------------------------------------------- greedy
def test_greedy_is_argmin_distance_whatever_the_traffic():
    rng = np.random.default_rng(0)
    agent = GreedyAgent(5, np.random.default_rng(0))
    for _ in range(200):
        obs = random_obs(rng, 5)
        assert agent.act(obs) == int(np.argmin(obs[:5]))
    # the nearest station wins even with a jammed route and a long queue
    assert agent.act(obs_of([900.0, 1000.0, 5000.0, 3000.0, 2000.0], [80, 0, 0, 0, 0], [9, 0, 0, 0, 0])) == 0


def test_greedy_is_the_same_on_normalised_observations():
    rng = np.random.default_rng(1)
    points = [2, 3, 1, 2, 2]
    agent = GreedyAgent(5, np.random.default_rng(0))
    for _ in range(200):
        obs = random_obs(rng, 5)
        assert agent.act(normalized(obs, points)) == agent.act(obs) == int(np.argmin(obs[:5]))


def test_greedy_ties_go_to_the_lowest_index_and_unreachable_loses():
    agent = GreedyAgent(3, np.random.default_rng(0))
    assert agent.act(obs_of([700.0, 700.0, 700.0])) == 0
    assert agent.act(obs_of([1.0e6, 2500.0, 1.0e6])) == 1  # D of an unreachable station is 1e6 m
    assert agent.act(obs_of([300.0, 0.0, 10.0])) == 1  # 0 = the target waits in that car park


# ---------------------------------------------------------------------------------------- queue-aware
def test_queue_aware_without_queues_picks_the_quickest_drive():
    agent = QueueAwareAgent(3, np.random.default_rng(0), points=2, speed_mps=10.0, vehicle_delay_s=2.0)
    obs = obs_of([1000.0, 1200.0, 3000.0], [40, 0, 0], [1, 0, 0])
    assert agent.estimate(obs).tolist() == pytest.approx([180.0, 120.0, 300.0])
    assert agent.act(obs) == 1


def test_queue_aware_avoids_a_long_queue():
    agent = QueueAwareAgent(2, np.random.default_rng(0), points=2, charge_s=1200.0)
    # near station: 2 charging + 3 waiting -> backlog 4 departures x 600 s; far one is empty
    obs = obs_of([500.0, 4000.0], [0, 0], [5, 0])
    assert agent.estimate(obs).tolist() == pytest.approx([2400.0, 400.0])
    assert agent.act(obs) == 1
    # a queue that drains while the target drives there costs nothing
    assert agent.estimate(obs_of([9000.0, 4000.0], [0, 0], [2, 0]))[0] == pytest.approx(900.0)


def test_queue_aware_does_not_count_the_target_in_its_own_queue():
    agent = QueueAwareAgent(2, np.random.default_rng(0), points=1, charge_s=1000.0)
    # the target waits at station 0 (D = 0) with one car charging: Z = 2 counts itself
    assert agent.estimate(obs_of([0.0, 2000.0], [0, 0], [2, 0]))[0] == pytest.approx(1000.0)


def test_queue_aware_is_the_same_on_normalised_observations():
    rng = np.random.default_rng(2)
    points = [2, 3, 1, 2]
    raw = QueueAwareAgent(4, np.random.default_rng(0), points=points)
    scaled = QueueAwareAgent(4, np.random.default_rng(0), points=points, normalized=True)
    for _ in range(200):
        obs = random_obs(rng, 4)
        np.testing.assert_allclose(scaled.estimate(normalized(obs, points)), raw.estimate(obs), rtol=1e-5)
        assert scaled.act(normalized(obs, points)) == raw.act(obs)


@pytest.mark.parametrize(
    "kwargs,needle",
    [({"points": 0}, "points"), ({"points": [2, 2]}, "points"), ({"points": 1.5}, "points"),
     ({"speed_mps": 0.0}, "speed_mps"), ({"vehicle_delay_s": -1.0}, "vehicle_delay_s")],
)  # fmt: skip
def test_queue_aware_bad_values(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        QueueAwareAgent(3, np.random.default_rng(0), **kwargs)
