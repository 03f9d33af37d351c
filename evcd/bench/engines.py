"""The batched engine measured against the single environment: equivalence and throughput.

- :func:`compare_engines`: the travel time of every episode seed under both engines, for greedy and
  for each fixed station, at one or more ``batch_episodes``.
- :func:`engine_rates`, :func:`learning_rate`, :func:`parallel_scaling`: episodes per second of both
  engines on the same seeds, transitions per second of a learning DQN on the engine and the share of
  it spent restarting SUMO to go back in time, the scaling of two engine processes
  (``scripts/bench.py --suite throughput`` runs them on the morning peak and the whole day).
- :func:`kept_routes`: the observer's routes kept on calm roads against found anew at every
  observation (:class:`~evcd.env.observation.RouteObserver`'s ``static_routes``): the rate of each and
  whether every episode is the same.

Every ratio is measured in the same run, side by side. libsumo runs one simulation per process, so
each engine runs in turn (and the scaling test in spawned subprocesses).
"""

from __future__ import annotations

import dataclasses
import logging
import multiprocessing
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from evcd.agents import make_agent_for_env
from evcd.agents.base import Agent
from evcd.agents.dqn import DQNConfig
from evcd.agents.heuristics import FixedStationAgent
from evcd.env import ChargingNavEnv
from evcd.env.runners import BatchedRunner, EpisodeRow, EpisodeRunner, SingleEnvRunner
from evcd.loops.seeds import TRAIN_STREAM, episode_specs

log = logging.getLogger(__name__)

PEAK = (7 * 3600.0, 10 * 3600.0)
WHOLE_DAY = (0.0, 86_400.0)


def _policies(env: ChargingNavEnv) -> dict[str, Callable[[], Agent]]:
    rng = np.random.default_rng(0)
    out: dict[str, Callable[[], Agent]] = {"greedy": lambda: make_agent_for_env("greedy", env, rng)}
    for i in range(len(env.stations)):
        out[f"fixed{i}"] = lambda i=i: FixedStationAgent(len(env.stations), rng, i)
    return out


def _travel(rows: Sequence[EpisodeRow]) -> list[float]:
    return [r.travel_time for r in rows]


def compare_engines(
    env_kwargs: Mapping[str, Any],
    episodes: int,
    batch_sizes: Sequence[int],
    seed: int = 0,
    progress: Callable[[str], None] = log.info,
) -> dict[str, Any]:
    """Per seed and policy, ``T`` under the single environment and under the engine at each batch
    size. Returns the raw travel times, stations, and a summary per policy and batch size."""
    specs = episode_specs(seed, range(episodes))
    env = ChargingNavEnv(**env_kwargs)
    env.prepare()
    policies = _policies(env)
    out: dict[str, Any] = {"episodes": episodes, "seed": seed, "single": {}, "batched": {}, "summary": {}}
    runner: EpisodeRunner = SingleEnvRunner(env)
    for name, make in policies.items():
        t0 = time.perf_counter()
        rows = runner.run(specs, make())
        out["single"][name] = {"T": _travel(rows), "station": [r.station for r in rows],
                               "wall_s": time.perf_counter() - t0}  # fmt: skip
        progress(f"single {name}: {np.mean(_travel(rows)):.1f} s mean over {episodes}")
    env.close()
    for b in batch_sizes:
        runner = BatchedRunner(ChargingNavEnv(**env_kwargs), b)
        for name, make in policies.items():
            t0 = time.perf_counter()
            rows = runner.run(specs, make())
            out["batched"].setdefault(str(b), {})[name] = {
                "T": _travel(rows), "station": [r.station for r in rows], "wall_s": time.perf_counter() - t0,
            }  # fmt: skip
            summary = _difference(out["single"][name], out["batched"][str(b)][name])
            out["summary"].setdefault(str(b), {})[name] = summary
            progress(f"batched (batch {b}) {name}: {summary}")
        runner.close()
    return out


def _difference(single: Mapping[str, Any], batched: Mapping[str, Any]) -> dict[str, float]:
    s, b = np.asarray(single["T"]), np.asarray(batched["T"])
    d = np.abs(b - s)
    return {
        "mean_T_single": float(s.mean()),
        "mean_T_batched": float(b.mean()),
        "mean_abs_dT": float(d.mean()),
        "mean_abs_dT_pct": float(100 * d.mean() / s.mean()),
        "median_abs_dT": float(np.median(d)),
        "p95_abs_dT": float(np.percentile(d, 95)),
        "max_abs_dT": float(d.max()),
        "identical_share": float(np.mean(d == 0)),
        "same_station_share": float(np.mean(np.asarray(single["station"]) == np.asarray(batched["station"]))),
    }


# ---------------------------------------------------------------------------------------- throughput
def _rate(runner: EpisodeRunner, agent: Agent, specs: Sequence[Any], learn: bool = False) -> dict[str, float]:
    t0 = time.perf_counter()
    rows = runner.run(specs, agent, explore=learn, learn=learn)
    wall = time.perf_counter() - t0
    steps = sum(r.steps for r in rows)
    return {"episodes": len(rows), "wall_s": wall, "episodes_per_s": len(rows) / wall,
            "transitions": steps, "transitions_per_s": steps / wall}  # fmt: skip


