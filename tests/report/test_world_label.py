"""A run's world in the tables (evcd.report.sweep.world_label): calm runs keep their regime's name, a
perturbed or better-informed run gets a table of its own, and so does a forecast from another
forecaster."""

from __future__ import annotations

from evcd.report.sweep import world_label


def test_the_world_names_the_regime_the_perturbations_and_what_the_agents_saw():
    assert world_label({"regime": "peak", "perturbations": {}, "env": {"observe": []}}) == "peak"
    assert world_label({"regime": "table"}) == "table"
    perturbed = {"regime": "peak", "perturbations": {"rain": {"chance": 1}, "outages": None, "incidents": {}}}
    assert world_label(perturbed) == "peak +incidents/rain"  # {}: the kind with its defaults
    seen = {"regime": "peak", "perturbations": {"outages": {"per_day": 2}},
            "env": {"observe": ["forecast", "points_in_service"]}}  # fmt: skip
    assert world_label(seen) == "peak +outages sees PF"
    seen["env"]["forecaster"] = {"name": "anomaly", "bin_s": 600}  # F from another forecaster: another world
    assert world_label(seen) == "peak +outages sees PF (anomaly)"
    seen["env"]["forecaster"] = "history"
    assert world_label(seen) == "peak +outages sees PF"
    seen["env"] = {"observe": ["points_in_service"], "forecaster": "trend"}  # no F: the forecaster is unused
    assert world_label(seen) == "peak +outages sees P"
