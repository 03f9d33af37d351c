"""The one trainer (train_and_evaluate) on a hand-built fleet's runners (real SUMO, real torch): its
files, the paired evaluation, the validation that does not touch the weights, and an interrupted run
that resumes to the weights of an uninterrupted one."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from evcd.agents import make_agent_for_env
from evcd.agents.dqn import DQNConfig
from evcd.env.runners import FleetRunner
from evcd.loops.fleet import FleetTrainState
from evcd.loops.train import TrainSettings, train_and_evaluate
from evcd.loops.validation import ValidationSettings
from evcd.utils.checkpoint import CheckpointError, load_checkpoint, state_sha256
from tests.loops.test_fleet_loop import TWO_EVS

CONFIG = DQNConfig(
    hidden=(16, 16),
    lr=3e-3,
    batch_size=16,
    gamma=0.9,
    learning_starts=20,
    target_update=50,
    exploration_steps=40,
    reward_scale=10.0,
    loss="huber",
)


class Fleet(dict):
    """Each phase's fleet env; called with a phase, its runner (what ``train_and_evaluate`` takes)."""

    def __call__(self, phase: str) -> FleetRunner:
        return FleetRunner(self[phase])


@pytest.fixture
def fleet(make_small_fleet) -> Fleet:
    env = make_small_fleet(TWO_EVS, max_travel_time=900.0)
    return Fleet(train=env, eval=env, validation=env)


def _agent(env: Any, name: str = "dueling_ddqn", config: DQNConfig = CONFIG) -> Any:
    return make_agent_for_env(name, env, np.random.default_rng(7), config=config)


def _rules(env: Any, *names: str) -> dict[str, Any]:
    return {n: make_agent_for_env(n, env, np.random.default_rng(1)) for n in names}


def _settings(every: int = 0, episodes: int = 6) -> TrainSettings:
    return TrainSettings(
        episodes=episodes,
        eval_episodes=2,
        seed=3,
        checkpoint_every=2,
        progress=False,
        resamples=200,
        validation=ValidationSettings(every, 1),
    )


def _weights(agent: Any) -> dict[str, torch.Tensor]:
    return agent.state_dict()["online"]


def _same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_a_fleet_run_writes_its_files_and_pairs_every_rule_on_the_same_episodes(
    fleet, tmp_path, one_torch_thread, caplog
) -> None:
    env = fleet["train"]
    agent = _agent(env)
    run = tmp_path / "run"
    result = train_and_evaluate(
        agent,
        fleet,
        _settings(every=2),
        run,
        baselines=_rules(env, "greedy", "queue_aware"),
        config={"seed": 3},
        validation_rules=_rules(env, "greedy"),
    )
    for name in (
        "train_fleet_episodes.csv",
        "fleet_episodes.csv",
        "baseline_greedy_fleet_episodes.csv",
        "baseline_queue_aware_fleet_episodes.csv",
        "results.json",
        "learning_curve.png",
        "fleet_trace.png",
    ):
        assert (run / name).stat().st_size > 0, name
    train = _csv(run / "train_fleet_episodes.csv")
    assert [int(r["episode"]) for r in train] == list(range(6))
    data = json.loads((run / "results.json").read_text())
    assert data["task"] == "fleet" and data["agent"] == "dueling_ddqn" and data["config"] == {"seed": 3}
    t = data["training"]
    assert t["episodes_done"] == 6 and t["transitions"] == sum(int(r["transitions"]) for r in train)
    assert t["gradient_steps"] > 0 and agent.stats()["gradient_steps"] == t["gradient_steps"]
    assert t["policy_sha256"] == state_sha256(agent.policy_state_dict())  # the evaluated policy's
    # validation after 2, 4 and 6 episodes on the same episode, greedy once beside it
    points = data["validation"]["points"]
    assert [p["episodes_done"] for p in points] == [2, 4, 6] and list(data["validation"]["rules"]) == [
        "greedy"
    ]
    # the evaluation: the agent's mean is the mean of its episodes; the rules on the same episodes
    rows = _csv(run / "fleet_episodes.csv")
    # one day, every EV guided: the two evaluation episodes are one episode played twice, and the
    # run says so (in its summary and in a warning)
    assert rows[0]["guided_travel"] == rows[1]["guided_travel"]
    assert data["summary"]["episodes"] == 2 and data["summary"]["distinct_episodes"] == 1
    assert any("only 1 of 2 fleet episodes differ" in r.getMessage() for r in caplog.records)
    assert data["summary"]["guided_travel"] == pytest.approx(
        np.mean([float(r["guided_travel"]) for r in rows])
    )
    for rule in ("greedy", "queue_aware"):
        base = _csv(run / f"baseline_{rule}_fleet_episodes.csv")
        assert [(r["day"], r["guided"]) for r in base] == [(r["day"], r["guided"]) for r in rows]
        paired = data["baselines"][rule]["paired"]["guided_travel"]
        differences = [
            float(a["guided_travel"]) - float(b["guided_travel"]) for a, b in zip(rows, base, strict=True)
        ]
        assert paired["pairs"] == 2 and paired["mean_difference"] == pytest.approx(np.mean(differences))
        assert set(data["baselines"][rule]["paired"]) == {"guided_travel", "all_travel"}
    assert result.paired["greedy"]["guided_travel"]["mean_difference"] == pytest.approx(
        data["baselines"]["greedy"]["paired"]["guided_travel"]["mean_difference"]
    )
    events = EventAccumulator(str(run / "tensorboard")).Reload()
    tags = set(events.Tags()["scalars"])
    assert {
        "charts/guided_travel",
        "charts/all_travel",
        "charts/switches",
        "charts/epsilon",
        "losses/td_loss",
        "eval/validation_travel_time",
        "eval/validation_greedy",
        "eval/travel_time",
        "eval/paired_difference_queue_aware",
    } <= tags
    assert len(events.Scalars("charts/guided_travel")) == 6  # herding: NaN with 2 EVs (bins of >= 4)
    assert "charts/herding" not in tags
    # a finished run is never entered again
    with pytest.raises(FileExistsError, match="already holds"):
        train_and_evaluate(_agent(env), fleet, _settings(), run)
    with pytest.raises(FileExistsError, match="complete"):
        train_and_evaluate(_agent(env), fleet, _settings(), run, resume=True)


