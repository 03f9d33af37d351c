"""A run's world in the tables (evcd.report.sweep.world_label): calm runs keep their regime's name, a
perturbed or better-informed run gets a table of its own."""

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
