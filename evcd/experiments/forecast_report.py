"""How well each forecaster predicts the vehicles at a station when an EV would get there, on an
experiment's held-out days (``scripts/forecast_errors.py``).

For every evaluation day (its snapshots built over the departure window), every decision time in
the window (each ``every_s``) and every horizon (5-20 min by default), each forecaster's forecast of
the vehicles at each station at the time plus the horizon is compared with what the day's records
say happened: the mean absolute error by station and hour (:func:`evcd.forecast.forecast_errors`).
The history, anomaly and sessions forecasters learn from the training days only; the trend reads
each day up to the decision time; the oracle reads the day itself (its error is 0 where the records
reach: a check, not a forecaster one could run). The reference ``now`` is no forecast at all: the
vehicles there at the decision time (what ``queue_aware`` reads, the trend over a window of 0 s).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from evcd.env.config import EnvConfig
from evcd.env.forecast_source import day_timeline
from evcd.forecast import FORECASTERS, OccupancyTimeline, forecast_errors, make_forecaster
from evcd.sim.snapshots import DayCache


def day_timelines(kwargs: Mapping[str, Any]) -> list[OccupancyTimeline]:
    """The occupancy timelines of the days of an environment's arguments ``kwargs`` (built where
    missing; for the fleet's, its background days as cached, every EV driving to its own choice)."""
    skip = ("observe", "forecaster", "forecast_days", "guided_share")
    config = EnvConfig(**{k: v for k, v in kwargs.items() if k not in skip})
    scenario, days = config.load()
    times = config.snapshot_times()
    ids = [st.id for st in scenario.stations]
    return [day_timeline(DayCache(spec, config.cache_dir), times, ids) for spec in days]


def forecaster_errors(
    train: Sequence[OccupancyTimeline],
    held_out: Sequence[OccupancyTimeline],
    window: tuple[float, float],
    names: Sequence[str] = ("history", "trend", "anomaly", "sessions", "oracle"),
    horizons_s: Sequence[float] = (300.0, 600.0, 900.0, 1200.0),
    every_s: float = 60.0,
    settings: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """Per forecaster name, the rows ``{station, hour, mae, n}`` on the ``held_out`` days (each made
    with its ``settings[name]``, else its defaults; those that learn fitted on ``train``; the oracle
    made for each day in turn, its rows pooled), and under ``now`` the reference of the vehicles there
    at the decision time."""
    now = make_forecaster("trend", window_s=0.0)
    out: dict[str, list[dict[str, Any]]] = {
        "now": forecast_errors(now, held_out, window, horizons_s, every_s)
    }
    for name in names:
        if name == "oracle":
            per_day = [forecast_errors(make_forecaster("oracle", day=d), [d], window, horizons_s, every_s)
                       for d in held_out]  # fmt: skip
            out[name] = pool_rows([r for rows in per_day for r in rows])
        else:
            days = train if FORECASTERS[name].needs_days else ()
            forecaster = make_forecaster(name, days, **(settings or {}).get(name, {}))
            out[name] = forecast_errors(forecaster, held_out, window, horizons_s, every_s)
    return out


def pool_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows of the same station and hour merged: their MAE weighted by their counts."""
    pooled: dict[tuple[str, int], list[float]] = {}
    for r in rows:
        total = pooled.setdefault((r["station"], r["hour"]), [0.0, 0.0])
        total[0] += r["mae"] * r["n"]
        total[1] += r["n"]
    return [{"station": s, "hour": h, "mae": t / n if n else 0.0, "n": int(n)}
            for (s, h), (t, n) in sorted(pooled.items())]  # fmt: skip


def overall(rows: Sequence[Mapping[str, Any]]) -> float:
    """The MAE over every row (weighted by their counts)."""
    n = sum(r["n"] for r in rows)
    return sum(r["mae"] * r["n"] for r in rows) / n if n else float("nan")