def engine_rates(
    env_kwargs: Mapping[str, Any], single_episodes: int, batched_episodes: int, batch_episodes: int
) -> dict[str, dict[str, float]]:
    """Greedy episodes per second of both engines on the first seeds of the same stream."""
    env = ChargingNavEnv(**env_kwargs)
    env.prepare()
    agent = make_agent_for_env("greedy", env, np.random.default_rng(0))
    single = _rate(SingleEnvRunner(env), agent, episode_specs(0, range(single_episodes)))
    env.close()
    runner = BatchedRunner(ChargingNavEnv(**env_kwargs), batch_episodes)
    batched = _rate(runner, agent, episode_specs(0, range(batched_episodes)))
    runner.close()
    return {"single": single, "batched": batched}


def kept_routes(env_kwargs: Mapping[str, Any], episodes: int, batch_episodes: int) -> dict[str, Any]:
    """Greedy episodes per second of the batched engine with the observer's routes found anew at every
    observation and kept (the world's default on calm roads), on the same seeds; ``same_rows``: every
    episode's row the same but its wall time."""
    out: dict[str, Any] = {}
    rows: dict[str, list[tuple[Any, ...]]] = {}
    for name, keep in (("found_anew", False), ("kept", True)):
        runner = BatchedRunner(ChargingNavEnv(**env_kwargs), batch_episodes)
        runner.prepare()
        runner.env.observer.static_routes = keep
        agent = make_agent_for_env("greedy", runner.env, np.random.default_rng(0))
        t0 = time.perf_counter()
        played = runner.run(episode_specs(0, range(episodes)), agent, explore=False, learn=False)
        wall = time.perf_counter() - t0
        out[name] = {"episodes": len(played), "wall_s": wall, "episodes_per_s": len(played) / wall}
        rows[name] = [dataclasses.astuple(dataclasses.replace(r, wall_s=0.0)) for r in played]
        runner.close()
    speedup = out["kept"]["episodes_per_s"] / out["found_anew"]["episodes_per_s"]
    return {**out, "speedup": speedup, "same_rows": rows["kept"] == rows["found_anew"]}


def learning_rate(
    env_kwargs: Mapping[str, Any], learner: DQNConfig, episodes: int, batch_episodes: int
) -> dict[str, float]:
    """Transitions per second of a Dueling DDQN with the hyperparameters ``learner`` learning on the
    engine (training episodes), and what going back in time cost: SUMO's restarts before a snapshot
    load to an earlier time (:mod:`evcd.env.simulation`), their count, seconds and share of the wall time."""
    import torch

    torch.set_num_threads(1)
    runner = BatchedRunner(ChargingNavEnv(**env_kwargs), batch_episodes)
    runner.prepare()
    agent = make_agent_for_env("dueling_ddqn", runner.env, np.random.default_rng(0), config=learner)
    out = _rate(runner, agent, episode_specs(0, range(episodes), TRAIN_STREAM), learn=True)
    sim = runner.env.simulation
    runner.close()
    back = {"going_back_restarts": float(sim.back_restarts), "going_back_s": sim.back_restart_s,
            "going_back_share": sim.back_restart_s / out["wall_s"]}  # fmt: skip
    return {**out, "gradient_steps": float(agent.gradient_steps), **back}


def _engine_job(args: tuple[dict[str, Any], int, int, int]) -> dict[str, float]:
    env_kwargs, episodes, batch, stream_seed = args
    env = ChargingNavEnv(**env_kwargs)
    agent = make_agent_for_env("greedy", env, np.random.default_rng(0))
    runner = BatchedRunner(env, batch)
    runner.prepare()
    out = _rate(runner, agent, episode_specs(stream_seed, range(episodes)))
    runner.close()
    return out


def parallel_scaling(env_kwargs: Mapping[str, Any], episodes: int, batch_episodes: int) -> dict[str, float]:
    """Episodes per second with two engine processes (spawned) over one, each its own seeds."""
    ctx = multiprocessing.get_context("spawn")
    jobs = [(dict(env_kwargs), episodes, batch_episodes, s) for s in (0, 1)]
    with ctx.Pool(1) as pool:  # warm: day caches verified, imports done
        pool.map(_engine_job, [(dict(env_kwargs), 1, 1, 9)])
        t0 = time.perf_counter()
        pool.map(_engine_job, jobs[:1])
        one = episodes / (time.perf_counter() - t0)
    with ctx.Pool(2) as pool:
        pool.map(_engine_job, [(dict(env_kwargs), 1, 1, 9)] * 2)
        t0 = time.perf_counter()
        pool.map(_engine_job, jobs)
        two = 2 * episodes / (time.perf_counter() - t0)
    return {"one_process_episodes_per_s": one, "two_processes_episodes_per_s": two, "scaling": two / one}
