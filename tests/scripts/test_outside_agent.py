"""An agent written outside evcd (examples/outside_agent/evcd_tiny_learner.py) plugs in through the public
registry: installed as a package with an entry point in the group ``evcd.agents`` (a ``.dist-info``
folder on ``PYTHONPATH``, what pip writes), ``scripts/train.py agent=tiny`` trains it on the single
target and on the fleet, a killed run resumes to the same weights, and ``scripts/evaluate.py``
evaluates it from its checkpoint with the run's own results (real SUMO, the script grid)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from evcd.agents import Agent, agent_class, agent_names, make_agent, register_agent, unregister_agent
from evcd.utils.checkpoint import load_checkpoint
from tests.conftest import ROOT, SCRIPTS, compose_config
from tests.scripts.test_train_fleet_script import FLEET
from tests.scripts.test_train_script import KILL_MID_BATCH, KILLER, read_csv

OUTSIDE = ROOT / "examples" / "outside_agent"
#: A tiny run of the single target (the default regime, peak, on the grid).
SINGLE = ["agent=tiny", "train.episodes=6", "train.checkpoint_every=2", "batch_episodes=2", "eval.episodes=2",
          "eval.bootstrap_resamples=200"]  # fmt: skip


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict[str, str]:
    """The environment of a process where the tiny learner's package is installed: its module and
    its distribution's metadata (with the entry point) on the path, as pip would leave them."""
    site = tmp_path_factory.mktemp("site")
    dist = site / "evcd_tiny-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: evcd-tiny\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[evcd.agents]\ntiny = evcd_tiny_learner:TinyLearner\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), str(OUTSIDE), env.get("PYTHONPATH")) if p)
    return env


