"""What a day that is not calm costs to build: the same background day built calm and perturbed, in
turns, each into an empty cache, over the same snapshot times (``scripts/bench.py --suite
perturbed``).

``perturbed_build_ratio`` = the perturbed builds' wall time / the calm builds' (sums over the
repeats, measured alternately in one process). What the events do to the traffic (speeds,
teleports per hour) is what ``scripts/inspect_scenario.py perturbations=...`` reports.
"""

from __future__ import annotations

import logging
import tempfile
import time as wallclock
from collections.abc import Mapping
from typing import Any

from evcd.env.config import EnvConfig
from evcd.sim.driver import SumoDriver
from evcd.sim.snapshots import DayCache, DaySpec

log = logging.getLogger(__name__)

#: Every kind at once, its events inside the README regime's morning peak (07:00-10:00).
PEAK_MIXED: dict[str, Any] = {
    "incidents": {"per_day": 8.0, "start_window": [25200.0, 36000.0]},
    "rain": {"chance": 1.0, "start_window": [25200.0, 30000.0]},
    "outages": {"per_day": 4.0, "start_window": [25200.0, 36000.0]},
    "roadworks": {},
}


def _build(spec: DaySpec, times: list[float]) -> float:
    """Wall seconds of building ``spec``'s snapshots at ``times`` into an empty cache (routes included)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = wallclock.perf_counter()
        DayCache(spec, tmp).ensure(times)
        return wallclock.perf_counter() - t0


def perturbed_build_cost(
    env_kwargs: Mapping[str, Any],
    perturbations: Mapping[str, Any] = PEAK_MIXED,
    repeats: int = 2,
    day: int = 0,
) -> dict[str, Any]:
    """Build day ``day`` of ``env_kwargs``' world calm and with ``perturbations``, ``repeats`` times
    each in turn; return the figures (``perturbed_build_ratio`` and every build)."""
    if SumoDriver.active() is not None:
        raise RuntimeError("the build benchmark needs this process's libsumo: close the running simulation")
    calm_cfg = EnvConfig(**{**env_kwargs, "perturbations": None})
    hit_cfg = EnvConfig(**{**env_kwargs, "perturbations": dict(perturbations)})
    calm, hit = calm_cfg.load()[1][day], hit_cfg.load()[1][day]
    times = calm_cfg.snapshot_times()
    rows: list[dict[str, Any]] = []
    for r in range(repeats):
        for name, spec in (("calm", calm), ("perturbed", hit)):
            row = {"repeat": r, "day": name, "wall_s": round(_build(spec, times), 2)}
            log.info("%s", row)
            rows.append(row)
    total = {k: sum(x["wall_s"] for x in rows if x["day"] == k) for k in ("calm", "perturbed")}
    events = {
        "incidents": len(hit.roads.incidents), "rain": len(hit.roads.rain),
        "roadworks": len(hit.roads.roadworks), "outages": len(hit.outages),
    }  # fmt: skip
    return {
        "perturbed_build_ratio": round(total["perturbed"] / total["calm"], 3),
        "calm_build_s": round(total["calm"] / repeats, 2),
        "perturbed_build_s": round(total["perturbed"] / repeats, 2),
        "snapshot_times": [times[0], times[-1], len(times)],
        "events": events,
        "perturbations": dict(perturbations),
        "builds": rows,
    }
