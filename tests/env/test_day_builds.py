"""A world's days built side by side (evcd.env.day_builds): the same files as one after the other,
each built once, in processes of their own."""

from __future__ import annotations

import dataclasses
import gzip
import hashlib
import json
import logging
import re

import pytest

from evcd.env import ChargingNavEnv
from evcd.env.day_builds import DayBuildError, build_days
from evcd.sim.snapshots import MANIFEST
from tests.conftest import GRID_ENV


def snapshot_files(env: ChargingNavEnv) -> list[dict[str, tuple[str, str]]]:
    """Per day and snapshot: the hash of SUMO's state without the comment SUMO heads it with (when and
    where it was written), and the queues' hash from the cache's manifest."""
    out = []
    for cache in env.simulation.caches:
        manifest = json.loads((cache.dir / MANIFEST).read_text())
        day = {}
        for t, entry in sorted(manifest["snapshots"].items()):
            state = gzip.decompress((cache.dir / entry["state"]).read_bytes()).decode()
            body = re.sub(r"<!--.*?-->", "", state, count=1, flags=re.DOTALL)
            day[t] = (hashlib.sha256(body.encode()).hexdigest(), entry["controller_sha256"])
        out.append(day)
    return out


@pytest.mark.slow
def test_days_built_side_by_side_are_the_days_built_one_after_the_other(grid_env_dir, tmp_path, caplog):
    kwargs = {"scenario": grid_env_dir, **GRID_ENV, "demand_seeds": [0, 1, 2]}
    alone = ChargingNavEnv(**kwargs, cache_dir=tmp_path / "alone")
    with alone:
        alone.prepare(workers=1)
        one_by_one = snapshot_files(alone)
    side = ChargingNavEnv(**kwargs, cache_dir=tmp_path / "side")
    with side, caplog.at_level(logging.INFO, logger="evcd.env.day_builds"):
        assert not any(side.simulation.cached(d) for d in range(3))
        side.prepare(workers=2)
        assert "built 3 background days 2 at a time" in caplog.text
        assert all(side.simulation.cached(d) for d in range(3))
        assert all(c.built_times == [] for c in side.simulation.caches)  # built by the other processes
        assert snapshot_files(side) == one_by_one and len(one_by_one[0]) > 1
        # cached now: nothing is built again, in processes or here
        assert build_days(side.config, [0, 1, 2], workers=2).keys() == {0, 1, 2}
        assert snapshot_files(side) == one_by_one
    assert len({json.dumps(d) for d in one_by_one}) == 3  # three different days


@pytest.mark.slow
def test_days_are_built_side_by_side_inside_a_joblib_worker(grid_env_dir, tmp_path):
    """Hydra's joblib launcher runs each job in a loky worker, whose multiprocessing start method a
    spawned child cannot take: the builds are plain processes, so a job there builds its days too."""
    from joblib import Parallel, delayed

    kwargs = {"scenario": grid_env_dir, **GRID_ENV, "demand_seeds": [5, 6], "cache_dir": tmp_path}
    (cached,) = Parallel(n_jobs=2, backend="loky")(delayed(_prepare_in_worker)(kwargs) for _ in range(1))
    assert cached == [True, True]


def _prepare_in_worker(kwargs: dict) -> list[bool]:
    env = ChargingNavEnv(**kwargs)
    with env:
        env.prepare(workers=2)
        return [env.simulation.caches[d].has(env.simulation.times) for d in range(2)]


def test_a_failed_build_names_its_day_and_quotes_its_output(grid_env_dir, tmp_path):
    env = ChargingNavEnv(scenario=grid_env_dir, **GRID_ENV, demand_seeds=[0, 1], cache_dir=tmp_path)
    broken = dataclasses.replace(env.config, scenario=tmp_path / "no_such_city")
    with pytest.raises(DayBuildError, match=r"building day \d in a process of its own failed \(exit 1\)"):
        build_days(broken, [0, 1], workers=2)
    env.close()