@pytest.mark.slow
def test_the_validation_does_not_change_the_weights(fleet, tmp_path, one_torch_thread) -> None:
    env = fleet["train"]
    with_it, without = _agent(env), _agent(env)
    train_and_evaluate(
        with_it, fleet, _settings(every=2), tmp_path / "a", validation_rules=_rules(env, "queue_aware")
    )
    train_and_evaluate(without, fleet, _settings(every=0), tmp_path / "b")
    assert _same(_weights(with_it), _weights(without))
    a = _csv(tmp_path / "a" / "train_fleet_episodes.csv")
    b = _csv(tmp_path / "b" / "train_fleet_episodes.csv")
    assert [r["guided_travel"] for r in a] == [r["guided_travel"] for r in b]


@pytest.mark.slow
def test_an_interrupted_fleet_run_resumes_to_the_weights_of_an_uninterrupted_one(
    fleet, tmp_path, one_torch_thread
) -> None:
    env = fleet["train"]
    whole = _agent(env)
    train_and_evaluate(
        whole,
        fleet,
        _settings(every=2),
        tmp_path / "whole",
        config={"seed": 3},
        validation_rules=_rules(env, "greedy"),
    )
    steps = [int(r["transitions"]) for r in _csv(tmp_path / "whole" / "train_fleet_episodes.csv")]
    at = steps[0] + steps[1] + steps[2] // 2 + 1  # in the middle of the third episode (checkpoint after 2)
    run = tmp_path / "cut"
    cut = _agent(env)
    observe, calls = cut.observe, [0]

    def interrupted(*args: Any, **kwargs: Any) -> None:
        calls[0] += 1
        if calls[0] == at:
            raise KeyboardInterrupt
        observe(*args, **kwargs)

    cut.observe = interrupted  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(
            cut, fleet, _settings(every=2), run, config={"seed": 3}, validation_rules=_rules(env, "greedy")
        )
    saved = load_checkpoint(run / "checkpoints")
    assert saved["format"] == FleetTrainState.FORMAT and saved["trainer"]["episodes_done"] == 2
    assert not (run / "results.json").exists()
    with pytest.raises(ValueError, match="seed: 3 -> 4"):
        train_and_evaluate(_agent(env), fleet, _settings(every=2), run, resume=True, config={"seed": 4})
    resumed = _agent(env)
    train_and_evaluate(
        resumed,
        fleet,
        _settings(every=2),
        run,
        resume=True,
        config={"seed": 3},
        validation_rules=_rules(env, "greedy"),
    )
    assert _same(_weights(resumed), _weights(whole))
    a = json.loads((tmp_path / "whole" / "results.json").read_text())
    b = json.loads((run / "results.json").read_text())
    assert b["training"]["sessions"] == 2 and a["training"]["transitions"] == b["training"]["transitions"]
    assert a["summary"]["guided_travel"] == b["summary"]["guided_travel"]
    assert a["validation"]["points"] == b["validation"]["points"]


def test_a_single_target_checkpoint_is_not_resumed_as_a_fleet_run(
    fleet, tmp_path, make_env, one_torch_thread
) -> None:
    """The two trainers' checkpoints differ in format: resuming one as the other stops with one line."""
    single = make_env()
    # learns from its first transitions: a learner without a gradient step is refused before evaluation
    config = dataclasses.replace(CONFIG, learning_starts=4, batch_size=4)
    agent = make_agent_for_env("dqn", single, np.random.default_rng(0), config=config)
    run = tmp_path / "run"
    settings = TrainSettings(episodes=2, eval_episodes=1, seed=0, checkpoint_every=1, progress=False)
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(agent, _interrupt_eval(single), settings, run)
    with pytest.raises(CheckpointError, match=r"expected 'evcd\.fleet_train/1'"):
        train_and_evaluate(_agent(fleet["train"]), fleet, _settings(), run, resume=True)


def _interrupt_eval(env: Any) -> Any:
    """Runners whose evaluation phase is interrupted (training ran and checkpointed)."""
    from evcd.env.runners import make_runner

    def runners(phase: str) -> Any:
        runner = make_runner(env, "single", 1)
        if phase == "eval":
            runner.prepare = _interrupt  # type: ignore[method-assign]
        return runner

    return runners


def _interrupt() -> None:
    raise KeyboardInterrupt
