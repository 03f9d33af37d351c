"""Selecting the best validated policy (:mod:`evcd.loops.best_policy`): which point is best, which
networks are kept and loaded, and a trainer run that evaluates the selected policy while training to
the very weights of a run without selection (real torch on the toy problem; the fleet trainer on a
real SUMO fleet)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from evcd.loops.best_policy import BEST_DIR, keep_if_best, load_best, policy_to_evaluate
from evcd.loops.evaluate import evaluate
from evcd.loops.run_files import CHECKPOINTS, RESULTS_JSON
from evcd.loops.train import train_and_evaluate
from evcd.loops.validation import ValidationPoint, ValidationRecord, ValidationSettings
from evcd.utils.checkpoint import CheckpointError, load_checkpoint
from tests.loops.test_fleet_loop import TWO_EVS
from tests.loops.test_fleet_train import Fleet, _agent, _rules, _same, _weights
from tests.loops.test_fleet_train import _settings as fleet_settings
from tests.loops.test_train import (
    BASELINES,
    CONFIG,
    greedy,
    learner,
    queue_aware,
    settings,
    toy_runners,
    trained,  # noqa: F401  (a fixture: the run without selection)
)

NAN = math.nan
SELECT = ValidationSettings(every=10, episodes=8, select_best=True)


def _point(episodes: int, *times: float) -> ValidationPoint:
    return ValidationPoint(episodes, 10 * episodes, list(times))


def test_the_best_point_has_the_fewest_truncations_then_the_lowest_mean_then_comes_first():
    record = ValidationRecord()
    assert record.best() is None
    record.points = [_point(10, 300.0, 310.0), _point(20, 100.0, NAN), _point(30, 250.0, 260.0),
                     _point(40, 255.0, 255.0), _point(50, NAN, NAN)]  # fmt: skip
    # 20 has the lowest mean of its charged episodes but one truncation; 30 and 40 tie at 255 s
    assert record.best() is record.points[2]
    assert record.to_dict()["best_episodes_done"] == 30
    assert record.points[4].rank() == (2, math.inf)


def test_select_best_needs_a_validation_and_a_boolean():
    with pytest.raises(ValueError, match=r"select_best=true needs a validation.*every > 0"):
        ValidationSettings(every=0, select_best=True)
    with pytest.raises(ValueError, match=r"select_best='yes': must be true or false"):
        ValidationSettings(every=10, select_best="yes")  # type: ignore[arg-type]


def _perturbed(agent, seed: int) -> None:
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in agent.policy.online.parameters():
            p.add_(torch.randn(p.shape, generator=gen))


def test_only_a_new_best_is_kept_and_the_kept_networks_come_back(tmp_path):
    agent, record = learner(), ValidationRecord()
    kept = {}
    for episodes, mean, seed in ((10, 300.0, 1), (20, 200.0, 2), (30, 250.0, 3)):
        _perturbed(agent, seed)
        record.points.append(_point(episodes, mean))
        kept[episodes] = keep_if_best(tmp_path, agent, SELECT, record)
        if episodes == 20:
            best_weights = _weights(agent)
    assert kept == {10: True, 20: True, 30: False}
    assert not _same(_weights(agent), best_weights)
    assert not keep_if_best(tmp_path / "off", agent, ValidationSettings(every=10), record)
    assert not (tmp_path / "off").exists()
    fresh = learner(seed=9)
    assert load_best(tmp_path, fresh, record).episodes_done == 20
    assert _same(_weights(fresh), best_weights)
    # the folder holds the networks only, and scripts/evaluate.py's agent.checkpoint reads it
    saved = load_checkpoint(tmp_path / BEST_DIR)
    assert saved["episodes_done"] == 20 and not {"replay", "optimizer"} & set(saved["agent"])
    other = learner(seed=11)
    other.load(tmp_path / BEST_DIR)
    assert _same(_weights(other), best_weights)
    # without selection the trainer evaluates what it has; a record whose best is not the kept one fails
    assert policy_to_evaluate(tmp_path, fresh, ValidationSettings(every=10), record, 30) == 30
    record.points.append(_point(40, 100.0))
    with pytest.raises(CheckpointError, match="holds the policy after 20 episodes, but the best validation "
                                              "is after 40"):  # fmt: skip
        load_best(tmp_path, fresh, record)
    with pytest.raises(CheckpointError, match="holds no validated policy"):
        load_best(tmp_path / "nothing", fresh, record)


@pytest.fixture(scope="module")
def selected(tmp_path_factory):
    torch.set_num_threads(1)
    run_dir = tmp_path_factory.mktemp("selected") / "run"
    agent = learner()
    rules = {"greedy": greedy(), "queue_aware": queue_aware()}
    result = train_and_evaluate(agent, toy_runners, settings(validation=SELECT), run_dir,
                                baselines=BASELINES(), config=CONFIG, validation_rules=rules)  # fmt: skip
    return run_dir, agent, result


@pytest.mark.slow
def test_a_run_with_select_best_evaluates_its_best_validated_policy(selected, trained):  # noqa: F811
    run_dir, agent, result = selected
    data = json.loads((run_dir / RESULTS_JSON).read_text())
    points = data["validation"]["points"]
    best = min(points, key=lambda p: (sum(t is None for t in p["travel_times"]), p["mean"]))
    assert data["training"]["evaluated_after_episodes"] == best["episodes_done"]
    assert data["validation"]["best_episodes_done"] == best["episodes_done"]
    # the evaluated policy is the one kept in best/: a fresh learner loaded from it plays the same
    fresh = learner(seed=5)
    fresh.load(run_dir / BEST_DIR)
    runner = toy_runners("eval")
    runner.prepare()
    again = evaluate(runner, fresh, 12, 3, progress=False, resamples=200)
    assert [r.travel_time for r in again.rows] == [r.travel_time for r in result.evaluation.rows]
    # training is untouched: the last checkpoint holds the weights of the run without selection
    _plain_dir, plain, _ = trained
    last = load_checkpoint(run_dir / CHECKPOINTS)["agent"]["online"]
    assert _same(last, _weights(plain))
    assert _same(_weights(agent), _weights(fresh))
    # here the selection matters: the validations tie, so the earliest is kept, not the last weights
    assert best["episodes_done"] < 30 and not _same(last, _weights(fresh))


@pytest.mark.slow
def test_a_fleet_run_with_select_best_evaluates_the_kept_policy(make_small_fleet, tmp_path, one_torch_thread):
    env = make_small_fleet(TWO_EVS, max_travel_time=900.0)
    fleet = Fleet(train=env, eval=env, validation=env)
    base = fleet_settings(every=2)
    select = dataclasses.replace(base, validation=ValidationSettings(2, 1, select_best=True))
    agent, plain = _agent(env), _agent(env)
    train_and_evaluate(agent, fleet, select, tmp_path / "a", validation_rules=_rules(env, "greedy"))
    train_and_evaluate(plain, fleet, base, tmp_path / "b", validation_rules=_rules(env, "greedy"))
    data = json.loads((tmp_path / "a" / RESULTS_JSON).read_text())
    assert data["training"]["evaluated_after_episodes"] == data["validation"]["best_episodes_done"]
    kept = load_checkpoint(tmp_path / "a" / BEST_DIR)
    assert _same(_weights(agent), kept["agent"]["online"])
    assert _same(load_checkpoint(tmp_path / "a" / CHECKPOINTS)["agent"]["online"], _weights(plain))
    assert np.isfinite(data["summary"]["guided_travel"])
