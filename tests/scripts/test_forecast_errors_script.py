"""scripts/forecast_errors.py end to end on the grid (real Hydra, real SUMO): every forecaster's
errors by station and hour on the held-out days, the oracle's exactly 0, bad settings refused."""

from __future__ import annotations

import json

from tests.conftest import run_script


def test_the_forecasters_errors_on_the_held_out_days(script_overrides, tmp_path):
    out = tmp_path / "run"
    proc = run_script("forecast_errors.py", *script_overrides, "days.train=[0,3]", "days.evaluation=[101]",
                      "forecast.horizons_s=[300,600]", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((out / "forecast_errors.json").read_text())
    assert data["train_days"] == [0, 3] and data["evaluation_days"] == [101]
    assert set(data["rows"]) == {"now", "history", "trend", "anomaly", "oracle"}
    assert data["overall_mae"]["oracle"] == 0.0  # the day's own records: a check of the pipeline
    for name in ("now", "history", "trend", "anomaly"):
        rows = data["rows"][name]
        assert rows and all(r["mae"] >= 0 and r["n"] > 0 for r in rows)
        assert {r["hour"] for r in rows} == {6}  # decisions 06:00-06:30
    text = (out / "forecast_errors.md").read_text()
    assert "## history: overall MAE" in text and "held-out" in text.lower()
    proc = run_script("forecast_errors.py", *script_overrides, "forecast.forecasters=[crystal_ball]",
                      f"hydra.run.dir={tmp_path / 'bad'}")  # fmt: skip
    assert proc.returncode == 2
    assert "choose among history, trend, anomaly, oracle" in proc.stdout + proc.stderr
