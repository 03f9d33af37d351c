"""How far the fast protocol's travel times are from the paper protocol's, for the same seeds.

The fast protocol starts each episode from a day snapshot; the paper protocol simulates the day from
00:00. SUMO 1.28 does not restore a saved state bit for bit (the routing engine's averaged edge
speeds, some car-park bookkeeping and floating-point accumulators differ in their last digits), and a
tiny difference can later flip a discrete event (a route choice among near-equal ones, an insertion
one step later), so travel times may differ by a few seconds. :func:`compare_protocols` measures it:

    diff = compare_protocols(n_episodes=20, scenario="sumo_net/jurong_west", evs=400)
    print(diff.summary())        # mean/max |dT|, share of identical episodes

Each protocol runs in turn in this process (libsumo allows one simulation per process).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evcd.agents.heuristics import GreedyAgent
from evcd.env.charging_nav import ChargingNavEnv

log = logging.getLogger(__name__)

#: A policy: ``(observation, stations, seed) -> action``.
Policy = Callable[[np.ndarray, int, int], int]


def fixed_policy(obs: np.ndarray, stations: int, seed: int) -> int:
    """One station drawn from the episode seed, kept all episode (independent of observations, so
    both protocols drive the same way even where their observations differ)."""
    return int(np.random.default_rng([seed, 0xEC]).integers(stations))


def greedy_policy(obs: np.ndarray, stations: int, seed: int) -> int:
    """The station with the smallest ``D`` (the greedy rule, :class:`~evcd.agents.heuristics.GreedyAgent`)."""
    return GreedyAgent(stations, np.random.default_rng(seed)).act(obs)


POLICIES: dict[str, Policy] = {"fixed": fixed_policy, "greedy": greedy_policy}


@dataclass
class ProtocolDifference:
    """Travel times (s) of the same episodes under both protocols (``nan``: did not charge)."""

    seeds: list[int]
    fast: list[float] = field(default_factory=list)
    paper: list[float] = field(default_factory=list)
    fast_reasons: list[str] = field(default_factory=list)
    paper_reasons: list[str] = field(default_factory=list)

    @property
    def abs_diff(self) -> np.ndarray:
        """``|T_fast - T_paper|`` per episode where both charged."""
        f, p = np.asarray(self.fast, dtype=float), np.asarray(self.paper, dtype=float)
        both = ~(np.isnan(f) | np.isnan(p))
        return np.abs(f[both] - p[both])

    def summary(self) -> dict[str, Any]:
        """Mean/max ``|dT|``, the share of identical travel times, and outcome mismatches."""
        d = self.abs_diff
        return {
            "episodes": len(self.seeds),
            "compared": int(d.size),
            "mean_abs_dt_s": float(d.mean()) if d.size else float("nan"),
            "max_abs_dt_s": float(d.max()) if d.size else float("nan"),
            "identical_share": float((d == 0).mean()) if d.size else float("nan"),
            "mean_t_fast_s": float(np.nanmean(self.fast)) if self.fast else float("nan"),
            "reason_mismatches": sum(
                a != b for a, b in zip(self.fast_reasons, self.paper_reasons, strict=True)
            ),
        }


def run_episode(env: Any, seed: int, policy: Policy) -> tuple[float, str]:
    """One episode with ``policy``; its travel time (``nan`` unless charged) and end reason."""
    obs, _ = env.reset(seed=seed)
    m = int(env.action_space.n)
    while True:
        obs, _, terminated, truncated, info = env.step(policy(obs, m, seed))
        if terminated or truncated:
            travel = float(info["travel_time"]) if info["charged"] else float("nan")
            return travel, str(info["reason"])


def compare_protocols(
    n_episodes: int = 10,
    seeds: Sequence[int] | None = None,
    policy: str | Policy = "fixed",
    **env_kwargs: Any,
) -> ProtocolDifference:
    """Run the same episodes under ``protocol="fast"`` and ``"paper"``; return both travel times.

    Args:
        n_episodes: episodes (seeds ``0..n-1``) unless ``seeds`` is given.
        seeds: the episode seeds.
        policy: ``"fixed"``, ``"greedy"`` (see :data:`POLICIES`) or a callable.
        env_kwargs: :class:`~evcd.env.ChargingNavEnv` arguments (``protocol`` is set here).
    """
    fn = POLICIES[policy] if isinstance(policy, str) else policy
    seeds = list(range(n_episodes)) if seeds is None else [int(s) for s in seeds]
    result = ProtocolDifference(seeds)
    for protocol, times, reasons in (
        ("fast", result.fast, result.fast_reasons),
        ("paper", result.paper, result.paper_reasons),
    ):
        env = ChargingNavEnv(**{**env_kwargs, "protocol": protocol})
        try:
            for seed in seeds:
                travel, reason = run_episode(env, seed, fn)
                times.append(travel)
                reasons.append(reason)
        finally:
            env.close()
    log.info("fast vs paper over %d episodes: %s", len(seeds), result.summary())
    return result
