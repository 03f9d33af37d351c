"""``scripts/train.py experiment=fleet`` end to end (real Hydra, real SUMO on a generated grid, real
torch), the trained policy through ``scripts/evaluate.py task=fleet``, and the bad settings that stop
before SUMO starts."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from evcd.agents import agent_names, make_agent_for_env
from evcd.env.fleet import FleetEnv
from evcd.experiments.worlds import fleet_kwargs
from evcd.utils.checkpoint import load_checkpoint
from tests.conftest import compose_config, run_refusals, run_script, shared_folder

pytestmark = pytest.mark.slow  # every test here takes seconds

#: A fleet on the script grid (as the evaluate script's tests): charging EVs departing 06:00-07:00,
#: one day per use.
FLEET = [
    "experiment=fleet",
    "evs=300",
    "scenario.demand.charging_share=0.6",
    "env.departure_window=[21600,25200]",
    "days.train=[0]",
    "days.tuning=[2]",
    "days.evaluation=[1]",
]
#: A tiny learner and run.
TINY = [
    "learner.hidden=[16,16]",
    "learner.learning_starts=8",
    "learner.batch_size=8",
    "learner.target_update=20",
    "learner.exploration_steps=20",
    "train.episodes=2",
    "train.checkpoint_every=1",
    "train.validation.every=2",
    "train.validation.episodes=1",
    "eval.episodes=1",
    "eval.baselines=[greedy,reservation]",
    "eval.bootstrap_resamples=200",
]


@pytest.fixture(scope="module")
def small(script_overrides) -> list[str]:
    return [*script_overrides, *FLEET, *TINY]


def test_the_fleet_experiment_composes_and_builds_every_fleet_dispatcher(script_overrides):
    cfg = compose_config("train", "experiment=fleet")
    assert (cfg.task, cfg.regime, cfg.fleet.guided_share, cfg.env.reward) == ("fleet", "fleet", 1.0, "time")
    assert list(cfg.env.departure_window) == [25200.0, 36000.0] and cfg.agent.name == "dueling_ddqn"
    assert cfg.evs == 600 and list(cfg.train.validation.rules) == ["queue_aware", "central"]
    assert set(cfg.eval.baselines) == {"greedy", "queue_aware", "reservation", "central"}
    assert compose_config("train").task == "single"
    cfg = compose_config("train", *script_overrides, *FLEET)
    env = FleetEnv(**fleet_kwargs(cfg))  # no SUMO
    assert env.config.demand_seeds == (0,) and env.config.departure_window == (21600.0, 25200.0)
    for name in agent_names("fleet"):
        params = OmegaConf.to_container(
            compose_config("train", *script_overrides, *FLEET, f"agent={name}").agent
        )
        assert params.pop("name") == name
        params.pop("checkpoint", None)
        assert make_agent_for_env(name, env, np.random.default_rng(0), **params).name == name


def test_train_a_fleet_then_evaluate_its_policy(small, script_overrides, tmp_path):
    run = tmp_path / "run"
    proc = run_script(
        "train.py", *small, "agent=dqn", "train.validation.select_best=true", f"hydra.run.dir={run}"
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-3000:]
    for name in (
        "train_fleet_episodes.csv",
        "fleet_episodes.csv",
        "baseline_greedy_fleet_episodes.csv",
        "baseline_reservation_fleet_episodes.csv",
        "learning_curve.png",
        "fleet_trace.png",
    ):
        assert (run / name).stat().st_size > 0, name
    data = json.loads((run / "results.json").read_text())
    assert data["task"] == "fleet" and data["config"]["regime"] == "fleet"
    assert data["training"]["episodes_done"] == 2 and data["training"]["transitions"] > 0
    assert [p["episodes_done"] for p in data["validation"]["points"]] == [2]
    # select_best reaches the trainer: its one validation's policy is kept and evaluated
    assert data["training"]["evaluated_after_episodes"] == 2 and (run / "best" / "latest.json").is_file()
    assert set(data["validation"]["rules"]) == {"queue_aware", "central"}
    assert set(data["baselines"]) == {"greedy", "reservation"}
    assert "vs reservation, guided_travel on the same 1 episodes" in log
    assert load_checkpoint(run / "checkpoints")["format"] == "evcd.fleet_train/1"
    with open(run / "fleet_episodes.csv", newline="") as f:
        (row,) = csv.DictReader(f)
    assert int(row["day"]) == 1  # the held-out day
    # the trained policy through evaluate.py on the same evaluation episode: the same result
    out = tmp_path / "eval"
    proc = run_script(
        "evaluate.py",
        *script_overrides,
        "task=fleet",
        "evs=300",
        "scenario.demand.charging_share=0.6",
        "env.departure_window=[21600,25200]",
        "env.demand_seeds=[1]",
        "episodes=1",
        "agent=dqn",
        f"agent.checkpoint={run / 'best'}",  # the selected policy: the networks alone
        f"hydra.run.dir={out}",
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    again = json.loads((out / "results.json").read_text())
    assert again["summary"]["guided_travel"] == pytest.approx(data["summary"]["guided_travel"])
    # its own world (read from the run's checkpoint) and held-out day: nothing to warn about
    assert again["trained_world"] == {"differences": [], "training_days": [], "tuning_days": [],
                                      "forecast_days": None}  # fmt: skip
    # a finished run is not resumed, nor overwritten
    proc = run_script("train.py", *small, "agent=dqn", "resume=true", f"hydra.run.dir={run}")
    assert proc.returncode == 2 and "that run is complete" in proc.stdout + proc.stderr


def test_a_rule_is_evaluated_on_the_fleet_without_training(small, tmp_path):
    run = tmp_path / "run"
    proc = run_script(
        "train.py", *small, "agent=central", "eval.baselines=[queue_aware]", f"hydra.run.dir={run}"
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert data["training"]["episodes"] == 0 and not (run / "train_fleet_episodes.csv").exists()
    assert data["baselines"]["queue_aware"]["paired"]["guided_travel"]["pairs"] == 1


def test_the_clairvoyant_bound_is_played_where_a_rule_is(small, tmp_path):
    """``agent=fleet_bound``: each evaluation episode read, planned and the plan played; results.json
    holds the played plan as the job's summary and the bound per episode, paired with the baselines."""
    run = tmp_path / "run"
    proc = run_script("train.py", *small, "agent=fleet_bound", "agent.time_limit_s=2",
                      "eval.baselines=[greedy]", f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert data["agent"] == "fleet_bound" and data["training"]["episodes"] == 0
    (episode,) = data["fleet_bound"]["episodes"]
    assert episode["status"] in ("optimal", "feasible") and episode["day"] == 1
    assert episode["played"] == data["summary"]["guided_travel"] == data["episodes"][0]["guided_travel"]
    assert episode["bound"] <= episode["model"] and data["fleet_bound"]["settings"]["time_limit_s"] == 2.0
    assert data["baselines"]["greedy"]["paired"]["guided_travel"]["pairs"] == 1


def test_each_seed_plays_its_own_evaluation_days_in_turn(small, tmp_path):
    # day_per_seed on the fleet: seed 1 with 2 episodes takes the block days[2:4] of [1, 4, 7] (wrapping
    # round), one day per episode, so at guided_share 1 its two episodes are two distinct episodes
    run = tmp_path / "run"
    proc = run_script("train.py", *small, "agent=greedy", "eval.baselines=[queue_aware]", "eval.episodes=2",
                      "eval.day_per_seed=true", "days.evaluation=[1,4,7]", "seed=1",
                      f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert [e["day"] for e in data["episodes"]] == [7, 1]
    assert data["summary"]["distinct_episodes"] == 2
    base = list(csv.DictReader((run / "baseline_queue_aware_fleet_episodes.csv").open()))
    assert [int(r["day"]) for r in base] == [7, 1]
    assert "only 1 of 2" not in proc.stdout + proc.stderr


#: Fleet training settings (over :data:`FLEET` and :data:`TINY`) train.py refuses before SUMO starts, and
#: what its message says.
BAD_FLEET_TRAINING = [
    (["experiment=peak", "task=fleet"], "task=fleet with experiment regime 'peak'"),
    (["task=single"], "regime 'fleet' is the fleet's: it needs task=fleet"),
    (["agent=hindsight"], "agent 'hindsight' is not an agent of task=fleet"),
    (["agent=fleet_bound", "agent.time_limit_s=0"], "time_limit_s=0: must be a finite number > 0"),
    (["agent=fleet_bound", "agent.workers=0"], "workers=0: must be an integer >= 1"),
    (["eval.baselines=[dqn]"], "eval.baselines: 'dqn' is not a rule"),
    (["train.validation.rules=[dueling_ddqn]"], "train.validation.rules: 'dueling_ddqn' is not a rule"),
    (["fleet.guided_share=0"], "guided_share=0"),
    (["fleet.guided_share=1.5"], "guided_share=1.5"),
    (["env.protocol=paper"], "env.protocol=paper is for the single target"),
    (["train.validation.days=[0]"], "train.validation.days share [0]"),
    (["agent.checkpoint=somewhere"], "agent.checkpoint is for scripts/evaluate.py"),
    (["env.departure_window=[3600,3660]"], "nothing to guide"),
    (
        ["train.checkpoint_every=2", "train.validation.every=3"],
        "must be a multiple of train.checkpoint_every",
    ),
]


@pytest.fixture(scope="module")
def refused(small: list[str], tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_FLEET_TRAINING` run by train.py in one process (:func:`run_refusals`),
    each into its own run directory."""
    root = shared_folder(tmp_path_factory, "train_fleet_script_refused")
    cases = [[*small, *overrides, f"hydra.run.dir={root / f'run{i}'}"]
             for i, (overrides, _) in enumerate(BAD_FLEET_TRAINING)]  # fmt: skip
    return root, run_refusals("train.py", cases, root)


@pytest.mark.parametrize(
    "case", range(len(BAD_FLEET_TRAINING)), ids=[" ".join(o) for o, _ in BAD_FLEET_TRAINING]
)
def test_bad_fleet_training_settings_stop_before_sumo(refused, case):
    root, runs = refused
    code, log = runs[case]
    assert code == 2, log[-2000:]
    assert BAD_FLEET_TRAINING[case][1] in log
    assert "simulating a background day" not in log and not any((root / f"run{case}").glob("*.csv"))
