"""The examples run as a user runs them, from the repository (real SUMO on the script grid)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.conftest import run_script


@pytest.mark.slow
def test_the_gymnasium_loop_plays_both_splits(script_overrides) -> None:
    overrides = [a for o in script_overrides for a in ("--override", o)]
    proc = run_script("../examples/gymnasium_loop.py", "--episodes", "2", *overrides)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    out = proc.stdout
    for split in ("train", "eval"):
        assert len(re.findall(rf"^{split} episode \d: ", out, re.M)) == 2, out
        mean = re.search(rf"^{split}: mean travel time ([0-9.]+) s$", out, re.M)
        assert mean is not None and 0 < float(mean.group(1)) < 7200, out


def test_the_examples_rule_takes_the_fewest_vehicles_per_point_then_the_nearest() -> None:
    from examples.gymnasium_loop import fewest_per_point

    #            D (km)         N            Z (per point)
    obs = np.array([3.0, 1.0, 2.0, 0, 0, 0, 0.5, 0.5, 1.0], dtype=np.float32)
    assert fewest_per_point(obs, 3) == 1  # stations 0 and 1 tie on Z; 1 is nearer
    obs[7] = 0.75
    assert fewest_per_point(obs, 3) == 0


@pytest.mark.slow
def test_stable_baselines3_ppo_trains_and_is_evaluated_beside_the_rule(script_overrides) -> None:
    overrides = [a for o in script_overrides for a in ("--override", o)]
    tiny = ["--timesteps", "32", "--n-steps", "16", "--envs", "2", "--episodes", "2"]
    proc = run_script("../examples/sb3_ppo.py", *tiny, *overrides)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert re.search(r"^trained (3[2-9]|4\d) decisions$", proc.stdout, re.M), proc.stdout
    held_out = re.search(
        r"^held-out: sb3 PPO ([0-9.]+) s, queue_aware ([0-9.]+) s on the same 2 episodes$", proc.stdout, re.M
    )
    assert held_out is not None, proc.stdout
    assert all(0 < float(v) < 7200 for v in held_out.groups())


@pytest.mark.slow
def test_torchrl_trains_a_shared_policy_on_the_fleet(script_overrides) -> None:
    """TorchRL's PPO on the fleet's slot view (grid world): every batch has EV decisions, trips end with
    a travel time, and the shared policy's weights change."""
    fleet = [
        "evs=300",
        "scenario.demand.charging_share=0.6",
        "env.departure_window=[21600,25200]",
        "days.train=[0]",
    ]
    overrides = [a for o in [*script_overrides, *fleet] for a in ("--override", o)]
    proc = run_script(
        "../examples/torchrl_fleet.py", "--batches", "3", "--frames", "30", "--slots", "40", *overrides
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    rows = re.findall(
        r"^batch (\d): (\d+) EV decisions, (\d+) trips ended, mean travel time ([0-9.]+) s$",
        proc.stdout,
        re.M,
    )
    assert [int(r[0]) for r in rows] == [0, 1, 2], proc.stdout
    assert all(int(r[1]) > 0 for r in rows) and sum(int(r[2]) for r in rows) > 0
    assert all(0 < float(r[3]) < 7200 for r in rows)
    assert re.search(r"^policy weights changed by [0-9.e+-]+ \(L2\)$", proc.stdout, re.M), proc.stdout


@pytest.mark.slow
def test_the_cleanrl_style_dqn_trains_on_the_sweep_beside_the_rule(script_overrides, tmp_path):
    """The single-file DQN on the batched engine (grid world): it counts its decisions over every
    target, logs the ended episodes' travel times and its TD loss, and plays the held-out episodes."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    overrides = [a for o in script_overrides for a in ("--override", o)]
    tiny = ["--decisions", "160", "--envs", "4", "--learning-starts", "40", "--episodes", "2",
            "--logdir", str(tmp_path)]  # fmt: skip
    proc = run_script("../examples/cleanrl_dqn.py", *tiny, *overrides)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert re.search(r"^trained 160 decisions in \d+ s", proc.stdout, re.M), proc.stdout
    held_out = re.search(r"^held-out: DQN ([0-9.]+) s, queue_aware ([0-9.]+) s on the same 2 episodes$",
                         proc.stdout, re.M)  # fmt: skip
    assert held_out is not None and all(0 < float(v) < 7200 for v in held_out.groups()), proc.stdout
    (run,) = tmp_path.iterdir()
    acc = EventAccumulator(str(run))
    acc.Reload()
    assert {"charts/travel_time", "losses/td_loss", "charts/epsilon"} <= set(acc.Tags()["scalars"])
    assert all(0 < e.value < 7200 for e in acc.Scalars("charts/travel_time"))
