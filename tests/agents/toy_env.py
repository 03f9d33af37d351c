"""A small deterministic dispatch problem with a known optimal policy (no SUMO).

Three stations. At reset (from the seed) the target is ``D_i`` slots of driving from station ``i``
(1-4) and station ``i`` has a queue that lasts ``Z_i`` slots (0-5). Every slot the target drives
one slot towards the chosen station (and one slot away from each other one), and every queue drains
by one slot. Driving to ``i`` and staying there, the target starts charging after
``max(D_i, Z_i)`` slots; switching only adds driving. So the optimal policy picks
``argmin_i max(D_i, Z_i)`` and keeps it; greedy (``argmin D``) falls into queues.

Observations follow ``ChargingNavEnv``'s layout ``[D, N, Z]`` (``D`` in km: 1 km per slot, ``N``
zero, ``Z`` in slots); the reward is the paper's ``7200 / T_travel`` at the start of charging, and
the final ``info`` carries the keys the episode runners read.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

SLOT_S = 60.0
M = 3


class ToyDispatchEnv(gymnasium.Env):
    """See the module docstring."""

    def __init__(self, max_slots: int = 20) -> None:
        self.action_space = gymnasium.spaces.Discrete(M)
        self.observation_space = gymnasium.spaces.Box(0.0, 100.0, shape=(3 * M,), dtype=np.float32)
        self.max_slots = max_slots
        self.closed = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        self.d = rng.integers(1, 5, size=M).astype(np.int64)
        self.z = rng.integers(0, 6, size=M).astype(np.int64)
        self.t = 0
        self.station: int | None = None
        self.switches = 0
        self.wait = 0
        self.start = (self.d.copy(), self.z.copy())
        return self._obs(), {"departure": 0.0}

    def _obs(self) -> np.ndarray:
        return np.concatenate([self.d, np.zeros(M), self.z]).astype(np.float32)

    def step(self, action: Any):
        a = int(action)
        if self.station is not None and a != self.station:
            self.switches += 1
        self.station = a
        self.t += 1
        if self.d[a] > 0:
            self.d += 1
            self.d[a] -= 2
        else:
            self.wait += 1
        self.z = np.maximum(self.z - 1, 0)
        started = self.d[a] == 0 and self.z[a] == 0
        truncated = not started and self.t >= self.max_slots
        travel = self.t * SLOT_S
        reward = 7200.0 / travel if started else 0.0
        info: dict[str, Any] = {"station": a}
        if started or truncated:
            info |= {"departure": 0.0, "travel_time": travel, "queue_wait": self.wait * SLOT_S,
                     "reason": "charging" if started else "max_travel_time", "switches": self.switches,
                     "station_id": f"s{a}", "day": 0}  # fmt: skip
        return self._obs(), reward, bool(started), bool(truncated), info

    def close(self) -> None:
        self.closed = True


def optimal_travel(seed: int) -> float:
    """The optimal travel time (s) of the episode of ``seed``."""
    env = ToyDispatchEnv()
    env.reset(seed=seed)
    d, z = env.start
    return float(np.maximum(d, z).min() * SLOT_S)


def greedy_travel(seed: int) -> float:
    """Greedy's travel time (s): the nearest station, kept."""
    env = ToyDispatchEnv()
    env.reset(seed=seed)
    d, z = env.start
    i = int(np.argmin(d))
    return float(max(d[i], z[i]) * SLOT_S)