def run(script: str, *args: str, env: dict[str, str], patch: str = "") -> subprocess.CompletedProcess[str]:
    """``python scripts/<script> args`` in the environment ``env`` (with ``patch``: killed as it says)."""
    path = str(SCRIPTS / script)
    cmd = [sys.executable, "-c", KILLER.format(patch=textwrap.dedent(patch), script=path)] if patch else [
        sys.executable, path]  # fmt: skip
    return subprocess.run([*cmd, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)


@pytest.fixture
def tiny_class(monkeypatch):
    monkeypatch.syspath_prepend(str(OUTSIDE))
    from evcd_tiny_learner import TinyLearner

    return TinyLearner


def test_register_agent_is_the_public_way_in(tiny_class):
    register_agent("tiny_by_hand", tiny_class, defaults={"lr": 0.2})
    try:
        assert agent_class("tiny_by_hand") is tiny_class
        assert "tiny_by_hand" in agent_names("single") and "tiny_by_hand" in agent_names("fleet")
        agent = make_agent("tiny_by_hand", 3, np.random.default_rng(0))
        assert agent.lr == 0.2 and agent.learns  # the name's default
        with pytest.raises(ValueError, match=r"unknown options \['speed'\]; it takes \['lr', 'epsilon'"):
            make_agent("tiny_by_hand", 3, np.random.default_rng(0), speed=1)
        with pytest.raises(ValueError, match="registered already"):
            register_agent("tiny_by_hand", tiny_class)
        # its Hydra block is made from its declared options, with the name's defaults
        from evcd.experiments.schema import agent_block

        block = {"name": "tiny_by_hand", "lr": 0.2, "epsilon": 0.3, "gamma": 0.9, "checkpoint": None}
        assert agent_block("tiny_by_hand") == block
    finally:
        unregister_agent("tiny_by_hand")
    assert "tiny_by_hand" not in agent_names()
    with pytest.raises(ValueError, match=r"not a subclass of evcd\.agents\.Agent"):
        register_agent("not_an_agent", dict)
    with pytest.raises(ValueError, match="lowercase Python identifier"):
        register_agent("Tiny-Agent", tiny_class)
    with pytest.raises(ValueError, match="import path 'module:Class'"):
        register_agent("tiny_path", "evcd_tiny_learner.TinyLearner")
    assert issubclass(tiny_class, Agent)


def test_the_generated_block_composes_and_refuses_unknown_keys(tiny_class):
    register_agent("tiny", tiny_class)
    try:
        cfg = compose_config("train", "agent=tiny", "agent.lr=0.5")
        assert cfg.agent.name == "tiny" and cfg.agent.lr == 0.5 and cfg.agent.checkpoint is None
        assert compose_config("train", "agent=ppo").agent.clip == 0.2  # evcd's own PPO: the same path
    finally:
        unregister_agent("tiny")


def weights(run_dir: Path) -> tuple[list[float], list[float]]:
    agent = load_checkpoint(run_dir / "checkpoints")["agent"]
    return list(np.asarray(agent["w"])), list(np.asarray(agent["b"]))


@pytest.mark.slow
def test_an_outside_learner_trains_resumes_and_is_evaluated_on_the_single_target(
    installed, script_overrides, tmp_path
):
    reference = tmp_path / "reference"
    proc = run("train.py", *script_overrides, *SINGLE, f"hydra.run.dir={reference}", env=installed)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-3000:]
    data = json.loads((reference / "results.json").read_text())
    assert data["training"]["episodes_done"] == 6 and data["training"]["gradient_steps"] > 0
    assert data["baselines"]["greedy"]["paired"] is not None
    # killed in its 4th training episode, resumed from the checkpoint after 2: the same weights and rows
    out = tmp_path / "run"
    killed = run("train.py", *script_overrides, *SINGLE, f"hydra.run.dir={out}", env=installed,
                 patch=KILL_MID_BATCH.format(when=3))  # fmt: skip
    assert killed.returncode == -9, killed.stderr[-3000:]
    assert load_checkpoint(out / "checkpoints")["trainer"]["episodes_done"] == 2
    resumed = run(
        "train.py", *script_overrides, *SINGLE, f"hydra.run.dir={out}", "resume=true", env=installed
    )
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert weights(out) == weights(reference)
    for name in ("train_episodes.csv", "episodes.csv"):
        assert read_csv(out / name) == read_csv(reference / name), name
    # its checkpoint through evaluate.py: the run's evaluation episodes again
    ev = tmp_path / "eval"
    proc = run("evaluate.py", *script_overrides, "agent=tiny", f"agent.checkpoint={reference}",
               "episodes=2", "env.demand_seeds=[101,102]", "env.reward=time", f"hydra.run.dir={ev}",
               env=installed)  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert read_csv(ev / "episodes.csv") == read_csv(reference / "episodes.csv")


@pytest.mark.slow
def test_an_outside_learner_trains_on_the_fleet_and_is_evaluated(installed, script_overrides, tmp_path):
    run_dir = tmp_path / "run"
    proc = run("train.py", *script_overrides, *FLEET, "agent=tiny", "train.episodes=2",
               "train.checkpoint_every=1", "eval.episodes=1", "eval.baselines=[central]",
               "eval.bootstrap_resamples=200", f"hydra.run.dir={run_dir}", env=installed)  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run_dir / "results.json").read_text())
    assert data["task"] == "fleet" and data["training"]["episodes_done"] == 2
    assert 0 < data["training"]["gradient_steps"] <= data["training"]["transitions"]  # aborted slots: none
    assert load_checkpoint(run_dir / "checkpoints")["agent"]["format"] == "tiny/1"
    ev = tmp_path / "eval"
    proc = run("evaluate.py", *script_overrides, "task=fleet", "evs=300",
               "scenario.demand.charging_share=0.6", "env.departure_window=[21600,25200]",
               "env.demand_seeds=[1]", "episodes=1", "agent=tiny",
               f"agent.checkpoint={run_dir}", f"hydra.run.dir={ev}", env=installed)  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    again = json.loads((ev / "results.json").read_text())
    assert again["summary"]["guided_travel"] == pytest.approx(data["summary"]["guided_travel"])
