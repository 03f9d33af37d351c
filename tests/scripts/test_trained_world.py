"""``evcd.cli.trained_world``: an evaluation's world against the one a policy was trained in, on the
configs the scripts really compose (real Hydra)."""

from __future__ import annotations

from typing import Any

from omegaconf import OmegaConf

from evcd.cli.trained_world import trained_world, warnings
from tests.conftest import compose_config

#: What evaluate.py needs to play the README regime's world (conf/experiment/peak.yaml).
PEAK_WORLD = ["env.departure_window=[25200.0,36000.0]", "env.reward=time"]


def saved(*overrides: str) -> dict[str, Any]:
    """A training run's config as its checkpoints hold it: resolved, the environments given the
    training days (as scripts/train.py does)."""
    cfg = OmegaConf.to_container(compose_config("train", *overrides), resolve=True)
    cfg["env"]["demand_seeds"] = list(cfg["days"]["train"])
    return cfg


def evaluation(*overrides: str) -> dict[str, Any]:
    return OmegaConf.to_container(compose_config("evaluate", *overrides), resolve=True)


def test_the_readme_policy_in_its_own_world_on_held_out_days_raises_nothing():
    report = trained_world(saved(), evaluation(*PEAK_WORLD, "env.demand_seeds=[101,102]"))
    assert report == {"differences": [], "training_days": [], "tuning_days": [], "forecast_days": None}
    assert warnings(report) == []
    # how the observation is scaled, where the caches live, the GUI: not the world
    report = trained_world(saved(), evaluation(*PEAK_WORLD, "env.normalize_obs=true", "env.cache_dir=/x"))
    assert report["differences"] == []


def test_another_window_reward_world_and_days_are_each_named():
    world = evaluation("env.demand_seeds=[0,2,101]", "perturbations=outages", "evs=300")
    report = trained_world(saved(), world)
    diff = report["differences"]
    assert "env.departure_window: [25200.0, 36000.0] -> [0.0, 86400.0]" in diff, diff
    assert any(d.startswith("env.reward: 'time' -> ") for d in diff), diff
    assert "evs: 400 -> 300" in diff, diff
    assert any(d.startswith("perturbations.outages") for d in diff), diff
    assert report["training_days"] == [0] and report["tuning_days"] == [2]
    lines = warnings(report)
    assert len(lines) == 3 and "env.departure_window" in lines[0]
    assert lines[1] == "evaluated on days the policy trained on: [0]"
    assert "tuning days" in lines[2] and "[2]" in lines[2]


def test_the_scenario_folder_is_compared_as_a_folder(tmp_path):
    folder = tmp_path / "city"
    trained = saved(f"scenario.path={folder}")
    same = evaluation(*PEAK_WORLD, f"scenario.path={folder}/../city")
    assert trained_world(trained, same)["differences"] == []
    other = trained_world(trained, evaluation(*PEAK_WORLD, f"scenario.path={tmp_path / 'town'}"))
    assert len(other["differences"]) == 1 and other["differences"][0].startswith("scenario.path: ")


def test_a_forecast_learnt_from_other_days_is_named():
    trained = saved("env.observe=[forecast]")  # forecast_days null: the training days 0 and 3
    observe = [*PEAK_WORLD, "env.observe=[forecast]", "env.demand_seeds=[101]"]
    assert trained_world(trained, evaluation(*observe, "env.forecast_days=[3,0]"))["forecast_days"] is None
    other = trained_world(trained, evaluation(*observe, "env.forecast_days=[0]"))
    assert other["forecast_days"] == "[0, 3] -> [0]" and other["differences"] == []
    assert len(warnings(other)) == 1 and "other days than in training: [0, 3] -> [0]" in warnings(other)[0]


def test_a_fleet_policy_against_another_share_and_nothing_known_without_a_config():
    trained = saved("experiment=fleet")
    fleet = ["task=fleet", "evs=600", "env.demand_seeds=[106]"]
    assert trained_world(trained, evaluation(*fleet))["differences"] == []
    diff = trained_world(trained, evaluation(*fleet, "fleet.guided_share=0.5"))["differences"]
    assert diff == ["fleet.guided_share: 1.0 -> 0.5"]
    single = trained_world(trained, evaluation(*PEAK_WORLD, "evs=600"))["differences"]
    assert "task: 'fleet' -> 'single'" in single, single
    assert trained_world(None, evaluation()) is None and warnings(None) == []
