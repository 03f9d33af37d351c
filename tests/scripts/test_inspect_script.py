"""The inspection command end to end: real Hydra, real SUMO, on a generated scenario folder."""

from __future__ import annotations

import json
import subprocess
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from evcd.scenario.demand import DemandConfig
from tests.conftest import ROOT, compose_config, run_refusals, run_script, shared_folder


def run_inspect(*overrides: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return run_script("inspect_scenario.py", *overrides, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def scenario_dir(script_grid) -> Path:
    return script_grid


def test_yaml_demand_defaults_equal_the_library_defaults():
    cfg = compose_config("inspect")
    yaml = dict(cfg.scenario.demand)
    lib = asdict(DemandConfig())
    lib.pop("evs")
    assert set(yaml) == set(lib)
    for key, value in lib.items():
        assert tuple(yaml[key]) == value if isinstance(value, tuple) else yaml[key] == value, key
    assert cfg.evs == 400 and cfg.scenario.charging_points == 2


@pytest.mark.slow
def test_inspect_a_morning_on_a_small_scenario(scenario_dir, tmp_path):
    out = tmp_path / "run"
    proc = run_inspect(
        f"scenario.path={scenario_dir}", "evs=120", "seed=3", "begin=25200", "end=32400",
        "scenario.demand.cars_per_day=800", "scenario.demand.min_trip_m=500",
        "scenario.demand.charging_share=0.6",
        f"hydra.run.dir={out}",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["network"]["lefthand"] is True
    assert len(report["stations"]) == 3
    assert [h["hour"] for h in report["hourly"]] == [7, 8]
    s = report["summary"]
    assert s["departed"] > 0 and s["arrived"] > 0 and s["teleports"] == 0
    served = sum(st["served"] for st in report["stations"])
    assert served > 0
    # every EV that got a point had arrived first; nobody charged twice
    charges = report["charges"]
    assert len({c["vehicle"] for c in charges}) == len(charges)
    assert all(c["start_time"] >= c["arrival_time"] for c in charges if c["start_time"] is not None)
    png = (out / "scenario_day.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    assert (out / "routes.rou.xml.gz").stat().st_size > 0
    log = proc.stdout + proc.stderr
    assert "per station" in log and "station-to-station road distance" in log


@pytest.mark.slow
def test_inspect_a_perturbed_morning_plays_and_draws_its_events(scenario_dir, tmp_path):
    """perturbations=mixed with every kind in the morning: the report lists the events drawn from the
    day's seed (those an environment of that day plays), the hourly traffic is slower than the calm
    day's, and day_events.png is written."""
    common = (
        f"scenario.path={scenario_dir}", "evs=120", "seed=3", "begin=25200", "end=32400",
        "scenario.demand.cars_per_day=800", "scenario.demand.min_trip_m=500",
    )  # fmt: skip
    wet = (
        "perturbations=mixed", "perturbations.rain.chance=1", "perturbations.rain.start_window=[25200,26000]",
        "perturbations.rain.speed_factor=0.7", "perturbations.incidents.per_day=6",
        "perturbations.incidents.start_window=[25200,32400]",
        "perturbations.outages.start_window=[25200,32400]",
    )  # fmt: skip
    runs = {}
    for name, extra in (("calm", ()), ("mixed", wet)):
        out = tmp_path / name
        proc = run_inspect(*common, *extra, f"hydra.run.dir={out}")
        assert proc.returncode == 0, proc.stderr[-3000:]
        runs[name] = (out, json.loads((out / "report.json").read_text()))
    out, report = runs["mixed"]
    events = report["events"]
    assert events["incidents"] and events["rain"] and events["roadworks"]
    assert all(25200 <= e["start"] < 32400 for e in events["incidents"])
    assert runs["calm"][1]["events"] == {"incidents": [], "rain": [], "roadworks": [], "outages": []}
    speed = {k: np.mean([h["mean_speed_kmh"] for h in r[1]["hourly"]]) for k, r in runs.items()}
    assert speed["mixed"] < 0.9 * speed["calm"]
    png = (out / "day_events.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    assert not (runs["calm"][0] / "day_events.png").exists()


#: Settings inspect_scenario.py refuses before SUMO starts, and what its message says.
BAD_VALUES = [
    ("evs=-1", "evs=-1"),
    ("scenario.charging_points=0", "charging_points=0"),
    ("begin=90000", "begin=90000"),
    ("scenario.path=/no/such/folder", "/no/such/folder"),
    ("+perturbations.rain={hours: [0, 30]}", "perturbations.rain.hours=[0, 30]"),
]


@pytest.fixture(scope="module")
def refused(
    scenario_dir: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_VALUES` run by inspect_scenario.py in one process (:func:`run_refusals`),
    each into its own run directory."""
    root = shared_folder(tmp_path_factory, "inspect_script_refused")
    cases = [[f"scenario.path={scenario_dir}", override, f"hydra.run.dir={root / f'run{i}'}"]
             for i, (override, _) in enumerate(BAD_VALUES)]  # fmt: skip
    return root, run_refusals("inspect_scenario.py", cases, root)


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(BAD_VALUES)), ids=[override for override, _ in BAD_VALUES])
def test_bad_values_stop_before_sumo(refused, case):
    root, runs = refused
    code, log = runs[case]
    assert code == 2, log[-2000:]
    assert BAD_VALUES[case][1] in log
    assert not (root / f"run{case}" / "routes.rou.xml.gz").exists()  # nothing was generated or simulated


@pytest.mark.slow
def test_a_refusal_exits_with_code_2_in_a_process_of_its_own(scenario_dir, tmp_path):
    """What the batched refusals above stand for: ``python scripts/inspect_scenario.py`` itself, refused,
    exits with code 2 and the message before anything is generated."""
    out = tmp_path / "run"
    proc = run_inspect(f"scenario.path={scenario_dir}", "evs=-1", f"hydra.run.dir={out}")
    assert proc.returncode == 2
    assert "evs=-1" in proc.stdout + proc.stderr
    assert not (out / "routes.rou.xml.gz").exists()


@pytest.mark.slow
def test_unknown_option_is_rejected_by_name(tmp_path):
    proc = run_inspect("no_such_option=3", f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode != 0
    assert "no_such_option" in proc.stderr
