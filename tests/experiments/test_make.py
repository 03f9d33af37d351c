"""An experiment's worlds from Python (evcd.experiments): ``gymnasium.make(..., experiment=, split=)``
and the fleet's ``parallel_env`` (and its AEC form) play the very episodes ``scripts/train.py``
plays (real Hydra composition, real SUMO on the script grid), the checks of Gymnasium and PettingZoo
pass, and bad input is refused by name before SUMO starts."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import api_test, parallel_api_test

from evcd import ENV_ID, experiments
from evcd.agents import make_agent_for_env
from evcd.env.runners import FleetRunner
from evcd.experiments import (
    SPLITS,
    compose_experiment,
    experiment_names,
    make_sweep_env,
    make_vector_env,
    parallel_env,
    split_days,
)
from evcd.loops.fleet import fleet_spec
from evcd.loops.seeds import episode_spec
from evcd.scenario.scenario import JURONG_WEST
from tests.conftest import run_script
from tests.scripts.test_train_fleet_script import FLEET

#: The fleet experiment on the script grid, as the fleet script tests run it (one day per split).
FLEET_WORLD = [o for o in FLEET if o != "experiment=fleet"]


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_every_experiment_composes_and_each_split_has_its_days() -> None:
    assert {"peak", "table", "paper", "fleet"} <= set(experiment_names())
    for name in experiment_names():
        cfg = compose_experiment(name)
        days = {split: split_days(cfg, split, seed=0) for split in SPLITS}
        assert not set(days["train"]) & set(days["eval"]), name
        assert not set(days["tuning"]) & set(days["train"] + days["eval"]), name
    cfg = compose_experiment("peak")
    assert split_days(cfg, "eval", seed=3) == (101, 102) == tuple(cfg.eval.days)
    # the fleet: each run seed its own held-out days, one per evaluation episode
    fleet = compose_experiment("fleet")
    assert split_days(fleet, "eval", seed=0) == (106, 107, 108, 109, 110)
    assert split_days(fleet, "eval", seed=1) == (111, 112, 113, 114, 115)


@pytest.mark.slow
def test_the_readme_world_from_gymnasium(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # the shipped scenario is found from any working directory
    env = gymnasium.make(ENV_ID, experiment="peak", split="train", cache_dir=tmp_path)  # no SUMO yet
    assert env.unwrapped.scenario.root == JURONG_WEST
    world = env.unwrapped.config
    assert world.demand_seeds == (0, 3) and world.departure_window == (25200.0, 36000.0)
    assert world.reward == "time" and world.demand_config.evs == 400 and world.normalize_obs
    raw = gymnasium.make(ENV_ID, experiment="peak", split="eval", normalize_obs=False, evs=300)
    assert raw.unwrapped.config.demand_seeds == (101, 102) and not raw.unwrapped.config.normalize_obs
    assert raw.unwrapped.config.demand_config.evs == 300
    # without an experiment: the environment of the arguments given, normalised
    plain = gymnasium.make(ENV_ID, evs=200)
    assert plain.unwrapped.config.demand_seeds == (0,) and plain.unwrapped.config.normalize_obs


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"experiment": "peek"}, "experiment='peek': unknown; the experiments: fleet, paper, peak, table"),
        ({"experiment": "peak", "split": "test"}, "split='test': must be one of train, tuning, eval"),
        (
            {"experiment": "fleet"},
            "experiment='fleet' is a fleet-task experiment: make it with evcd.experiments.parallel_env",
        ),
        ({"split": "eval"}, "give experiment=... too"),
        ({"experiment": "peak", "run_seed": -1}, "run_seed"),
        ({"experiment": "peak", "evs": -3}, "evs"),
    ],
)
def test_bad_experiments_are_refused_by_name(kwargs, needle) -> None:
    with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        gymnasium.make(ENV_ID, **kwargs)


def test_a_single_target_experiment_is_not_a_fleet() -> None:
    with pytest.raises(ValueError, match="experiment='peak' is a single-task experiment"):
        parallel_env(experiment="peak")


@pytest.mark.slow
def test_gymnasium_plays_the_episodes_of_the_scripts_evaluation(script_overrides, tmp_path) -> None:
    """``split="eval"`` of run seed 2 is the evaluation ``train.py experiment=peak seed=2`` plays: a
    rule's travel times equal, episode by episode (the script on the single environment, as a
    Gymnasium user plays it)."""
    run = tmp_path / "run"
    overrides = ["experiment=peak", "agent=greedy", "seed=2", "engine=single", "eval.episodes=3"]
    proc = run_script("train.py", *script_overrides, *overrides, "eval.baselines=[]", f"hydra.run.dir={run}")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    script = _rows(run / "episodes.csv")
    env = gymnasium.make(ENV_ID, experiment="peak", split="eval", run_seed=2, overrides=script_overrides)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert not [w for w in caught if "WARN" in str(w.message)], [str(w.message) for w in caught]
        greedy = make_agent_for_env("greedy", env.unwrapped, np.random.default_rng(0))
        for i, row in enumerate(script):
            spec = episode_spec(2, i)
            obs, info = env.reset(seed=spec.reset_seed)
            assert spec.reset_seed == int(row["seed"]) and info["day"] == int(row["day"])
            greedy.begin_episode()
            done = False
            while not done:
                action = greedy.act(obs)
                obs, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
            assert info["travel_time"] == pytest.approx(float(row["travel_time"]), abs=1e-9), i
            assert info["reason"] == row["reason"]
    finally:
        env.close()


@pytest.mark.slow
def test_the_fleet_experiment_plays_the_scripts_evaluation_episodes(script_overrides, tmp_path) -> None:
    run = tmp_path / "run"
    proc = run_script("train.py", *script_overrides, *FLEET, "agent=queue_aware", "eval.episodes=2",
                      "eval.baselines=[]", f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    script = _rows(run / "fleet_episodes.csv")
    env = parallel_env(experiment="fleet", split="eval", overrides=[*script_overrides, *FLEET_WORLD])
    assert env.config.demand_seeds == (1,) and env.guided_share == 1.0 and env.config.normalize_obs
    with FleetRunner(env) as runner:  # closes the fleet's simulation
        parallel_api_test(env, num_cycles=200)
        rule = make_agent_for_env("queue_aware", env, np.random.default_rng(0))
        played = runner.run([fleet_spec(0, i, len(env.days)) for i in range(2)], rule)
    aec = experiments.env(experiment="fleet", split="eval", overrides=[*script_overrides, *FLEET_WORLD])
    try:
        assert aec.unwrapped.config == env.config
        api_test(aec, num_cycles=100)
    finally:
        aec.close()
    assert [ep.row()["guided_travel"] for ep in played] == pytest.approx(
        [float(r["guided_travel"]) for r in script], abs=1e-9
    )


@pytest.mark.slow
def test_the_subprocess_vector_env_takes_an_experiment(script_overrides) -> None:
    envs = make_vector_env(2, experiment="peak", split="eval", overrides=script_overrides)
    try:
        obs, infos = envs.reset(seed=[episode_spec(0, i).reset_seed for i in range(2)])
        assert obs.shape == (2, 3 * 3) and set(infos["day"]) <= {101, 102}
        assert (obs[:, :3] < 50).all()  # D in km: normalised by default
    finally:
        envs.close()


@pytest.mark.parametrize("size", [0, -2, 1.5, "2"])
def test_a_vector_env_of_a_bad_size_is_refused_before_workers_start(size) -> None:
    with pytest.raises(ValueError, match="num_envs"):
        make_vector_env(size, experiment="peak")


def test_the_sweep_vector_env_takes_an_experiment(script_overrides) -> None:
    vec = make_sweep_env(3, experiment="peak", split="eval", overrides=script_overrides)
    try:
        assert vec.env.config.demand_seeds == (101, 102) and vec.env.config.normalize_obs
        obs, _ = vec.reset(seed=1)
        assert obs.shape == (3, 9) and (obs[:, :3] < 50).all()
        for _ in range(5):
            obs, *_ = vec.step(np.zeros(3, dtype=np.int64))
    finally:
        vec.close()
    with pytest.raises(ValueError, match="num_envs"):
        make_sweep_env(0, experiment="peak")
