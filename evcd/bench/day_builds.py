"""What building a world's days side by side saves (:mod:`evcd.env.day_builds`), measured in one run.

The same days of the same world are built twice from empty caches: one after the other in this
process's own way (``workers=1``), then side by side (``workers`` processes). The figure is the
ratio of the two wall times (>1: side by side is faster), measured back to back so that both meet the
same machine.
"""

from __future__ import annotations

import logging
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from evcd.env.charging_nav import ChargingNavEnv

log = logging.getLogger(__name__)


def day_build_speedup(env_kwargs: Mapping[str, Any], workers: int = 2) -> dict[str, Any]:
    """Build every day of the world of ``env_kwargs`` (a :class:`~evcd.env.ChargingNavEnv`'s arguments,
    ``cache_dir`` left out) one after the other, then ``workers`` at a time, each into a fresh cache.

    Raises:
        ValueError: ``workers`` < 2, or a world of one day (nothing to build side by side).
    """
    if workers < 2:
        raise ValueError(f"workers={workers}: side by side needs at least 2")
    walls = {}
    with tempfile.TemporaryDirectory(prefix="evcd_days_") as tmp:
        for name, n in (("one_by_one_s", 1), ("side_by_side_s", workers)):
            env = ChargingNavEnv(**env_kwargs, cache_dir=Path(tmp) / name)
            if len(env.days) < 2:
                env.close()
                raise ValueError(f"a world of {len(env.days)} day has nothing to build side by side")
            with env:
                t0 = time.perf_counter()
                env.prepare(workers=n)
                walls[name] = time.perf_counter() - t0
            log.info("%d days built %d at a time: %.1f s", len(env.days), n, walls[name])
    return {**walls, "days": len(env.days), "workers": workers,
            "day_build_speedup": walls["one_by_one_s"] / walls["side_by_side_s"]}  # fmt: skip
