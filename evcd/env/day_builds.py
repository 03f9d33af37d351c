"""A world's background days built side by side before the first episode needs them.

    built = build_days(config, days=[0, 2, 3], workers=2)     # {day: wall s}, each in a process of its own

A day not cached is simulated once (:class:`~evcd.sim.snapshots.DayCache`, a few minutes on Jurong
West) in a SUMO of its own, and libsumo runs one simulation per process: days built one after the
other leave every other core idle, and so does a sweep whose jobs wait for each other's builds (the
cache's lock lets one process build a day, the others wait). :func:`build_days` starts one process per
day missing (``spawn``: nothing that holds libsumo is forked), ``workers`` at a time, each rebuilding
the world from its :class:`~evcd.env.config.EnvConfig` (the scenario cannot be sent to a process) and
building that day under the cache's lock, so that processes of other runs that need the same day
still build it once. A built day is the same files whichever process built it.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor

from evcd.env.config import EnvConfig

log = logging.getLogger(__name__)


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def build_days(config: EnvConfig, days: Sequence[int], workers: int) -> dict[int, float]:
    """Build the snapshots of each of ``days`` (indices into the world's days) in processes of their
    own, ``workers`` at a time; the wall time of each, by day (a day another process had built or was
    building takes the time it waited)."""
    if not days:
        return {}
    context = multiprocessing.get_context("spawn")
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, min(workers, len(days))), mp_context=context) as pool:
        walls = dict(zip(days, pool.map(_build_day, [config] * len(days), days), strict=True))
    each = ", ".join(f"day {d}: {w:.1f} s" for d, w in walls.items())
    log.info("built %d background days %d at a time in %.1f s (%s)", len(days), min(workers, len(days)),
             time.perf_counter() - t0, each)  # fmt: skip
    return walls


def _build_day(config: EnvConfig, day: int) -> float:
    """In a process of its own: the world of ``config``, its day ``day`` made ready (built if missing)."""
    from evcd.env.world import World

    t0 = time.perf_counter()
    world = World(config)
    try:
        world.simulation.prepare(day)
    finally:
        world.simulation.close()
    return time.perf_counter() - t0
