"""PPO through the scripts, as a user runs it: ``scripts/train.py agent=ppo`` on the single target
(batched engine) and on the fleet, killed mid-batch and resumed to the same weights, its TensorBoard
scalars, and ``scripts/evaluate.py`` from its checkpoint (real SUMO, the script grid)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from evcd.utils.checkpoint import load_checkpoint
from tests.conftest import run_script
from tests.scripts.test_train_fleet_script import FLEET
from tests.scripts.test_train_script import KILL_MID_BATCH, read_csv, run_train

pytestmark = pytest.mark.slow  # every test here takes seconds

#: A tiny PPO run on the grid: an update every 8 transitions.
PPO = ["agent=ppo", "agent.hidden=[16,16]", "agent.rollout_steps=8", "agent.minibatch_size=4",
       "agent.epochs=2", "train.episodes=6", "train.checkpoint_every=2", "batch_episodes=2",
       "eval.episodes=2", "eval.bootstrap_resamples=200"]  # fmt: skip


def weights(run_dir: Path) -> dict[str, torch.Tensor]:
    agent = load_checkpoint(run_dir / "checkpoints")["agent"]
    return {f"{net}.{k}": v for net in ("actor", "critic") for k, v in agent[net].items()}


def test_ppo_trains_resumes_exactly_and_is_evaluated_on_the_single_target(script_overrides, tmp_path):
    reference = tmp_path / "reference"
    proc = run_train(*script_overrides, *PPO, f"hydra.run.dir={reference}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((reference / "results.json").read_text())
    assert data["training"]["gradient_steps"] > 0 and data["training"]["target_updates"] == 0
    acc = EventAccumulator(str(reference / "tensorboard"))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"losses/policy", "losses/value", "losses/entropy", "charts/approx_kl"} <= tags
    assert "losses/td_loss" not in tags  # the DQN learners' only
    out = tmp_path / "run"
    args = [*script_overrides, *PPO, f"hydra.run.dir={out}"]
    killed = run_train(*args, patch=KILL_MID_BATCH.format(when=3))
    assert killed.returncode == -9, killed.stderr[-3000:]
    resumed = run_train(*args, "resume=true")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    mine, ref = weights(out), weights(reference)
    assert mine.keys() == ref.keys() and all(torch.equal(mine[k], ref[k]) for k in mine)
    for name in ("train_episodes.csv", "episodes.csv"):
        assert read_csv(out / name) == read_csv(reference / name), name
    ev = tmp_path / "eval"
    # the checkpoint's network sizes, not the agent block's defaults (hidden [64, 64])
    proc = run_script("evaluate.py", *script_overrides, "agent=ppo", f"agent.checkpoint={reference}",
                      "episodes=2", "env.demand_seeds=[101,102]", "env.reward=time",
                      f"hydra.run.dir={ev}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert read_csv(ev / "episodes.csv") == read_csv(reference / "episodes.csv")


def test_ppo_trains_on_the_fleet_with_one_policy_for_every_guided_ev(script_overrides, tmp_path):
    run = tmp_path / "run"
    proc = run_train(*script_overrides, *FLEET, "agent=ppo", "agent.hidden=[16,16]",
                     "agent.rollout_steps=32", "train.episodes=2", "train.checkpoint_every=1",
                     "eval.episodes=1", "eval.baselines=[central]", "eval.bootstrap_resamples=200",
                     f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert data["training"]["gradient_steps"] > 0 and "central" in data["baselines"]
    ev = tmp_path / "eval"
    proc = run_script("evaluate.py", *script_overrides, "task=fleet", "evs=300",
                      "scenario.demand.charging_share=0.6", "env.departure_window=[21600,25200]",
                      "env.demand_seeds=[1]", "episodes=1", "agent=ppo",
                      f"agent.checkpoint={run}", f"hydra.run.dir={ev}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    again = json.loads((ev / "results.json").read_text())
    assert again["summary"]["guided_travel"] == pytest.approx(data["summary"]["guided_travel"])
