"""DQN and Dueling Double DQN learn: on a small deterministic dispatch problem whose optimal policy is
known (:mod:`tests.agents.toy_env`, no SUMO), both reach it within a fixed budget of training
episodes, judged on held-out evaluation episodes against the optimal and the greedy travel times;
an untrained agent does not pass the same bar. Both networks: the MLP and the one shared by the stations."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.agents import make_agent
from evcd.env.runners import SingleEnvRunner
from evcd.loops.seeds import TRAIN_STREAM, episode_specs
from tests.agents.toy_env import M, ToyDispatchEnv, greedy_travel, optimal_travel

# Measured over seeds 0-7 (1500 training episodes, 300 held-out ones): DQN and Dueling DDQN each at
# the optimal travel time in 97-99 % of the held-out episodes, the mean 0.1-1.4 % above the optimum,
# no truncation. With gamma 0.9, reward_scale 0.01 and the MSE loss the greedy policy of DQN sometimes
# zig-zags until the time limit and the optimal share drops to 85-92 %: too close to the bar.
SETTINGS = {
    "hidden": (64, 64),
    "lr": 1e-3,
    "batch_size": 32,
    "buffer_size": 5000,
    "gamma": 0.8,
    "learning_starts": 200,
    "target_update": 200,
    "exploration_steps": 2000,
    "beta_steps": 4000,
    "reward_scale": 0.1,
    "loss": "huber",
}
TRAIN_EPISODES = 1500
EVAL_EPISODES = 300
SEED = 0

# the bar: share of held-out episodes at the optimal travel time, and the mean's excess over the optimum
MIN_OPTIMAL_SHARE = 0.85
MAX_MEAN_EXCESS = 0.06


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _train_and_evaluate(name: str, seed: int, train_episodes: int, network: str = "mlp") -> dict:
    agent = make_agent(name, M, np.random.default_rng(seed), network=network, **SETTINGS)
    runner = SingleEnvRunner(ToyDispatchEnv())
    train = episode_specs(seed, range(train_episodes), TRAIN_STREAM)
    runner.run(train, agent, explore=True, learn=True)
    held_out = episode_specs(seed, range(EVAL_EPISODES))  # the evaluation stream: unseen episodes
    assert not {s.reset_seed for s in train} & {s.reset_seed for s in held_out}
    rows = runner.run(held_out, agent, explore=False, learn=False)
    travel = np.array([r.travel_time for r in rows])
    optimal = np.array([optimal_travel(r.seed) for r in rows])
    greedy = np.array([greedy_travel(r.seed) for r in rows])
    assert (travel >= optimal).all()  # the toy's optimum is a true lower bound
    return {
        "agent": agent,
        "optimal_share": float(np.mean(travel == optimal)),
        "mean": float(travel.mean()),
        "optimal_mean": float(optimal.mean()),
        "greedy_mean": float(greedy.mean()),
        "truncated": sum(r.truncated for r in rows),
    }


def _missed(result: dict) -> list[str]:
    """The criteria of the bar ``result`` misses (none: it passes)."""
    criteria = {
        f"optimal in >= {MIN_OPTIMAL_SHARE:.0%} of the episodes": (
            result["optimal_share"] >= MIN_OPTIMAL_SHARE
        ),
        f"mean within {MAX_MEAN_EXCESS:.0%} of the optimum": result["mean"]
        <= (1 + MAX_MEAN_EXCESS) * result["optimal_mean"],
        "no truncation": result["truncated"] == 0,
        "faster than greedy": result["mean"] < result["greedy_mean"],
    }
    return [name for name, met in criteria.items() if not met]


@pytest.mark.slow
@pytest.mark.parametrize("network", ["mlp", "station"])
@pytest.mark.parametrize("name", ["dqn", "dueling_ddqn"])
def test_agent_learns_the_optimal_dispatch(name, network):
    result = _train_and_evaluate(name, SEED, TRAIN_EPISODES, network)
    agent = result["agent"]
    assert agent.gradient_steps > 1000
    assert agent.target_updates == agent.gradient_steps // SETTINGS["target_update"]
    assert agent.epsilon == agent.config.epsilon_end
    assert not _missed(result), {k: v for k, v in result.items() if k != "agent"}


@pytest.mark.parametrize("network", ["mlp", "station"])
@pytest.mark.parametrize("name", ["dqn", "dueling_ddqn"])
def test_untrained_agent_does_not_pass(name, network):
    """The same bar with no training: the test above is not passed by construction."""
    result = _train_and_evaluate(name, SEED, 0, network)
    assert result["agent"].gradient_steps == 0
    assert f"optimal in >= {MIN_OPTIMAL_SHARE:.0%} of the episodes" in _missed(result), (
        {k: v for k, v in result.items() if k != "agent"})  # fmt: skip
