"""Every forecaster by name, the settings each takes, and :func:`make_forecaster`.

forecaster = make_forecaster("sessions", training_days=past_days, history_weight=0.5)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from evcd.forecast.forecasters import (
    AnomalyForecaster,
    Forecaster,
    HistoryForecaster,
    OracleForecaster,
    TrendForecaster,
)
from evcd.forecast.sessions import SessionsForecaster
from evcd.forecast.timeline import OccupancyTimeline
from evcd.utils.validation import check_choice, require

FORECASTERS: dict[str, type[Forecaster]] = {
    f.name: f
    for f in (HistoryForecaster, TrendForecaster, AnomalyForecaster, SessionsForecaster, OracleForecaster)
}
#: The settings each forecaster takes by name.
SETTINGS: dict[str, tuple[str, ...]] = {
    "history": ("bin_s", "sample_s"),
    "trend": ("window_s", "sample_s"),
    "anomaly": ("bin_s", "sample_s", "max_lag_s"),
    "sessions": ("bin_s", "window_s", "history_weight", "statistic"),
    "oracle": ("day",),
}


def make_forecaster(
    name: str, training_days: Sequence[OccupancyTimeline] = (), **settings: Any
) -> Forecaster:
    """A forecaster by name: ``"history"``, ``"anomaly"`` or ``"sessions"`` (fitted on
    ``training_days``), ``"trend"`` or ``"oracle"`` (needs ``day=`` the played day's timeline);
    ``settings`` go to its constructor.

    Raises:
        ValueError: an unknown name or setting (listing the allowed ones), ``"history"`` or
            ``"anomaly"`` without training days, ``"oracle"`` without ``day``.
    """
    check_choice("forecaster", name, tuple(FORECASTERS))
    unknown = sorted(set(settings) - set(SETTINGS[name]))
    require(not unknown, f"settings {unknown} for the {name} forecaster: it takes {list(SETTINGS[name])}")
    cls = FORECASTERS[name]
    if cls.needs_days:
        require(
            len(training_days) > 0,
            f"the {name} forecaster needs training days (timelines of past days); none were given",
        )
        return cls(**settings).fit(training_days)  # type: ignore[attr-defined]
    if name == "oracle":
        require("day" in settings, "the oracle forecaster needs day= the timeline of the day it plays")
    return cls(**settings)
