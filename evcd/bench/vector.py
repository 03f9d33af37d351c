"""The sweep vector environment (:mod:`evcd.env.sweep`) against the single environment, in one run:
how fast, and what its one decision clock changes.

    report = sweep_benchmark(env_kwargs, num_envs=16, steps=200, single_episodes=20, rule="queue_aware")

- **Speed**: a rule's decisions per second through :class:`~evcd.env.sweep.SweepVectorEnv` (every
  sub-environment one decision per step), through the single environment and through
  :func:`~evcd.env.make_vector_env` with 2 processes, measured one after the other in this run
  (libsumo: one simulation per process), each after its days are built.
- **Equivalence**: every episode the sweep finished by the episode's own rules (not cut by the
  window's end) is replayed in the single environment (same day, departure, origin and position,
  the same rule); the paired travel times say what co-simulated targets and the shared clock change.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from evcd.agents import make_agent_for_env
from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.sweep import WINDOW_END, SweepEpisode, SweepVectorEnv
from evcd.env.vector import make_vector_env
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)


def play_sweeps(env: ChargingNavEnv, num_envs: int, steps: int, seed: int, rule: str) -> dict[str, Any]:
    """``steps`` vector steps of ``rule`` on ``num_envs`` slots: the episodes, decisions and wall time
    (the first sweep's start, which may build days, excluded)."""
    vec = SweepVectorEnv(env, num_envs)
    wall = _time_rule(vec, env, steps, seed, rule)
    return {"episodes": list(vec.episodes), "decisions": steps * num_envs, "wall_s": wall,
            "sweeps": vec.sweeps}  # fmt: skip


def _time_rule(envs: Any, world: ChargingNavEnv, steps: int, seed: int, rule: str) -> float:
    """Seconds ``rule`` (made for ``world``) takes for ``steps`` steps of the vector env ``envs``
    after its reset; ``envs`` is closed."""
    agent = make_agent_for_env(rule, world, np.random.default_rng(seed))
    states = [agent.new_episode(np.random.default_rng(seed)) for _ in range(envs.num_envs)]
    try:
        obs, _ = envs.reset(seed=seed)
        t0 = time.perf_counter()
        for _ in range(steps):
            obs, *_ = envs.step(agent.decide(obs, states))
        return time.perf_counter() - t0
    finally:
        envs.close()


def replay_single(env: ChargingNavEnv, episodes: list[SweepEpisode], seed: int, rule: str) -> list[float]:
    """Each episode played alone in the single environment with ``rule``: its travel time (NaN if
    it did not charge)."""
    agent = make_agent_for_env(rule, env, np.random.default_rng(seed))
    times = []
    try:
        for ep in episodes:
            obs, info = env.reset(seed=seed, options=ep.replay_options())
            agent.begin_episode(np.random.default_rng(seed))
            done = terminated = False
            while not done:
                obs, _, terminated, truncated, info = env.step(agent.act(obs))
                done = terminated or truncated
            times.append(float(info["travel_time"]) if terminated else math.nan)
    finally:
        env.close()
    return times


def single_rate(env: ChargingNavEnv, episodes: int, seed: int, rule: str) -> dict[str, float]:
    """The single environment's decisions per second with ``rule`` over ``episodes`` episodes."""
    agent = make_agent_for_env(rule, env, np.random.default_rng(seed))
    env.prepare()
    decisions, t0 = 0, time.perf_counter()
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            agent.begin_episode()
            done = False
            while not done:
                obs, _, terminated, truncated, _ = env.step(agent.act(obs))
                decisions += 1
                done = terminated or truncated
    finally:
        env.close()
    wall = time.perf_counter() - t0
    return {"decisions": decisions, "wall_s": wall, "decisions_per_s": decisions / wall}


def async_rate(
    env_kwargs: Mapping[str, Any], num_envs: int, steps: int, seed: int, rule: str
) -> dict[str, float]:
    """:func:`~evcd.env.make_vector_env` (``num_envs`` spawned processes, one SUMO each): a rule's
    decisions per second over ``steps`` vector steps (the workers' start excluded)."""
    envs = make_vector_env(num_envs, **env_kwargs)
    wall = _time_rule(envs, ChargingNavEnv(**env_kwargs), steps, seed, rule)
    return {"decisions": steps * num_envs, "wall_s": wall, "decisions_per_s": steps * num_envs / wall}


def sweep_benchmark(
    env_kwargs: Mapping[str, Any], num_envs: int, steps: int, single_episodes: int, seed: int = 0,
    rule: str = "queue_aware", replay: int = 60,
) -> dict[str, Any]:  # fmt: skip
    """Speed and equivalence of the sweep vector environment (module docstring); ``replay``: at most
    this many of its episodes are replayed alone."""
    for key, value, low in (("num_envs", num_envs, 1), ("steps", steps, 1),
                            ("single_episodes", single_episodes, 1), ("replay", replay, 0)):  # fmt: skip
        check_int(key, value, minimum=low)
    swept = play_sweeps(ChargingNavEnv(**env_kwargs), num_envs, steps, seed, rule)
    single = single_rate(ChargingNavEnv(**env_kwargs), single_episodes, seed, rule)
    two = async_rate(env_kwargs, 2, max(1, single["decisions"] // 2), seed, rule)
    ended = [e for e in swept["episodes"] if e.row.reason != WINDOW_END]
    chosen = ended[:replay]
    alone = replay_single(ChargingNavEnv(**env_kwargs), chosen, seed, rule)
    pairs = [(e.row.travel_time, t) for e, t in zip(chosen, alone, strict=True)
             if not e.row.truncated and math.isfinite(t)]  # fmt: skip
    diff = np.array([a - b for a, b in pairs])
    rate = swept["decisions"] / swept["wall_s"]
    return {
        "rule": rule,
        "num_envs": num_envs,
        "steps": steps,
        "sweep": {
            "decisions": swept["decisions"],
            "wall_s": swept["wall_s"],
            "decisions_per_s": rate,
            "sweeps": swept["sweeps"],
            "episodes": len(swept["episodes"]),
            "cut_at_window_end": len(swept["episodes"]) - len(ended),
        },
        "single": single,
        "make_vector_env_2": two,
        "speedup": rate / single["decisions_per_s"],
        "speedup_vs_make_vector_env_2": rate / two["decisions_per_s"],
        "equivalence": {
            "replayed": len(chosen),
            "pairs": len(pairs),
            "identical": int((np.abs(diff) < 1e-9).sum()) if diff.size else 0,
            "mean_difference_s": float(diff.mean()) if diff.size else math.nan,
            "mean_abs_difference_s": float(np.abs(diff).mean()) if diff.size else math.nan,
            "max_abs_difference_s": float(np.abs(diff).max()) if diff.size else math.nan,
            "sweep_mean_s": float(np.mean([a for a, _ in pairs])) if pairs else math.nan,
            "single_mean_s": float(np.mean([b for _, b in pairs])) if pairs else math.nan,
        },
    }
