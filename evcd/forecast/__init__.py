"""Forecasts of the number of vehicles at each station at a future time (an EV's arrival there).

- :class:`OccupancyTimeline` (:mod:`~evcd.forecast.timeline`): vehicles at each station over time,
  from the controller's visit records, known up to the time they were read;
- :class:`Forecaster` and its :class:`HistoryForecaster`, :class:`TrendForecaster`,
  :class:`AnomalyForecaster` and :class:`OracleForecaster` (:mod:`~evcd.forecast.forecasters`),
  :class:`SessionsForecaster` (:mod:`~evcd.forecast.sessions`), made by name with
  :func:`make_forecaster` (:mod:`~evcd.forecast.registry`);
- :func:`forecast_errors` and :func:`format_mae_table` (:mod:`~evcd.forecast.errors`): a forecaster's
  mean absolute error per station and hour on played days.
"""

from __future__ import annotations

from evcd.forecast.errors import forecast_errors, format_mae_table
from evcd.forecast.forecasters import (
    AnomalyForecaster,
    Forecaster,
    HistoryForecaster,
    OracleForecaster,
    TrendForecaster,
)
from evcd.forecast.registry import FORECASTERS, make_forecaster
from evcd.forecast.sessions import SessionsForecaster
from evcd.forecast.timeline import OccupancyTimeline

__all__ = [
    "FORECASTERS",
    "AnomalyForecaster",
    "Forecaster",
    "HistoryForecaster",
    "OccupancyTimeline",
    "OracleForecaster",
    "SessionsForecaster",
    "TrendForecaster",
    "forecast_errors",
    "format_mae_table",
    "make_forecaster",
]
