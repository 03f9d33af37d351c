"""The evaluation loop on the real environment (small grid scenario), its statistics and writers."""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from evcd.agents import make_agent
from evcd.env import ChargingNavEnv
from evcd.env.runners import EpisodeRow
from evcd.loops.evaluate import evaluate, run_episode
from evcd.loops.run_files import CSV_FIELDS, write_episodes_csv, write_results_json
from evcd.loops.seeds import episode_seed
from evcd.loops.stats import EvalResult, bootstrap_ci, summarize
from tests.conftest import make_grid_scenario

#: A small, quick background day: the snapshots up to 06:30 build in a few seconds.
SMALL = {
    "evs": 100,
    "demand": {"cars_per_day": 1500, "min_trip_m": 500.0, "charging_share": 0.6},
    "departure_window": (21600.0, 23400.0),
}


@pytest.fixture(scope="module")
def make_env(tmp_path_factory):
    """Build envs on one grid scenario and one snapshot cache; closes them at the end."""
    root = tmp_path_factory.mktemp("evaluate")
    scenario = make_grid_scenario(root / "grid")
    envs: list[ChargingNavEnv] = []

    def make(**overrides) -> ChargingNavEnv:
        for env in envs:  # libsumo: one simulation per process
            env.close()
        env = ChargingNavEnv(scenario=scenario, cache_dir=root / "cache", **{**SMALL, **overrides})
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def rows_without_wall(result: EvalResult) -> list[dict]:
    return [{k: v for k, v in dataclasses.asdict(r).items() if k != "wall_s"} for r in result.rows]


# ---------------------------------------------------------------------------------------- the loop
@pytest.mark.slow
def test_same_seed_same_rows_other_seed_other_rows(make_env):
    env = make_env()
    agent = make_agent("random", env.action_space.n, np.random.default_rng(0))
    first = evaluate(env, agent, episodes=3, seed=11, progress=False)
    env = make_env()  # a fresh env (and SUMO) gives the same rows
    again = evaluate(env, agent, episodes=3, seed=11, progress=False)
    assert rows_without_wall(first) == rows_without_wall(again)
    assert dataclasses.replace(first.summary, mean_wall_s=0) == dataclasses.replace(
        again.summary, mean_wall_s=0
    )
    other = evaluate(env, agent, episodes=3, seed=12, progress=False)
    assert [r.seed for r in other.rows] != [r.seed for r in first.rows]
    assert [(r.departure, r.origin) for r in other.rows] != [(r.departure, r.origin) for r in first.rows]


def test_rows_describe_the_episodes(make_env):
    env = make_env()
    result = evaluate(env, make_agent("greedy", 3, np.random.default_rng(0)), 4, seed=3, progress=False)
    assert result.agent == "greedy" and result.seed == 3
    assert [r.episode for r in result.rows] == [0, 1, 2, 3]
    for row in result.rows:
        assert row.seed == episode_seed(3, row.episode)[0]
        assert 21600 <= row.departure < 23400 and row.day == 0 and row.origin
        choices = [int(c) for c in row.choices.split("-")]
        assert choices and row.station == choices[-1] and row.station_id == f"cs{row.station}"
        assert row.reason == "charging" and not row.truncated
        assert row.travel_time > 0 and row.queue_wait >= 0 and row.wall_s > 0
        assert row.episode_return == pytest.approx(7200.0 / row.travel_time)
    s = result.summary
    assert (s.episodes, s.completed, s.truncated) == (4, 4, 0)
    times = [r.travel_time for r in result.rows]
    assert s.mean_travel_time == pytest.approx(np.mean(times))
    assert s.median_travel_time == pytest.approx(np.median(times))
    assert s.ci_low <= s.mean_travel_time <= s.ci_high


@pytest.mark.slow
def test_an_episode_depends_only_on_run_seed_and_index(make_env):
    env = make_env()
    agent = make_agent("random", 3, np.random.default_rng(0))
    two = evaluate(env, agent, 2, seed=5, progress=False)
    three = evaluate(env, agent, 3, seed=5, progress=False)
    assert rows_without_wall(three)[:2] == rows_without_wall(two)
    # nor on the order: later departures first (the simulation goes back in time between episodes)
    backwards = sorted(range(3), key=lambda i: -three.rows[i].departure)
    rows = {i: run_episode(env, agent, i, seed=5) for i in backwards}
    again = EvalResult("random", 5, tuple(rows[i] for i in range(3)), three.summary)
    assert rows_without_wall(again) == rows_without_wall(three)


def test_greedy_chooses_the_same_on_normalised_observations(make_env):
    greedy = make_agent("greedy", 3, np.random.default_rng(0))
    raw = evaluate(make_env(), greedy, 3, seed=8, progress=False)
    scaled = evaluate(make_env(normalize_obs=True), greedy, 3, seed=8, progress=False)
    assert rows_without_wall(scaled) == rows_without_wall(raw)


def test_truncated_episodes_are_counted_not_averaged(make_env):
    env = make_env(max_travel_time=20.0)  # too short to reach any station from most origins
    result = evaluate(env, make_agent("greedy", 3, np.random.default_rng(0)), 4, seed=0, progress=False)
    cut = [r for r in result.rows if r.truncated]
    assert cut and all(r.reason == "max_travel_time" and r.episode_return == 0.0 for r in cut)
    assert result.summary.truncated == len(cut)
    done = [r.travel_time for r in result.rows if not r.truncated]
    if done:
        assert result.summary.mean_travel_time == pytest.approx(np.mean(done))
    else:
        assert math.isnan(result.summary.mean_travel_time)


