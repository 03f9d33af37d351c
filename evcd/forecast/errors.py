"""How far a forecaster is off: mean absolute error per station and hour of the day, on played days.

rows = forecast_errors(make_forecaster("trend"), test_days, window=(6 * 3600.0, 10 * 3600.0))
print(format_mae_table(rows))
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from evcd.forecast.forecasters import Forecaster
from evcd.forecast.timeline import OccupancyTimeline
from evcd.utils.validation import check_real, require


def forecast_errors(
    forecaster: Forecaster,
    days: Sequence[OccupancyTimeline],
    window: tuple[float, float],
    horizons_s: Sequence[float] = (300.0, 600.0, 900.0, 1200.0),
    every_s: float = 60.0,
) -> list[dict[str, Any]]:
    """Mean absolute error of ``forecaster`` per station and hour of the decision time.

    For each day, each decision time ``t = window[0] + i * every_s < window[1]`` and each horizon
    ``h`` with ``t + h <= day.known_until``, the forecast at ``now = t`` for an arrival at ``t + h`` at
    every station is compared with the truth ``day.at(t + h)``. The forecaster is given the day as known
    at ``t`` (:meth:`OccupancyTimeline.truncated`), so that it cannot read the future even by mistake.

    Returns:
        Rows ``{"station": id, "hour": int(t // 3600), "mae": float, "n": int}``, the error averaged
        over the days, decision times and horizons of that station and hour (``n`` of them), sorted by
        station id then hour; no rows when no ``(t, h)`` fits in the days.

    Raises:
        ValueError: no days, days with other stations, an empty window, ``every_s`` <= 0, no horizons
            or a negative one.
    """
    days = list(days)
    require(bool(days), "forecast_errors needs at least one day; none were given")
    stations = days[0].stations
    for day in days:
        require(
            day.stations == stations,
            f"days with stations {list(day.stations)} and {list(stations)}: all days need the same stations",
        )
    lo, hi = (check_real(f"window[{i}]", w) for i, w in enumerate(window))
    require(lo < hi, f"window={tuple(window)}: must be (start, end) with start < end")
    every_s = check_real("every_s", every_s, low=0.0, low_open=True)
    horizons = np.array(
        [check_real(f"horizons_s[{i}]", h, low=0.0) for i, h in enumerate(horizons_s)], dtype=np.float64
    )
    require(horizons.size > 0, "horizons_s=(): need at least one horizon")
    m = len(stations)
    times = lo + every_s * np.arange(math.ceil((hi - lo) / every_s))
    times = times[times < hi]
    first_hour = int(lo // 3600)
    n_hours = int(times[-1] // 3600) - first_hour + 1  # times[0] == lo: the window holds one at least
    abs_sum = np.zeros((n_hours, m))
    count = np.zeros(n_hours, dtype=np.int64)
    for day in days:
        for t in times:
            arrive = t + horizons[t + horizons <= day.known_until]
            if arrive.size == 0:
                continue
            arrival = np.repeat(arrive[:, None], m, axis=1)
            guess = forecaster.forecast(float(t), arrival, day.truncated(float(t)))
            truth = day.at(arrive)
            hour = int(t // 3600) - first_hour
            abs_sum[hour] += np.abs(guess - truth).sum(axis=0)
            count[hour] += arrive.size
    rows = [
        {
            "station": sid,
            "hour": first_hour + int(h),
            "mae": float(abs_sum[h, j] / count[h]),
            "n": int(count[h]),
        }
        for j, sid in enumerate(stations)
        for h in np.flatnonzero(count)
    ]
    return sorted(rows, key=lambda r: (r["station"], r["hour"]))


def format_mae_table(rows: Sequence[Mapping[str, Any]], digits: int = 2) -> str:
    """``rows`` of :func:`forecast_errors` as a plain text table: a row per station, a column per hour
    (``HH``), each cell the MAE (``-`` where there is none).

    Raises:
        ValueError: a row without ``station``, ``hour`` or ``mae``.
    """
    for row in rows:
        missing = [k for k in ("station", "hour", "mae") if k not in row]
        require(not missing, f"row {dict(row)!r} lacks {missing}: rows come from forecast_errors")
    if not rows:
        return "no forecast errors (no rows)"
    hours = sorted({int(r["hour"]) for r in rows})
    stations = sorted({str(r["station"]) for r in rows})
    cells = {(str(r["station"]), int(r["hour"])): f"{float(r['mae']):.{digits}f}" for r in rows}
    table = [["station", *(f"{h:02d}" for h in hours)]]
    table += [[sid, *(cells.get((sid, h), "-") for h in hours)] for sid in stations]
    widths = [max(len(line[i]) for line in table) for i in range(len(table[0]))]
    lines = [
        "  ".join(
            cell.ljust(w) if i == 0 else cell.rjust(w)
            for i, (cell, w) in enumerate(zip(line, widths, strict=True))
        )
        for line in table
    ]
    return "\n".join(line.rstrip() for line in lines)
