"""Speed measurements of the environment, taken side by side in one run (machines are noisy).

What it compares with its goals are ratios of times taken in the same run (absolute times vary
from one machine, and one minute, to the next):

- ``episode_speedup_vs_paper``: mean wall time of a ``paper`` episode (a fresh simulation from 00:00
  run on to 23:59) over that of a ``fast`` episode (from the latest day snapshot, stopped at charge
  start), same seeds and policy;
- ``overhead_vs_raw_sumo``: wall time of the ``fast`` episodes over the time the bare ``sumo`` binary
  needs to simulate the same spans from the same snapshots (its own ``Performance: Duration``, which
  excludes loading the network and the state), plus the same ratio without evcd's snapshot load;
- the day-snapshot build time and size.
"""

from __future__ import annotations

import logging
import re
import subprocess
import tempfile
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evcd.agents.heuristics import GreedyAgent
from evcd.env.charging_nav import ChargingNavEnv
from evcd.utils.sumo_tools import binary, tool_env

log = logging.getLogger(__name__)

_DURATION = re.compile(r"Performance:\s*\n\s*Duration:\s*([0-9.]+)\s*(ms|s)")


@dataclass
class EpisodeTiming:
    """One timed episode."""

    seed: int
    protocol: str
    wall_s: float
    departure: float
    travel_time: float
    reason: str
    start_snapshot: float | None = None  # fast: the snapshot the episode started from
    load_s: float = 0.0  # fast: wall time of restoring the snapshot (SUMO state + controller)


@dataclass
class BenchResult:
    """Everything measured; :meth:`summary` gives the ratios."""

    config: dict[str, Any]
    build_s: float = float("nan")
    cache_mb: float = float("nan")
    fast: list[EpisodeTiming] = field(default_factory=list)
    paper: list[EpisodeTiming] = field(default_factory=list)
    raw_sumo_s: list[float] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """Ratios and means (JSON-serialisable)."""
        fast_wall = np.array([e.wall_s for e in self.fast])
        paper_wall = np.array([e.wall_s for e in self.paper])
        loads = np.array([e.load_s for e in self.fast])
        raw = np.array(self.raw_sumo_s)
        seeds = {e.seed: e for e in self.fast}
        diffs = [
            abs(e.travel_time - seeds[e.seed].travel_time)
            for e in self.paper
            if e.seed in seeds and e.reason == "charging" and seeds[e.seed].reason == "charging"
        ]
        out: dict[str, Any] = {
            "episode_speedup_vs_paper": _ratio(paper_wall.mean(), fast_wall[: len(paper_wall)].mean())
            if len(paper_wall)
            else None,
            "overhead_vs_raw_sumo": _ratio(fast_wall.sum(), raw.sum()) if len(raw) else None,
            "overhead_vs_raw_sumo_without_snapshot_load": _ratio((fast_wall - loads).sum(), raw.sum())
            if len(raw)
            else None,
            "fast_episode_mean_s": float(fast_wall.mean()) if len(fast_wall) else None,
            "fast_snapshot_load_mean_s": float(loads.mean()) if len(loads) else None,
            "paper_episode_mean_s": float(paper_wall.mean()) if len(paper_wall) else None,
            "raw_sumo_span_mean_s": float(raw.mean()) if len(raw) else None,
            "snapshot_build_s": self.build_s,
            "snapshot_cache_mb": self.cache_mb,
            "fast_vs_paper_abs_dT_s": {"n": len(diffs), "mean": _mean(diffs), "max": _max(diffs)},
            "goals": {"episode_speedup_vs_paper": ">= 50", "overhead_vs_raw_sumo": "<= 1.2"},
        }
        return out


def _ratio(a: float, b: float) -> float | None:
    return float(a / b) if b > 0 else None


def _mean(x: list[float]) -> float | None:
    return float(np.mean(x)) if x else None


def _max(x: list[float]) -> float | None:
    return float(np.max(x)) if x else None


def time_episode(env: ChargingNavEnv, seed: int) -> EpisodeTiming:
    """Run one greedy episode and time it (reset included: that is where the snapshot is loaded)."""
    sim = env.simulation
    greedy = GreedyAgent(len(env.stations), np.random.default_rng(seed))  # draws nothing
    t0 = wallclock.perf_counter()
    obs, info = env.reset(seed=seed)
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(greedy.act(obs))
        done = terminated or truncated
    wall = wallclock.perf_counter() - t0
    protocol = env.config.protocol
    timing = EpisodeTiming(seed, protocol, wall, info["departure"], info["travel_time"], info["reason"])
    if protocol == "fast":
        timing.start_snapshot = sim.caches[0].latest_before(info["departure"]).time
    return timing


