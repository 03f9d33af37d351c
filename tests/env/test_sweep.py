"""The sweep vector environment (evcd.env.sweep) on the grid, real SUMO: Gymnasium's vector
conventions (spaces, SAME_STEP autoreset, infos), one seed one result, bad actions refused without
touching the sweep, the window's end, and its episodes against the single environment's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.bench.vector import play_sweeps, replay_single
from evcd.env.sweep import WINDOW_END, SweepVectorEnv
from evcd.sim.driver import SumoDriver

#: The grid's world with the time reward and normalised observations (what an outside learner gets).
WORLD = {"reward": "time", "normalize_obs": True}


def _rule(env, vec, name="queue_aware"):
    agent = make_agent_for_env(name, env, np.random.default_rng(0))
    states = [agent.new_episode(np.random.default_rng(0)) for _ in range(vec.num_envs)]
    return lambda obs: agent.decide(obs, states)


def _play(vec, policy, steps):
    obs, _ = vec.reset(seed=3)
    out = []
    for _ in range(steps):
        obs, rewards, terminated, truncated, infos = vec.step(policy(obs))
        out.append((obs.copy(), rewards.copy(), terminated.copy(), truncated.copy(), infos))
    return out


@pytest.mark.slow
def test_vector_conventions_and_same_step_autoreset(make_env) -> None:
    env = make_env(**WORLD)
    vec = SweepVectorEnv(env, 4)
    assert vec.single_action_space == env.action_space and vec.action_space.shape == (4,)
    assert vec.observation_space.shape == (4, 9) and vec.metadata["autoreset_mode"].name == "SAME_STEP"
    try:
        obs, infos = vec.reset(seed=3)
        assert obs in vec.observation_space and obs.dtype == np.float32 and (obs[:, :3] > 0).all()
        policy, ended = _rule(env, vec), 0
        for _ in range(40):
            obs, rewards, terminated, truncated, infos = vec.step(policy(obs))
            assert obs in vec.observation_space and rewards.dtype == np.float64
            assert (rewards <= 0).all() and (rewards >= -1 / 60 - 1e-9).all()  # minus hours per slot
            done = terminated | truncated
            assert not (terminated & truncated).any()
            if done.any():  # the step's observation is the new episode's; the last one is in infos
                assert (infos["_final_obs"] == done).all() and (infos["final_info"]["_reason"] == done).all()
                assert (infos["final_obs"][done][:, :3] >= 0).all()
                ended += int(done.sum())
            else:
                assert infos == {}
        assert ended == len(vec.episodes) > 10
        for ep in vec.episodes:
            assert ep.row.reason == "charging" or ep.row.truncated
            assert ep.row.day in env.config.demand_seeds and ep.plan.departure == ep.row.departure
    finally:
        vec.close()
    assert SumoDriver.active() is None


@pytest.mark.slow
def test_one_seed_one_sweep(make_env) -> None:
    runs = []
    for _ in range(2):
        env = make_env(**WORLD)
        vec = SweepVectorEnv(env, 3)
        try:
            steps = _play(vec, _rule(env, vec), 25)
        finally:
            vec.close()
        runs.append(([s[:4] for s in steps], [e.row for e in vec.episodes]))
    (a, rows_a), (b, rows_b) = runs
    for x, y in zip(a, b, strict=True):
        for u, v in zip(x, y, strict=True):
            np.testing.assert_array_equal(u, v)
    assert [dict(r.row(), wall_s=0) for r in rows_a] == [dict(r.row(), wall_s=0) for r in rows_b]


def test_bad_actions_are_refused_by_sub_environment_and_change_nothing(make_env) -> None:
    env = make_env(**WORLD)
    vec = SweepVectorEnv(env, 3)
    try:
        vec.reset(seed=3)
        bad = [([0, 1], r"actions of shape \(2,\): need \(3,\)"),
               ([0, 7, 1], r"actions\[1\]=7: must be a station index in \[0, 3\) \(sub-environment 1\)"),
               ([0, 1.5, 1], r"actions\[1\]=1.5"), ([-1, 0, 0], r"actions\[0\]=-1")]  # fmt: skip
        for actions, needle in bad:
            with pytest.raises(ValueError, match=needle):
                vec.step(np.array(actions))
        after = vec.step(np.array([0, 1, 2]))
    finally:
        vec.close()
    fresh_env = make_env(**WORLD)
    fresh = SweepVectorEnv(fresh_env, 3)
    try:
        fresh.reset(seed=3)
        again = fresh.step(np.array([0, 1, 2]))
    finally:
        fresh.close()
    np.testing.assert_array_equal(after[0], again[0])
    np.testing.assert_array_equal(after[1], again[1])
    with pytest.raises(ValueError, match="num_envs=0"):
        SweepVectorEnv(make_env(**WORLD), 0)
    with pytest.raises(ValueError, match="protocol='paper'"):
        SweepVectorEnv(make_env(protocol="paper"), 2)


@pytest.mark.slow
def test_the_window_end_truncates_every_running_episode_and_a_new_sweep_starts(make_env) -> None:
    env = make_env(**WORLD)
    lo, hi = env.config.departure_window
    vec = SweepVectorEnv(env, 3)
    try:
        obs, _ = vec.reset(seed=3)
        policy = _rule(env, vec)
        times = []
        for _ in range(int((hi - lo) // env.config.decision_interval) + 3):
            obs, _, terminated, truncated, infos = vec.step(policy(obs))
            times.append(vec._sweep.sim.time)
            if vec.sweeps == 2:
                break
        assert vec.sweeps == 2 and times[-1] < lo + 10  # the new sweep is back at the window's start
        assert (terminated | truncated).all()
        cut = [e for e in vec.episodes if e.row.reason == WINDOW_END]
        assert cut and all(e.row.truncated for e in cut)
        assert WINDOW_END in set(infos["final_info"]["reason"])
        assert all(lo <= e.plan.departure < hi for e in vec.episodes)
    finally:
        vec.close()


@pytest.mark.slow
@pytest.mark.parametrize("num_envs", [1, 4])
def test_sweep_episodes_replayed_alone_in_the_single_environment(make_env, num_envs) -> None:
    """What the one clock and the co-simulated targets change: a rule's travel times of the sweep's
    episodes against the same episodes (day, departure, origin) alone in the single environment,
    within the batched engine's own bound (2 % of the mean travel time, tests/env/test_batched.py)
    plus the second by which a target's charge start is seen later alone."""
    swept = play_sweeps(make_env(**WORLD), num_envs, 50, 3, "queue_aware")
    episodes = [e for e in swept["episodes"] if e.row.reason == "charging"][:30]
    alone = replay_single(make_env(**WORLD), episodes, 3, "queue_aware")
    pairs = np.array([(e.row.travel_time, t) for e, t in zip(episodes, alone, strict=True)
                      if math.isfinite(t)])  # fmt: skip
    assert len(pairs) >= 20
    diff = np.abs(pairs[:, 0] - pairs[:, 1])
    assert diff.mean() <= 0.02 * pairs[:, 1].mean() + 1.0, diff