@pytest.mark.parametrize(
    "episodes,seed,needle", [(0, 0, "episodes=0"), (2, -1, "seed=-1"), (1.5, 0, "episodes")]
)
def test_bad_arguments(episodes, seed, needle):
    agent = make_agent("greedy", 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match=needle):
        evaluate(None, agent, episodes, seed, progress=False)  # type: ignore[arg-type]


def test_episode_seeds_are_distinct_and_reproducible():
    seeds = [episode_seed(0, i)[0] for i in range(1000)]
    assert len(set(seeds)) == 1000 and all(0 <= s < 2**63 for s in seeds)
    assert seeds[:10] == [episode_seed(0, i)[0] for i in range(10)]
    assert episode_seed(1, 0)[0] != seeds[0]
    assert episode_seed(0, 4)[1].random() == episode_seed(0, 4)[1].random()


# ---------------------------------------------------------------------------------------- statistics
def test_bootstrap_ci_contains_the_mean_and_narrows_with_more_samples():
    data = np.random.default_rng(0).exponential(900.0, size=3200)
    widths = []
    for n in (50, 200, 800, 3200):
        x = data[:n]
        lo, hi = bootstrap_ci(x, np.random.default_rng(1))
        assert lo < x.mean() < hi
        widths.append(hi - lo)
    assert all(a > b for a, b in itertools.pairwise(widths))
    # about the normal-theory width 2 x 1.96 x sd / sqrt(n)
    assert widths[-1] == pytest.approx(2 * 1.96 * data.std(ddof=1) / math.sqrt(3200), rel=0.1)


def test_bootstrap_ci_is_reproducible_and_covers_the_true_mean():
    x = np.random.default_rng(2).normal(100.0, 10.0, size=40)
    assert bootstrap_ci(x, np.random.default_rng(3)) == bootstrap_ci(x, np.random.default_rng(3))
    covered = 0
    for seed in range(200):  # 95% intervals of samples of a known mean cover it ~95% of the time
        sample = np.random.default_rng(seed).normal(100.0, 10.0, size=40)
        lo, hi = bootstrap_ci(sample, np.random.default_rng(seed), resamples=2000)
        covered += lo <= 100.0 <= hi
    assert 0.88 <= covered / 200 <= 0.99


def test_bootstrap_ci_edge_cases():
    rng = np.random.default_rng(0)
    assert all(math.isnan(v) for v in bootstrap_ci([], rng))
    assert bootstrap_ci([42.0], rng) == (42.0, 42.0)
    lo, hi = bootstrap_ci([1.0, 2.0], rng, level=0.5)
    assert 1.0 <= lo <= hi <= 2.0
    for bad, needle in (({"resamples": 0}, "resamples"), ({"level": 1.0}, "level")):
        with pytest.raises(ValueError, match=needle):
            bootstrap_ci([1.0, 2.0], rng, **bad)
    with pytest.raises(ValueError, match="finite"):
        bootstrap_ci([1.0, math.nan], rng)


def row(i: int, travel: float, truncated: bool = False) -> EpisodeRow:
    return EpisodeRow(
        episode=i, seed=i, departure=100.0 * i, origin="e", day=0, choices="1-1", station=1,
        station_id="cs1", travel_time=travel, queue_wait=5.0, reason="stuck" if truncated else "charging",
        truncated=truncated, episode_return=0.0 if truncated else 7200.0 / travel, wall_s=0.5,
    )  # fmt: skip


def test_summary_skips_truncated_episodes():
    s = summarize([row(0, 100.0), row(1, 300.0), row(2, 9999.0, truncated=True)], np.random.default_rng(0))
    assert (s.episodes, s.completed, s.truncated) == (3, 2, 1)
    assert s.mean_travel_time == 200.0 and s.median_travel_time == 200.0
    assert 100.0 <= s.ci_low <= 200.0 <= s.ci_high <= 300.0
    assert s.mean_wall_s == 0.5 and s.ci_level == 0.95


# ---------------------------------------------------------------------------------------- writers
def result_of(rows: list[EpisodeRow]) -> EvalResult:
    return EvalResult("greedy", 0, tuple(rows), summarize(rows, np.random.default_rng(0)))


def test_writers_round_trip_and_refuse_to_clobber(tmp_path: Path):
    result = result_of([row(0, 100.0), row(1, 250.5), row(2, 80.0, truncated=True)])
    csv_path = write_episodes_csv(result, tmp_path / "episodes.csv")
    json_path = write_results_json(result, tmp_path / "results.json", config={"evs": 400})
    with open(csv_path, newline="") as f:
        read = list(csv.DictReader(f))
    assert tuple(read[0]) == CSV_FIELDS and len(read) == 3
    assert read[1]["choices"] == "1-1" and float(read[1]["travel_time"]) == 250.5
    assert read[2]["truncated"] == "True"
    data = json.loads(json_path.read_text())
    assert {"agent", "seed", "summary", "episodes", "config"} <= set(data)
    assert data["summary"]["mean_travel_time"] == pytest.approx(175.25) and data["config"] == {"evs": 400}
    assert len(data["episodes"]) == 3
    for write, path in ((write_episodes_csv, csv_path), (write_results_json, json_path)):
        before = path.read_bytes()
        with pytest.raises(FileExistsError, match=path.name):
            write(result_of([row(0, 1.0)]), path)
        assert path.read_bytes() == before
        write(result_of([row(0, 1.0)]), path, overwrite=True)
        assert path.read_bytes() != before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.csv", "results.json"]  # no temp files


def test_results_json_is_strict_when_nothing_completed(tmp_path: Path):
    path = write_results_json(result_of([row(0, 50.0, truncated=True)]), tmp_path / "results.json")
    text = path.read_text()
    assert "NaN" not in text
    s = json.loads(text)["summary"]
    assert s["mean_travel_time"] is None and s["ci_low"] is None and s["truncated"] == 1