def time_snapshot_loads(env: ChargingNavEnv, times: list[float]) -> dict[float, float]:
    """Wall time of restoring each snapshot (SUMO state + charging queues), loaded in time order.

    Loading only forward in time keeps SUMO's route reader valid (see :mod:`evcd.env.simulation`).
    """
    sim = env.simulation
    cache = sim.caches[0]
    ordered = sorted(set(times))
    sim.start_at(0, ordered[0])  # a fresh start positioned at the first snapshot
    out = {}
    for t in ordered:
        snap = cache.latest_before(t)
        t0 = wallclock.perf_counter()
        cache.load(snap, sim.driver, sim.controller)
        out[t] = wallclock.perf_counter() - t0
    return out


def raw_sumo_span(env: ChargingNavEnv, begin: float, end: float) -> float:
    """Seconds the bare ``sumo`` binary simulates ``[begin, end)`` from the day snapshot at ``begin``.

    SUMO's own ``Performance: Duration`` is used: it excludes loading the network and the state.
    """
    cache = env.simulation.caches[0]
    snap = cache.latest_before(begin)
    sc = env.scenario
    cmd = [
        binary("sumo"), "-n", str(sc.net_file),
        "-a", ",".join(str(p) for p in sc.additional_files),
        "-r", str(cache.routes_file), "--load-state", str(snap.state),
        "--begin", f"{snap.time:g}", "--end", f"{end:g}",
        "--seed", str(cache.spec.sumo_seed), "--step-length", f"{cache.spec.step_length:g}",
        "--time-to-teleport", f"{cache.spec.time_to_teleport:g}",
        "--no-step-log", "--no-warnings", "--duration-log.statistics",
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, env=tool_env())
    if proc.returncode != 0:
        raise RuntimeError(f"sumo failed: {proc.stderr[-2000:]}")
    m = _DURATION.search(proc.stdout + proc.stderr)
    if m is None:
        raise RuntimeError(f"no Performance/Duration in sumo's output:\n{proc.stdout[-2000:]}")
    value = float(m.group(1))
    return value / 1000.0 if m.group(2) == "ms" else value


def run_bench(
    env_kwargs: dict[str, Any],
    fast_episodes: int,
    paper_episodes: int,
    cache_dir: str | Path | None = None,
    paper_day_end: float | None = None,
) -> BenchResult:
    """Measure snapshot build, fast episodes, paper episodes and raw SUMO spans.

    Args:
        env_kwargs: :class:`ChargingNavEnv` arguments shared by both protocols.
        fast_episodes: fast episodes (seeds ``0..n-1``).
        paper_episodes: paper episodes (the first seeds of the fast ones).
        cache_dir: snapshot cache; default a fresh temporary folder, so the build is measured.
        paper_day_end: cut paper episodes there instead of 23:59 (the ``--quick`` mode; its speed-up
            then understates the full protocol's).
    """
    result = BenchResult(
        config={**env_kwargs, "fast_episodes": fast_episodes, "paper_episodes": paper_episodes}
    )
    with tempfile.TemporaryDirectory(prefix="evcd-bench-") as tmp:
        cache = Path(cache_dir) if cache_dir is not None else Path(tmp)
        fast = ChargingNavEnv(**env_kwargs, protocol="fast", cache_dir=cache)
        try:
            t0 = wallclock.perf_counter()
            fast.prepare()
            result.build_s = wallclock.perf_counter() - t0
            result.cache_mb = fast.simulation.caches[0].size_bytes() / 1e6
            log.info("day snapshots: %.1f s, %.1f MB", result.build_s, result.cache_mb)
            for seed in range(fast_episodes):
                e = time_episode(fast, seed)
                result.fast.append(e)
                log.info("fast  seed %d: %.2f s wall, T=%.0f s (%s)", seed, e.wall_s, e.travel_time, e.reason)
            fast.simulation.close()
            loads = time_snapshot_loads(fast, [e.start_snapshot for e in result.fast])
            for e in result.fast:
                e.load_s = loads[e.start_snapshot]
        finally:
            fast.close()
        for e in result.fast:
            result.raw_sumo_s.append(raw_sumo_span(fast, e.start_snapshot, e.departure + e.travel_time))
        extra = {} if paper_day_end is None else {"day_end": paper_day_end}
        paper = ChargingNavEnv(**env_kwargs, protocol="paper", cache_dir=cache, **extra)
        try:
            for seed in range(paper_episodes):
                e = time_episode(paper, seed)
                result.paper.append(e)
                log.info("paper seed %d: %.2f s wall, T=%.0f s (%s)", seed, e.wall_s, e.travel_time, e.reason)
        finally:
            paper.close()
    return result