@pytest.mark.slow
def test_stable_baselines3_learns_through_the_adapter(make_env) -> None:
    from stable_baselines3 import PPO

    from evcd.experiments.sb3 import SB3VecEnv

    venv = SB3VecEnv(SweepVectorEnv(make_env(**WORLD), 4))
    try:
        venv.seed(5)
        obs = venv.reset()
        assert obs.shape == (4, 9) and venv.num_envs == 4
        venv.step_async(np.zeros(4, dtype=np.int64))
        _, rewards, dones, infos = venv.step_wait()
        assert rewards.dtype == np.float32 and len(infos) == 4
        for done, info in zip(dones, infos, strict=True):
            assert ("terminal_observation" in info) == bool(done)
        model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=2, seed=0, verbose=0)
        model.learn(total_timesteps=128)
        assert model.num_timesteps >= 128 and venv.venv.episodes
        assert venv.get_attr("num_envs") == [4] * 4 and venv.env_is_wrapped(object) == [False] * 4
    finally:
        venv.close()


@pytest.mark.slow
def test_only_the_latest_episodes_are_kept(make_env) -> None:
    env = make_env(**WORLD)
    vec = SweepVectorEnv(env, 3, keep_episodes=5)
    try:
        _play(vec, _rule(env, vec), 30)
        assert len(vec.episodes) == 5
    finally:
        vec.close()
    with pytest.raises(ValueError, match="keep_episodes=-1"):
        SweepVectorEnv(make_env(**WORLD), 2, keep_episodes=-1)


def test_a_sumo_failure_while_targets_enter_ends_the_episodes_in_flight_and_starts_a_sweep(
    make_env, monkeypatch
) -> None:
    from evcd.env import sweep as sweep_module
    from evcd.sim.driver import SUMO_ERRORS

    env = make_env(**WORLD)
    vec = SweepVectorEnv(env, 3)
    real = sweep_module._Sweep.run_to
    armed = [False]

    def failing(self, until):
        if armed[0] and until - self.sim.time <= env.config.step_length + 1e-9:  # the refill step
            armed[0] = False
            raise SUMO_ERRORS[0]("planted failure")
        return real(self, until)

    monkeypatch.setattr(sweep_module._Sweep, "run_to", failing)
    try:
        obs, _ = vec.reset(seed=3)
        policy = _rule(env, vec)
        armed[0] = True
        for _ in range(30):
            before = vec.sweeps
            obs, _, terminated, truncated, infos = vec.step(policy(obs))
            if vec.sweeps > before:
                break
        assert not armed[0] and vec.sweeps == 2
        assert (terminated | truncated).all()  # the ended ones and those the failure cut
        assert "sumo_error" in set(infos["final_info"]["reason"]) and obs in vec.observation_space
    finally:
        vec.close()
