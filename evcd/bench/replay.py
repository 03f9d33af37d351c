"""Speed of the prioritized replay buffer's hot path: one ``sample`` + ``update_priorities`` round.

A DQN update pays this once per gradient step, so it has to stay small next to the network's own
forward/backward pass; ``python -c "from evcd.bench.replay import time_replay; print(time_replay())"``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from evcd.agents.replay import PrioritizedReplayBuffer


def time_replay(
    capacity: int = 10_000,
    batch_size: int = 32,
    obs_dim: int = 15,
    iterations: int = 2_000,
    seed: int = 0,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, float]:
    """Mean microseconds of ``sample`` and ``update_priorities`` on a full buffer of random transitions.

    The TD errors are drawn before the clock starts, so only the buffer's own work is timed; a few
    untimed rounds first warm the caches. ``clock`` reads the time (seconds).
    """
    rng = np.random.default_rng(seed)
    buffer = PrioritizedReplayBuffer(capacity, obs_dim)
    for _ in range(capacity):
        buffer.add(rng.random(obs_dim), int(rng.integers(4)), float(rng.random()), rng.random(obs_dim),
                   bool(rng.random() < 0.1), bool(rng.random() < 0.05))  # fmt: skip
    buffer.update_priorities(np.arange(capacity), rng.exponential(size=capacity))
    td_errors = rng.standard_normal((iterations, batch_size))
    for row in td_errors[: min(iterations, 20)]:
        buffer.update_priorities(buffer.sample(batch_size, rng, 0.4).indices, row)
    sample_s = update_s = 0.0
    for row in td_errors:
        t0 = clock()
        batch = buffer.sample(batch_size, rng, 0.4)
        t1 = clock()
        buffer.update_priorities(batch.indices, row)
        t2 = clock()
        sample_s += t1 - t0
        update_s += t2 - t1
    sample_us, update_us = 1e6 * sample_s / iterations, 1e6 * update_s / iterations
    return {
        "replay_batch_us": sample_us + update_us,
        # the issues' name for the same figure: sample + priority update of one batch
        "per_sample_update_us": sample_us + update_us,
        "per_transition_us": (sample_us + update_us) / batch_size,
        "replay_sample_us": sample_us,
        "replay_update_us": update_us,
        "capacity": capacity,
        "batch_size": batch_size,
    }
