"""The trainer (:mod:`evcd.loops.train`) on the toy dispatch problem: files, curves, resume, refusals.

Real torch, real TensorBoard files; the environment is ``tests/agents/toy_env.py`` (no SUMO), so that
every property of the loop is checked in seconds. ``tests/test_train_script.py`` runs the same loop
through ``scripts/train.py`` on a real SUMO scenario.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from evcd.agents import make_agent
from evcd.env.runners import EpisodeRow, SingleEnvRunner
from evcd.loops.run_files import CHECKPOINTS, RESULTS_JSON, TRAIN_CSV
from evcd.loops.seeds import EVAL_STREAM, TRAIN_STREAM, VALIDATION_STREAM, bootstrap_rng, episode_specs
from evcd.loops.stats import paired_difference
from evcd.loops.train import TrainSettings, train_and_evaluate, training_specs
from evcd.loops.train_state import check_run_dir, restore_training
from evcd.loops.validation import ValidationSettings
from evcd.utils.checkpoint import CheckpointError, load_checkpoint
from evcd.utils.provenance import code_record
from tests.agents.toy_env import ToyDispatchEnv, greedy_travel, optimal_travel
from tests.conftest import run_script

SMALL = {"hidden": (16, 16), "lr": 1e-3, "batch_size": 8, "buffer_size": 200, "gamma": 0.9,
         "learning_starts": 16, "target_update": 20, "exploration_steps": 60, "beta_steps": 100,
         "reward_scale": 0.01}  # fmt: skip
CONFIG = {"agent": "dqn", "learner": {"lr": 1e-3}, "seed": 3, "progress": False}


def learner(seed: int = 3, name: str = "dueling_ddqn"):
    return make_agent(name, 3, np.random.default_rng(seed), **SMALL)


def toy_runners(phase: str) -> SingleEnvRunner:
    return SingleEnvRunner(ToyDispatchEnv())


def greedy():
    return make_agent("greedy", 3, np.random.default_rng(0))


def BASELINES():  # noqa: N802  (a constant's factory: fresh agents per run)
    return {"greedy": greedy()}


def settings(**kw) -> TrainSettings:
    base = {"episodes": 30, "eval_episodes": 12, "seed": 3, "checkpoint_every": 10, "progress": False,
            "resamples": 500}  # fmt: skip
    return TrainSettings(**{**base, **kw})


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


class InterruptedRunner(SingleEnvRunner):
    """Raises ``KeyboardInterrupt`` once ``after`` episodes have ended (a run stopped by the user)."""

    def __init__(self, env, after: int) -> None:
        super().__init__(env)
        self.after, self.count = after, 0

    def run(self, specs, agent, *, on_episode=None, **kw):
        def count(row):
            on_episode(row)
            self.count += 1
            if self.count == self.after:
                raise KeyboardInterrupt

        return super().run(specs, agent, on_episode=count, **kw)


def interrupted_after(episodes: int):
    """Runners whose training phase is interrupted after ``episodes`` episodes."""
    return lambda phase: (
        InterruptedRunner(ToyDispatchEnv(), episodes) if phase == "train" else toy_runners(phase)
    )


# ---------------------------------------------------------------------------------------- statistics
def _row(i: int, seed: int, travel: float, truncated: bool = False) -> EpisodeRow:
    return EpisodeRow(i, seed, 0.0, "", 0, "0", 0, "s0", travel, 0.0, "charging", truncated, 1.0, 0.1)


def test_paired_difference_by_hand():
    agent = [_row(0, 10, 100.0), _row(1, 11, 300.0), _row(2, 12, 50.0, truncated=True), _row(3, 13, 80.0)]
    base = [_row(0, 10, 120.0), _row(1, 11, 250.0), _row(2, 12, 60.0), _row(3, 13, 80.0)]
    p = paired_difference(agent, base, np.random.default_rng(0), resamples=2000)
    # pairs where both charged: (100, 120), (300, 250), (80, 80) -> differences -20, +50, 0
    assert p["pairs"] == 3 and p["mean_difference"] == pytest.approx(10.0)
    assert (p["agent_faster"], p["equal"], p["agent_slower"]) == (1, 1, 1)
    assert p["agent_mean"] == pytest.approx(160.0) and p["baseline_mean"] == pytest.approx(150.0)
    assert -20.0 <= p["ci_low"] <= 10.0 <= p["ci_high"] <= 50.0
    with pytest.raises(ValueError, match="episodes differ"):
        paired_difference(agent, base[::-1], np.random.default_rng(0))


def test_training_and_evaluation_seeds_are_disjoint_streams():
    train = {s.reset_seed for s in episode_specs(0, range(2000), TRAIN_STREAM)}
    evaluation = {s.reset_seed for s in episode_specs(0, range(2000), EVAL_STREAM)}
    assert len(train) == len(evaluation) == 2000 and not train & evaluation


@pytest.mark.parametrize(
    "kw,needle",
    [({"episodes": -1}, "episodes=-1"), ({"eval_episodes": 0}, "eval_episodes=0"), ({"seed": -2}, "seed=-2"),
     ({"checkpoint_every": 1.5}, "checkpoint_every=1.5"), ({"resamples": 0}, "resamples=0")],
)  # fmt: skip
def test_bad_settings_are_named(kw, needle):
    with pytest.raises(ValueError, match=needle):
        settings(**kw)


# ---------------------------------------------------------------------------------------- a whole run
@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """One uninterrupted run of 30 training episodes (checkpoints every 10)."""
    torch.set_num_threads(1)
    run_dir = tmp_path_factory.mktemp("train") / "run"
    agent = learner()
    result = train_and_evaluate(agent, toy_runners, settings(), run_dir, baselines=BASELINES(), config=CONFIG)
    return run_dir, agent, result


@pytest.mark.slow
def test_a_run_writes_every_file(trained):
    run_dir, _agent, _result = trained
    for name in ("train_episodes.csv", "episodes.csv", "baseline_greedy_episodes.csv", "results.json",
                 "learning_curve.png", "checkpoints/latest.json"):  # fmt: skip
        assert (run_dir / name).is_file(), name
    train_rows = read_csv(run_dir / TRAIN_CSV)
    assert [int(r["episode"]) for r in train_rows] == list(range(30))
    assert [int(r["seed"]) for r in train_rows] == [
        s.reset_seed for s in episode_specs(3, range(30), TRAIN_STREAM)
    ]
    eval_rows = read_csv(run_dir / "episodes.csv")
    base_rows = read_csv(run_dir / "baseline_greedy_episodes.csv")
    assert (
        [r["seed"] for r in eval_rows]
        == [r["seed"] for r in base_rows]
        == [str(s.reset_seed) for s in episode_specs(3, range(12), EVAL_STREAM)]
    )
    assert all(len(set(r["choices"].split("-"))) >= 1 for r in base_rows)


def test_results_json_holds_training_evaluation_and_the_paired_comparison(trained):
    run_dir, agent, _result = trained
    data = json.loads((run_dir / RESULTS_JSON).read_text())
    assert {
        "agent",
        "seed",
        "summary",
        "episodes",
        "config",
        "training",
        "baselines",
    } <= set(data)
    t = data["training"]
    transitions = sum(len(r["choices"].split("-")) for r in read_csv(run_dir / TRAIN_CSV))
    assert t["episodes"] == 30 and t["transitions"] == transitions == agent.steps
    assert t["gradient_steps"] == agent.gradient_steps == transitions - SMALL["learning_starts"] + 1
    assert t["target_updates"] == agent.target_updates == agent.gradient_steps // SMALL["target_update"]
    assert t["wall_s"] > 0 and t["transitions_per_second"] > 0
    assert data["agent"] == "dueling_ddqn" and set(data["baselines"]) == {"greedy"}
    assert data["environment"] == "evcd/ChargingNav-v1" and data["code"] == code_record()
    paired = data["baselines"]["greedy"]["paired"]
    agent_t = [float(r["travel_time"]) for r in read_csv(run_dir / "episodes.csv")]
    base_t = [float(r["travel_time"]) for r in read_csv(run_dir / "baseline_greedy_episodes.csv")]
    assert data["baselines"]["greedy"]["summary"]["mean_travel_time"] == pytest.approx(np.mean(base_t))
    assert paired["pairs"] == 12
    assert paired["mean_difference"] == pytest.approx(np.mean(agent_t) - np.mean(base_t))
    assert data["summary"]["mean_travel_time"] == pytest.approx(np.mean(agent_t))
    assert data["config"] == CONFIG


def test_tensorboard_has_the_curves_and_the_config(trained):
    run_dir, _agent, _ = trained
    acc = EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0, "tensors": 0})
    acc.Reload()
    scalars = set(acc.Tags()["scalars"])
    expected = {"charts/travel_time", "charts/episodic_return", "charts/epsilon", "charts/learning_rate",
                "charts/transitions_per_second", "charts/switches", "losses/td_loss", "losses/q_values",
                "eval/travel_time", "eval/greedy_travel_time", "eval/paired_difference_greedy"}  # fmt: skip
    assert expected <= scalars
    travel = acc.Scalars("charts/travel_time")
    assert len(travel) == 30
    rows = read_csv(run_dir / TRAIN_CSV)
    assert [e.value for e in travel] == pytest.approx([float(r["travel_time"]) for r in rows])
    steps = np.cumsum([len(r["choices"].split("-")) for r in rows])
    assert [e.step for e in travel] == list(steps)
    eps = [e.value for e in acc.Scalars("charts/epsilon")]
    assert eps[0] > eps[-1] and eps[-1] == pytest.approx(0.1)
    assert "config/text_summary" in acc.Tags()["tensors"]


def test_a_rule_agent_is_only_evaluated(tmp_path):
    run_dir = tmp_path / "rule"
    agent = make_agent("random", 3, np.random.default_rng(1))
    result = train_and_evaluate(agent, toy_runners, settings(), run_dir, baselines=BASELINES())
    assert result.training["episodes"] == 0 and result.training["transitions"] == 0
    assert not (run_dir / CHECKPOINTS).exists() and not (run_dir / TRAIN_CSV).exists()
    assert result.paired["greedy"]["pairs"] == 12
    rules = {"greedy": greedy(), "queue_aware": queue_aware()}
    same = train_and_evaluate(greedy(), toy_runners, settings(), tmp_path / "greedy", baselines=rules)
    assert same.paired["greedy"]["mean_difference"] == 0.0 and same.baselines["greedy"] is same.evaluation
    assert same.baselines["queue_aware"] is not same.evaluation
    assert set(same.paired) == {"greedy", "queue_aware"}
    assert (tmp_path / "greedy" / "baseline_queue_aware_episodes.csv").is_file()


# ---------------------------------------------------------------------------------------- resume
def _weights(agent) -> dict[str, torch.Tensor]:
    return {**{f"online.{k}": v for k, v in agent.policy.online.state_dict().items()},
            **{f"target.{k}": v for k, v in agent.policy.target.state_dict().items()}}  # fmt: skip


def _without_wall(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.mark.slow
@pytest.mark.parametrize("stop_after", [5, 10, 17, 30])
def test_an_interrupted_run_resumes_to_the_same_weights_and_results(trained, tmp_path, stop_after):
    ref_dir, ref_agent, ref = trained
    run_dir = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(learner(), interrupted_after(stop_after), settings(), run_dir,
                           baselines=BASELINES(), config=CONFIG)  # fmt: skip
    done = (stop_after - 1) // 10 * 10  # the interrupted chunk never reached its checkpoint
    if done == 0:  # no checkpoint yet: nothing to resume, a new run starts afresh
        with pytest.raises(FileNotFoundError, match="no checkpoint"):
            check_run_dir(run_dir, resume=True)
        return
    saved = load_checkpoint(run_dir / CHECKPOINTS)["trainer"]
    assert saved["episodes_done"] == done
    agent = learner(seed=99)  # a different initialisation: everything must come from the checkpoint
    result = train_and_evaluate(agent, toy_runners, settings(), run_dir, baselines=BASELINES(), resume=True,
                                config={**CONFIG, "resume": True, "progress": True})  # fmt: skip
    mine, ref_w = _weights(agent), _weights(ref_agent)
    assert mine.keys() == ref_w.keys() and all(torch.equal(mine[k], ref_w[k]) for k in mine)
    assert agent.steps == ref_agent.steps and agent.gradient_steps == ref_agent.gradient_steps
    assert _without_wall(read_csv(run_dir / TRAIN_CSV)) == _without_wall(read_csv(ref_dir / TRAIN_CSV))
    assert _without_wall(read_csv(run_dir / "episodes.csv")) == _without_wall(
        read_csv(ref_dir / "episodes.csv")
    )
    assert result.paired == ref.paired
    assert result.training["sessions"] == 2 and result.training["episodes_done"] == 30


@pytest.mark.slow
def test_resume_with_other_settings_is_refused(trained, tmp_path):
    run_dir = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(learner(), interrupted_after(12), settings(), run_dir,
                           config=CONFIG)  # fmt: skip
    other = {**CONFIG, "learner": {"lr": 0.5}}
    with pytest.raises(ValueError, match=r"learner\.lr: 0\.001 -> 0\.5"):
        train_and_evaluate(learner(), toy_runners, settings(), run_dir, resume=True, config=other)

    # a setting the run did not have (added to evcd since): refused where it is on, not where it is off
    def added(value):
        return {**CONFIG, "learner": {**CONFIG["learner"], "new_option": value}}

    for on in (True, 1, ["P"], "x"):
        with pytest.raises(ValueError, match=rf"learner\.new_option: '<missing>' -> {re.escape(repr(on))}"):
            restore_training(run_dir, learner(), added(on))
    for off in (False, None, []):
        assert restore_training(run_dir, learner(), added(off)).episodes_done == 10


@pytest.mark.parametrize(("value", "resumes"), [(False, True), (True, False)])
def test_resuming_a_run_made_with_a_removed_setting(tmp_path, value, resumes):
    """A run of an earlier evcd recorded a setting that has left evcd since: at the value that did
    nothing it resumes; where the run used it, it is refused naming the last commit that has it."""
    run_dir = tmp_path / "run"
    old = {**CONFIG, "learner": {**CONFIG["learner"], "rule_prior": value}}
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(learner(), interrupted_after(12), settings(), run_dir, config=old)
    if resumes:
        assert restore_training(run_dir, learner(), CONFIG).episodes_done == 10
    else:
        expected = r"learner\.rule_prior=True: this setting left evcd; commit c467250"
        with pytest.raises(ValueError, match=expected):
            restore_training(run_dir, learner(), CONFIG)


def test_a_run_directory_is_never_reused_or_overwritten(trained, tmp_path):
    run_dir, _, _ = trained
    before = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    with pytest.raises(FileExistsError, match="resume=true"):
        train_and_evaluate(learner(), toy_runners, settings(), run_dir, config=CONFIG)
    with pytest.raises(FileExistsError, match="complete"):
        train_and_evaluate(learner(), toy_runners, settings(), run_dir, resume=True, config=CONFIG)
    assert {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()} == before
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        train_and_evaluate(learner(), toy_runners, settings(), tmp_path / "empty", resume=True)


def test_a_corrupted_checkpoint_is_reported_not_used(tmp_path):
    run_dir = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(learner(), interrupted_after(12), settings(), run_dir)
    ckpt = next((run_dir / CHECKPOINTS).glob("*.pt"))
    data = bytearray(ckpt.read_bytes())
    data[len(data) // 2] ^= 0xFF
    ckpt.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupted"):
        train_and_evaluate(learner(), toy_runners, settings(), run_dir, resume=True)
    ckpt.write_bytes(bytes(data[: len(data) // 3]))
    with pytest.raises(CheckpointError, match="truncated"):
        train_and_evaluate(learner(), toy_runners, settings(), run_dir, resume=True)


def test_a_checkpoint_of_another_observation_size_is_refused(trained, tmp_path):
    run_dir, _, _ = trained
    other = make_agent("dueling_ddqn", 4, np.random.default_rng(0), **SMALL)
    with pytest.raises(CheckpointError, match="observations of size 9"):
        other.load(run_dir)


def test_the_bootstrap_of_the_comparison_is_seeded(trained):
    _run_dir, _, result = trained
    rows_a = result.evaluation.rows
    rows_b = result.baselines["greedy"].rows
    again = paired_difference(rows_a, rows_b, bootstrap_rng(3), 500)
    assert again == result.paired["greedy"]


# ---------------------------------------------------------------------------------------- curves figure
def plot_curves(*args: str) -> subprocess.CompletedProcess:
    return run_script("plot_curves.py", *args, timeout=120)


@pytest.mark.slow
def test_plot_curves_overlays_runs_and_csv_files(trained, tmp_path):
    run_dir, _, _ = trained
    out = tmp_path / "curves.png"
    proc = plot_curves(
        str(run_dir), str(run_dir / "baseline_greedy_episodes.csv"), "--out", str(out), "--reference", "x=1"
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    again = plot_curves(str(run_dir), "--out", str(out))
    assert again.returncode == 2 and "exists" in again.stderr
    bad_calls = [
        ([str(tmp_path)], "no train_episodes.csv"),
        ([str(run_dir), "--label", "a", "--label", "b"], "2 --label for 1 runs"),
        ([str(run_dir), "--reference", "150"], "LABEL=SECONDS"),
    ]
    for bad, needle in bad_calls:
        proc = plot_curves(*bad, "--out", str(tmp_path / "other.png"))
        assert proc.returncode == 2 and needle in proc.stderr, proc.stderr


# ---------------------------------------------------------------------------------------- validation
def queue_aware():
    return make_agent("queue_aware", 3, np.random.default_rng(0), points=1)


def validated_settings(**kw) -> TrainSettings:
    return settings(validation=ValidationSettings(every=10, episodes=8), **kw)


@pytest.fixture(scope="module")
def validated(tmp_path_factory, trained):
    """The run of ``trained`` again, with a validation every 10 training episodes."""
    torch.set_num_threads(1)
    run_dir = tmp_path_factory.mktemp("validated") / "run"
    agent = learner()
    rules = {"greedy": greedy(), "queue_aware": queue_aware()}
    result = train_and_evaluate(agent, toy_runners, validated_settings(), run_dir, baselines=BASELINES(),
                                config=CONFIG, validation_rules=rules)  # fmt: skip
    return run_dir, agent, result


@pytest.mark.slow
def test_the_periodic_validation_does_not_touch_training(trained, validated):
    """A run with validations trains to exactly the weights, rows and evaluation of one without."""
    (plain_dir, plain, plain_result), (run_dir, agent, result) = trained, validated
    assert agent.steps == plain.steps and agent.gradient_steps == plain.gradient_steps
    for a, b in zip(agent.policy.online.parameters(), plain.policy.online.parameters(), strict=True):
        assert torch.equal(a, b)

    def rows(d):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in read_csv(d / TRAIN_CSV)]

    assert rows(run_dir) == rows(plain_dir)
    assert [r.travel_time for r in result.evaluation.rows] == [
        r.travel_time for r in plain_result.evaluation.rows
    ]


@pytest.mark.slow
def test_the_validation_plays_the_same_held_out_episodes_beside_the_rules(validated):
    run_dir, _agent, result = validated
    data = json.loads((run_dir / RESULTS_JSON).read_text())["validation"]
    assert [p["episodes_done"] for p in data["points"]] == [10, 20, 30]
    assert all(len(p["travel_times"]) == 8 for p in data["points"])
    assert set(data["rules"]) == {"greedy", "queue_aware"}
    # the rules ran the validation episodes: greedy's travel times are the toy's greedy ones, and
    # nothing beats the toy's optimum on them
    specs = episode_specs(3, range(8), VALIDATION_STREAM)
    assert data["rules"]["greedy"] == [greedy_travel(s.reset_seed) for s in specs]
    optimum = [optimal_travel(s.reset_seed) for s in specs]
    assert all(o <= t for o, t in zip(optimum, data["rules"]["queue_aware"], strict=True))
    assert all(o <= t for p in data["points"] for o, t in zip(optimum, p["travel_times"], strict=True))
    assert not {s.reset_seed for s in specs} & {
        s.reset_seed for s in episode_specs(3, range(30), TRAIN_STREAM)
    }
    first, last = data["points"][0]["mean"], data["points"][-1]["mean"]
    assert last <= first  # it learns on this problem (30 episodes are few; not worse than at 10)
    acc = EventAccumulator(str(run_dir / "tensorboard"))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"eval/validation_travel_time", "eval/validation_greedy", "eval/validation_queue_aware"} <= tags
    assert [e.step for e in acc.Scalars("eval/validation_travel_time")] == [
        p["transitions"] for p in data["points"]
    ]
    assert result.training["validation_s"] > 0


@pytest.mark.slow
def test_the_checkpoint_of_every_validation_is_kept_and_plays_it_again(trained, validated):
    run_dir = validated[0]
    points = json.loads((run_dir / RESULTS_JSON).read_text())["validation"]["points"]
    kept = sorted(p.name for p in (run_dir / CHECKPOINTS).glob("*.pt"))
    assert kept == [f"ckpt_{p['episodes_done']:07d}.pt" for p in points] == [
        "ckpt_0000010.pt", "ckpt_0000020.pt", "ckpt_0000030.pt"
    ]  # fmt: skip
    # without a validation, the latest alone
    assert [p.name for p in (trained[0] / CHECKPOINTS).glob("*.pt")] == ["ckpt_0000030.pt"]
    specs = episode_specs(3, range(8), VALIDATION_STREAM)
    for point in points:
        agent = learner()
        agent.load_state_dict(
            load_checkpoint(run_dir / CHECKPOINTS / f"ckpt_{point['episodes_done']:07d}.pt")["agent"]
        )
        rows = SingleEnvRunner(ToyDispatchEnv()).run(specs, agent, explore=False, learn=False)
        assert [r.travel_time for r in rows] == point["travel_times"]


@pytest.mark.slow
def test_a_resumed_run_keeps_its_validation_curve(validated, tmp_path):
    run_dir, _agent, _result = validated
    stopped = tmp_path / "run"
    rules = {"greedy": greedy(), "queue_aware": queue_aware()}
    with pytest.raises(KeyboardInterrupt):
        train_and_evaluate(learner(), interrupted_after(15), validated_settings(), stopped,
                           baselines=BASELINES(), config=CONFIG, validation_rules=rules)  # fmt: skip
    train_and_evaluate(learner(), toy_runners, validated_settings(), stopped, baselines=BASELINES(),
                       config=CONFIG, resume=True, validation_rules=rules)  # fmt: skip
    resumed = json.loads((stopped / RESULTS_JSON).read_text())["validation"]
    assert resumed == json.loads((run_dir / RESULTS_JSON).read_text())["validation"]


def test_validation_must_fall_on_the_training_calls():
    with pytest.raises(
        ValueError, match=r"validation.every=15: must be a multiple of train.checkpoint_every=10"
    ):
        settings(validation=ValidationSettings(every=15, episodes=4))


def test_several_training_days_are_played_in_turn_one_call_each():
    specs = training_specs(settings(episodes=50, checkpoint_every=10, rotate_days=3))
    assert [s.options["day"] for s in specs[::10]] == [0, 1, 2, 0, 1]
    assert all(s.options["day"] == specs[10 * (i // 10)].options["day"] for i, s in enumerate(specs))
    plain = training_specs(settings(episodes=50, checkpoint_every=10))
    assert [s.reset_seed for s in specs] == [s.reset_seed for s in plain] and plain[0].options is None


@pytest.mark.slow
def test_rules_played_beside_the_training_give_the_same_run(validated, tmp_path):
    """The validation's rules and the baselines played in a second process: the same validation,
    evaluation and comparison as the run that played them in turn."""
    torch.set_num_threads(1)
    run_dir, _agent, result = validated
    rules = {"greedy": greedy(), "queue_aware": queue_aware()}
    beside = train_and_evaluate(learner(), toy_runners, validated_settings(), tmp_path / "beside",
                                baselines=BASELINES(), config=CONFIG, validation_rules=rules,
                                beside=toy_runners)  # fmt: skip
    dirs = (run_dir, tmp_path / "beside")
    same, other = (_timeless(json.loads((d / RESULTS_JSON).read_text())) for d in dirs)
    assert other["validation"] == same["validation"] and other["baselines"] == same["baselines"]
    assert other["summary"] == same["summary"]
    assert [dataclasses.replace(r, wall_s=0.0) for r in beside.baselines["greedy"].rows] == [
        dataclasses.replace(r, wall_s=0.0) for r in result.baselines["greedy"].rows
    ]
    assert beside.paired == result.paired


def test_a_failure_beside_the_training_is_reported(tmp_path):
    with pytest.raises(RuntimeError, match="the process playing the rules beside the training failed"):
        train_and_evaluate(learner(), toy_runners, settings(episodes=10), tmp_path / "run",
                           baselines=BASELINES(), beside=_no_runner)  # fmt: skip


def _timeless(data):
    """``data`` without its wall times."""
    if isinstance(data, dict):
        return {k: _timeless(v) for k, v in data.items() if "wall" not in k}
    return [_timeless(v) for v in data] if isinstance(data, list) else data


def _no_runner(phase: str):
    raise ValueError(f"no runner for {phase}")
