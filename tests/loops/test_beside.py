"""A learner's rules played beside its training (:mod:`evcd.loops.beside`), on real SUMO: the rows they
play in turn, and a second process that fails is reported."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.env import ChargingNavEnv
from evcd.loops.beside import RulesBeside, RunnerRecipe, rule_episodes
from evcd.loops.seeds import baseline_rng
from evcd.loops.train import TrainSettings, train_and_evaluate
from evcd.loops.validation import ValidationSettings
from tests.conftest import GRID_ENV

SETTINGS = TrainSettings(episodes=8, eval_episodes=6, seed=1, checkpoint_every=4, progress=False,
                         resamples=200, validation=ValidationSettings(every=4, episodes=4))  # fmt: skip


def _timeless(rows):
    return [dataclasses.replace(r, wall_s=0.0) for r in rows]


@pytest.mark.slow
def test_rules_beside_the_training_play_the_rows_they_play_in_turn(grid_env_dir, env_cache, tmp_path):
    kwargs = {"scenario": grid_env_dir, "cache_dir": env_cache, **GRID_ENV}
    recipe = RunnerRecipe({phase: kwargs for phase in ("train", "eval", "validation")}, "batched", 4)
    env = ChargingNavEnv(**kwargs)

    def run(beside, name):
        learner = make_agent_for_env("dqn", env, np.random.default_rng(1), hidden=[8], batch_size=4,
                                     learning_starts=4)  # fmt: skip
        rules = {"greedy": make_agent_for_env("greedy", env, baseline_rng(1))}
        bases = {r: make_agent_for_env(r, env, baseline_rng(1)) for r in ("greedy", "random")}
        return train_and_evaluate(learner, recipe, SETTINGS, tmp_path / name, baselines=bases,
                                  validation_rules=rules, beside=beside)  # fmt: skip

    in_turn, beside = run(None, "in_turn"), run(recipe, "beside")
    assert rule_episodes(SETTINGS, {"greedy": None}, {"greedy": None, "random": None}) == 4 + 2 * 6
    for name in ("greedy", "random"):
        assert _timeless(beside.baselines[name].rows) == _timeless(in_turn.baselines[name].rows)
        assert beside.paired[name] == in_turn.paired[name]
    assert _timeless(beside.evaluation.rows) == _timeless(in_turn.evaluation.rows)
    assert beside.training["policy_sha256"] == in_turn.training["policy_sha256"]
    assert len({r.travel_time for r in in_turn.baselines["random"].rows}) > 1  # real, varied episodes


def test_a_second_process_that_fails_is_named_with_its_output(tmp_path):
    side = RulesBeside(_no_runner, SETTINGS, {"greedy": None}, {})
    try:
        with pytest.raises(RuntimeError, match=r"(?s)failed \(exit 1\) before its validation.*no runner for"):
            side.validation_rules()
    finally:
        side.close()


def _no_runner(phase: str):
    raise ValueError(f"no runner for {phase}")


def _slow_runner(phase: str):
    time.sleep(120)


TRAINER = """
import sys, time
from evcd.loops.beside import RulesBeside
from tests.loops.test_beside import SETTINGS, _slow_runner
side = RulesBeside(_slow_runner, SETTINGS, {"greedy": None}, {})
print(side.out, side._process.pid, flush=True)
time.sleep(120)
"""


def test_a_killed_trainer_leaves_no_process_and_no_files_behind():
    trainer = subprocess.Popen([sys.executable, "-c", TRAINER], stdout=subprocess.PIPE, text=True,
                               cwd=Path(__file__).resolve().parents[2])  # fmt: skip
    out, pid = trainer.stdout.readline().split()
    assert Path(out).is_dir()
    trainer.kill()
    trainer.wait()
    deadline = time.monotonic() + 20
    while (Path(out).exists() or _alive(int(pid))) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not Path(out).exists() and not _alive(int(pid))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}").exists() and "Z" not in Path(f"/proc/{pid}/stat").read_text().split()[2]
