"""The day-snapshot cache: keys, reuse, corruption, concurrency, restoring a snapshot."""

from __future__ import annotations

import dataclasses
import json
import logging
import multiprocessing
from pathlib import Path

import pytest

from evcd.scenario.demand import DemandConfig
from evcd.scenario.scenario import load_scenario
from evcd.sim.charging import ChargingController
from evcd.sim.driver import SumoDriver
from evcd.sim.snapshots import (
    CACHE_ENV,
    MANIFEST,
    CacheError,
    DayCache,
    DaySpec,
    default_cache_dir,
    snapshot_times,
)

DEMAND = DemandConfig(
    cars_per_day=300, evs=30, min_trip_m=200.0, charging_share=0.5, hourly_profile=(1.0,) + (0.0,) * 23
)
TIMES = [600.0, 900.0, 1200.0]


@pytest.fixture
def spec(small_scenario) -> DaySpec:
    return DaySpec(load_scenario(small_scenario.root), DEMAND, demand_seed=0)


def test_snapshot_times_cover_the_window():
    assert snapshot_times((1800, 3600), 300) == [1800, 2100, 2400, 2700, 3000, 3300]
    assert snapshot_times((1900, 2000), 300) == [1800]
    assert snapshot_times((0, 86_400), 3600)[-1] == 82_800
    with pytest.raises(ValueError, match="snapshot_every"):
        snapshot_times((0, 10), 0)


def test_default_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "evcd"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert default_cache_dir() == Path.home() / ".cache" / "evcd"
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "mine"))
    assert default_cache_dir() == tmp_path / "mine"


def test_a_cache_root_that_is_a_file_is_refused_naming_it(spec, monkeypatch, tmp_path):
    a_file = tmp_path / "cache.txt"
    a_file.write_text("not a folder")
    monkeypatch.setenv(CACHE_ENV, str(a_file))
    with pytest.raises(ValueError, match=rf"{a_file} \(from \$EVCD_CACHE.*is a file, not a folder"):
        DayCache(spec)
    with pytest.raises(ValueError, match=r"from cache_dir\) is a file"):
        DayCache(spec, a_file)
    assert a_file.read_text() == "not a folder"


def test_key_changes_with_everything_that_changes_the_day(spec, small_scenario):
    same = DaySpec(load_scenario(small_scenario.root), DEMAND, demand_seed=0)
    assert same.key == spec.key
    others = [
        dataclasses.replace(spec, demand=dataclasses.replace(DEMAND, evs=31)),
        dataclasses.replace(spec, demand=dataclasses.replace(DEMAND, cars_per_day=301)),
        dataclasses.replace(spec, demand_seed=1),
        dataclasses.replace(spec, step_length=0.5),
        dataclasses.replace(spec, time_to_teleport=-1),
        DaySpec(load_scenario(small_scenario.root, charging_points=3), DEMAND, demand_seed=0),
    ]
    keys = {spec.key} | {o.key for o in others}
    assert len(keys) == len(others) + 1
    with pytest.raises(ValueError, match="exactly one"):
        DaySpec(spec.scenario)


def test_key_changes_with_the_packages_that_draw_and_read_the_day(spec, monkeypatch):
    from evcd.sim import day_spec

    real, base = day_spec.importlib.metadata.version, spec.key
    for package in ("numpy", "sumolib"):
        monkeypatch.setattr(day_spec.importlib.metadata, "version",
                            lambda name, p=package: "0.0.1" if name == p else real(name))  # fmt: skip
        assert DaySpec(spec.scenario, DEMAND, demand_seed=0).key != base, package
    monkeypatch.undo()
    assert DaySpec(spec.scenario, DEMAND, demand_seed=0).key == base


