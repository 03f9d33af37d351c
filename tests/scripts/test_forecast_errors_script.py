"""scripts/forecast_errors.py end to end on the grid (real Hydra, real SUMO): every forecaster's
errors by station and hour on the held-out days, the oracle's exactly 0, the tuning days with chosen
settings, bad settings refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.conftest import run_refusals, run_script, shared_folder

pytestmark = pytest.mark.slow  # every test here takes seconds

#: Settings forecast_errors.py (comparing the sessions forecaster) refuses, and what its message says.
BAD_SETTINGS = [
    ("+forecast.settings.sessions.statistic=mode", "statistic='mode': must be one of median, mean"),
    ("+forecast.settings.trend.window_s=60", "settings go to the forecasters compared, ['sessions']"),
    ("forecast.split=train", "forecast.split='train': must be one of eval, tuning"),
]


@pytest.fixture(scope="module")
def refused(
    script_overrides: list[str], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_SETTINGS` run by forecast_errors.py in one process (:func:`run_refusals`),
    each into its own run directory."""
    root = shared_folder(tmp_path_factory, "forecast_errors_script_refused")
    sessions = [*script_overrides, "forecast.forecasters=[sessions]"]
    cases = [[*sessions, override, f"hydra.run.dir={root / f'bad{i}'}"]
             for i, (override, _) in enumerate(BAD_SETTINGS)]  # fmt: skip
    return root, run_refusals("forecast_errors.py", cases, root)


def test_the_forecasters_errors_on_the_held_out_days(script_overrides, tmp_path):
    out = tmp_path / "run"
    proc = run_script("forecast_errors.py", *script_overrides, "days.train=[0,3]", "days.evaluation=[101]",
                      "forecast.horizons_s=[300,600]", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((out / "forecast_errors.json").read_text())
    assert data["train_days"] == [0, 3] and data["evaluation_days"] == [101]
    assert set(data["rows"]) == {"now", "history", "trend", "anomaly", "sessions", "oracle"}
    assert data["overall_mae"]["oracle"] == 0.0  # the day's own records: a check of the pipeline
    for name in ("now", "history", "trend", "anomaly", "sessions"):
        rows = data["rows"][name]
        assert rows and all(r["mae"] >= 0 and r["n"] > 0 for r in rows)
        assert {r["hour"] for r in rows} == {6}  # decisions 06:00-06:30
    text = (out / "forecast_errors.md").read_text()
    assert "## history: overall MAE" in text and "held-out" in text.lower()
    proc = run_script("forecast_errors.py", *script_overrides, "forecast.forecasters=[crystal_ball]",
                      f"hydra.run.dir={tmp_path / 'bad'}")  # fmt: skip
    assert proc.returncode == 2
    assert "choose among history, trend, anomaly, sessions, oracle" in proc.stdout + proc.stderr


def test_the_tuning_days_with_a_forecasters_settings_and_bad_settings_refused(
    script_overrides, refused, tmp_path
):
    out = tmp_path / "tuning"
    proc = run_script("forecast_errors.py", *script_overrides, "days.train=[0,3]", "days.tuning=[2]",
                      "forecast.split=tuning", "forecast.forecasters=[sessions]",
                      "+forecast.settings.sessions.history_weight=0.25", "forecast.horizons_s=[300]",
                      f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((out / "forecast_errors.json").read_text())
    assert data["split"] == "tuning" and data["evaluation_days"] == [2]
    assert data["settings"] == {"sessions": {"history_weight": 0.25}}
    assert set(data["rows"]) == {"now", "sessions"} and data["rows"]["sessions"]
    assert "Tuning days [2]" in (out / "forecast_errors.md").read_text()
    root, runs = refused  # the bad settings, batched
    for case, ((override, message), (code, log)) in enumerate(zip(BAD_SETTINGS, runs, strict=True)):
        assert code == 2 and message in log, (override, log[-2000:])
        assert not (root / f"bad{case}" / "forecast_errors.json").exists()
