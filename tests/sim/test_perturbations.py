"""A day's perturbations (:mod:`evcd.sim.perturbations`): drawn from the day's own seed, part of the
day's key and snapshots, in every episode of that day; a calm day as before; bad input refused."""

from __future__ import annotations

import json

import pytest

from evcd.env import ChargingNavEnv
from evcd.scenario.demand import DemandConfig
from evcd.scenario.scenario import load_scenario
from evcd.sim.outages import Outage
from evcd.sim.perturbations import KINDS, OutageSettings, Perturbations
from evcd.sim.snapshots import DayCache, DaySpec

OUTAGES = {"outages": {"per_day": 6.0, "minutes": [30, 180], "points": 1}}


def test_the_same_seed_draws_the_same_outages_and_another_seed_others(small_scenario):
    p = Perturbations.from_value(OUTAGES)
    days = [p.outages_of(small_scenario.stations, seed) for seed in (7, 7, 8)]
    assert days[0] == days[1] != days[2]
    assert all(days) and all(isinstance(o, Outage) for o in days[0])
    points = {st.id: st.points for st in small_scenario.stations}
    for day in days:
        for o in day:
            assert o.end - o.start <= 180 * 60 and 0 <= o.start < 86_400
            assert o.end - o.start >= 30 * 60 or o.end == 86_400  # cut at the day's end
            # never more points out at once than the station has (cs2 has one)
            assert (
                sum(x.points for x in day if x.station == o.station and x.active(o.start))
                <= points[o.station]
            )
    assert [o.start for o in days[0]] == sorted(o.start for o in days[0])


def test_over_many_days_the_mean_number_and_the_stations_follow_the_settings(small_scenario):
    """Poisson with mean per_day (less the few dropped overlaps at cs2); stations in proportion to
    their points (cs1: 2, cs2: 1)."""
    p = Perturbations.from_value({"outages": {"per_day": 2.0}})
    days = [p.outages_of(small_scenario.stations, seed) for seed in range(400)]
    n = sum(len(d) for d in days)
    assert 1.7 < n / 400 <= 2.2
    share_cs1 = sum(o.station == "cs1" for d in days for o in d) / n
    assert 0.6 < share_cs1 < 0.75


def test_calm_is_calm(small_scenario):
    for value in (None, {}, {"outages": None}, {"outages": {"per_day": 0}}):
        p = Perturbations.from_value(value)
        assert p.outages_of(small_scenario.stations, 3) == ()
    assert Perturbations.from_value(None).calm and not Perturbations.from_value(OUTAGES).calm


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"hail": {}}, "unknown kind 'hail'; the kinds: " + ", ".join(KINDS)),
        ({"rain": {"factor": 0.8}}, "perturbations.rain.factor: unknown"),
        ({"outages": {"per_day": -1}}, "perturbations.outages.per_day"),
        ({"outages": {"minutes": [200, 100]}}, "perturbations.outages.minutes=[200, 100]"),
        ({"outages": {"minutes": [0, 10]}}, "need 1 <= low"),
        ({"outages": {"points": 0}}, "perturbations.outages.points"),
        ({"outages": {"start_window": [0, 90000]}}, "perturbations.outages.start_window"),
        ({"outages": {"duration": 5}}, "perturbations.outages.duration: unknown"),
        ("outages", "must be a mapping"),
    ],
)
def test_bad_settings_are_refused_by_name(value, message):
    with pytest.raises(ValueError, match=None) as info:
        Perturbations.from_value(value)
    assert message in str(info.value)


def test_an_outage_is_in_the_days_key_and_its_snapshots(small_scenario, tmp_path):
    """A day with cs1 closed all day: a key of its own, and its snapshots' queues at cs1 never charge
    anybody, while the calm day's do; the calm day's key has no trace of outages."""
    demand = DemandConfig(
        cars_per_day=300, evs=30, charging_share=1.0, min_trip_m=200.0, hourly_profile=(1.0,) + (0.0,) * 23
    )  # every EV departs in the first hour
    scenario = load_scenario(small_scenario.root)
    calm = DaySpec(scenario, demand, 5)
    closed = DaySpec(scenario, demand, 5, outages=(Outage("cs1", 2, 0.0, 86_400.0),))
    assert "outages" not in calm.fields and closed.fields["outages"][0]["station"] == "cs1"
    assert calm.key != closed.key
    states = {}
    for name, spec in (("calm", calm), ("closed", closed)):
        cache = DayCache(spec, tmp_path / "cache")
        (snap,) = cache.ensure([7_200.0])
        states[name] = json.loads(snap.controller.read_text())
    started = {
        k: [r for r in s["records"] if r["station"] == "cs1" and r["start_time"] is not None]
        for k, s in states.items()
    }
    assert started["calm"] and not started["closed"]
    assert states["closed"]["stations"]["cs1"]["queue"]  # they wait at the closed station


def test_an_environment_plays_its_days_outages(small_scenario, tmp_path):
    """ChargingNavEnv(perturbations=...) gives each day its own outages (different seeds, different
    outages), and its controller plays with the day's outages of the episode it resets to."""
    kwargs = {
        "scenario": small_scenario.root,
        "cache_dir": tmp_path / "cache",
        "demand_seeds": (3, 4),
        "demand": {"cars_per_day": 200, "evs": 30, "charging_share": 1.0, "min_trip_m": 200.0},
        "departure_window": (3600.0, 7200.0),
        "decision_interval": 60.0,
    }
    calm = ChargingNavEnv(**kwargs)
    env = ChargingNavEnv(**kwargs, perturbations={"outages": {"per_day": 20, "start_window": [0, 7200]}})
    try:
        days = env.world.days
        assert days[0].outages and days[0].outages != days[1].outages
        assert [d.key for d in calm.world.days] != [d.key for d in days]
        assert all(d.outages == () for d in calm.world.days)
        for day in (0, 1):
            env.reset(seed=1, options={"day": day})
            assert env.world.simulation.controller.outages == days[day].outages
    finally:
        env.close()
        calm.close()


def test_settings_keep_their_types():
    s = OutageSettings(per_day=1, minutes=[10, 20], start_window=[0, 100])  # type: ignore[arg-type]
    assert s.minutes == (10.0, 20.0) and s.start_window == (0.0, 100.0)