def test_the_code_key_lists_every_evcd_module_a_day_depends_on():
    """Every evcd module imported (transitively) by a module of the key is in the key, so that editing
    one of them (e.g. how the stations file is read) cannot leave another day in the cache."""
    import ast

    from evcd.sim import day_spec

    root = Path(day_spec.__file__).parents[1]
    listed, todo = set(day_spec._CODE), list(day_spec._CODE)
    while todo:
        tree = ast.parse((root / todo.pop()).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("evcd."):
                rel = node.module.removeprefix("evcd.").replace(".", "/") + ".py"
                assert rel in listed, f"{rel} shapes a cached day but is not in day_spec._CODE"
    assert "scenario/stations_file.py" in listed and "sim/charge_record.py" in listed


def test_second_run_builds_nothing(spec, tmp_path):
    first = DayCache(spec, tmp_path)
    snaps = first.ensure(TIMES)
    assert first.built_times == TIMES and [s.time for s in snaps] == TIMES
    stamps = {p.name: p.stat().st_mtime_ns for p in first.dir.iterdir()}
    manifest = json.loads((first.dir / MANIFEST).read_text())
    assert manifest["fields"]["demand"]["evs"] == 30 and len(manifest["snapshots"]) == 3
    second = DayCache(spec, tmp_path)
    assert second.has(TIMES) and second.ensure(TIMES) == snaps
    assert second.built_times == []
    assert {p.name: p.stat().st_mtime_ns for p in second.dir.iterdir()} == stamps
    # a wider window builds only the missing snapshots
    third = DayCache(spec, tmp_path)
    third.ensure([*TIMES, 1500.0])
    assert third.built_times == [1500.0]


def test_a_snapshot_restores_simulation_and_queues(spec, tmp_path):
    cache = DayCache(spec, tmp_path)
    snap = cache.ensure(TIMES)[1]
    reference = ChargingController(spec.scenario.stations)
    with cache.make_driver() as driver:
        driver.add_listener(reference.update)
        driver.step(until=900)
        vehicles = set(driver.api.vehicle.getIDList())
        expected = reference.state_dict()
        driver.step(until=1000)
        controller = ChargingController(spec.scenario.stations)
        assert cache.load(snap, driver, controller) == 900
        assert driver.time == 900 and set(driver.api.vehicle.getIDList()) == vehicles
        assert controller.state_dict() == expected
    assert expected["records"]  # the snapshot carries charging visits


@pytest.mark.parametrize("damage", ["flip", "truncate", "delete"])
def test_damaged_snapshot_is_detected_and_rebuilt(spec, tmp_path, caplog, damage):
    cache = DayCache(spec, tmp_path)
    snaps = cache.ensure(TIMES)
    victim = snaps[1].state
    good = victim.read_bytes()
    if damage == "flip":
        victim.write_bytes(good[:100] + bytes([good[100] ^ 0xFF]) + good[101:])
    elif damage == "truncate":
        victim.write_bytes(good[: len(good) // 2])
    else:
        victim.unlink()
    driver = cache.make_driver()
    with driver, pytest.raises(CacheError, match="corrupted"):  # never silently used
        cache.load(snaps[1], driver, ChargingController(spec.scenario.stations))
    caplog.set_level(logging.WARNING, logger="evcd.sim.snapshots")
    again = DayCache(spec, tmp_path)
    assert not again.has(TIMES)
    again.ensure(TIMES)
    assert again.built_times == [900.0] and DayCache(spec, tmp_path).has(TIMES)
    assert any("does not match its checksum" in r.message for r in caplog.records) or damage == "delete"


def test_partial_cache_without_manifest_is_rebuilt(spec, tmp_path):
    cache = DayCache(spec, tmp_path)
    cache.ensure(TIMES)
    (cache.dir / MANIFEST).unlink()  # e.g. a build killed before its manifest was written
    again = DayCache(spec, tmp_path)
    again.ensure(TIMES)
    assert again.built_times == TIMES
    (cache.dir / MANIFEST).write_text("{not json", encoding="utf-8")
    third = DayCache(spec, tmp_path)
    third.ensure(TIMES)
    assert third.built_times == TIMES
    routes = cache.dir / "routes.rou.xml.gz"
    routes.write_bytes(routes.read_bytes()[:-10])  # new routes: every snapshot is rebuilt
    fourth = DayCache(spec, tmp_path)
    fourth.ensure(TIMES)
    assert fourth.built_times == TIMES


def test_building_needs_this_process_libsumo(spec, tmp_path, small_scenario):
    cache = DayCache(spec, tmp_path)
    other = SumoDriver(small_scenario.net_file, [small_scenario.vtypes_file], seed=0)
    with other, pytest.raises(CacheError, match="close the running one"):
        cache.ensure(TIMES)


def _ensure_in_child(root: str, cache_dir: str) -> list[float]:
    cache = DayCache(DaySpec(load_scenario(root), DEMAND, demand_seed=7), cache_dir)
    cache.ensure(TIMES)
    return cache.built_times


@pytest.mark.slow
def test_parallel_processes_build_a_day_once(small_scenario, tmp_path):
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(2) as pool:
        built = pool.starmap(_ensure_in_child, [(str(small_scenario.root), str(tmp_path))] * 2)
    assert sorted(map(len, built)) == [0, len(TIMES)]  # one built, the other waited and reused


def test_a_build_says_once_what_it_is_and_shows_its_progress(spec, tmp_path, caplog, capsys, monkeypatch):
    import evcd.sim.snapshots as snapshots

    monkeypatch.setattr(snapshots, "_told", [False])
    with caplog.at_level("WARNING", logger="evcd.sim.snapshots"):
        DayCache(spec, tmp_path / "a").ensure(TIMES)
        DayCache(spec, tmp_path / "b").ensure(TIMES)  # another build in the same process: no repeat
    told = [r.getMessage() for r in caplog.records if "only the first time" in r.getMessage()]
    assert len(told) == 1 and str(tmp_path / "a") in told[0]
    err = capsys.readouterr().err
    assert "background day" in err and f"{TIMES[-1]:.0f} sim s" in err
