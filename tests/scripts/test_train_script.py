"""``scripts/train.py`` end to end: real Hydra, real SUMO (a generated grid), real torch.

The runs are tiny (a few episodes, a 16 x 16 network) so that each takes seconds; kills are
deterministic: a wrapper starts the script with one function patched to ``SIGKILL`` its own process
at a chosen point (in the middle of an episode, or half-way through writing a checkpoint).
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from evcd.agents import agent_class
from evcd.agents.dqn import DQNAgent, DQNConfig
from evcd.cli.params import agent_params
from evcd.env import ChargingNavEnv
from evcd.experiments.worlds import env_kwargs
from evcd.loops.hindsight import dispatcher_names, make_dispatcher
from evcd.utils.checkpoint import load_checkpoint
from tests.conftest import CONF, SCRIPTS, compose_config, run_refusals, run_refused, run_script, shared_folder

SCRIPT = SCRIPTS / "train.py"
EXPERIMENTS = sorted(p.stem for p in (CONF / "experiment").glob("*.yaml"))

KILLER = """
import os, runpy, signal, sys
{patch}
sys.argv = [{script!r}, *sys.argv[1:]]
runpy.run_path({script!r}, run_name="__main__")
"""
# SIGKILL at the start of the episode with this index in the process (mid-run, SUMO running)
KILL_MID_EPISODE = """
import evcd.env.runners.single as runner
_episode, _count = runner.SingleEnvRunner.episode, [0]
def episode(self, spec, agent, **kw):
    if kw.get("learn") and _count[0] == {when}:
        os.kill(os.getpid(), signal.SIGKILL)
    _count[0] += 1
    return _episode(self, spec, agent, **kw)
runner.SingleEnvRunner.episode = episode
"""
# the batched engine: SIGKILL as the 4th training episode (index 3) is first decided
KILL_MID_BATCH = """
import evcd.env.runners.batch as batch
_decide = batch.BatchSimulation._decide
def decide(self, due, now):
    if self.learn and any(live.spec.index == {when} for live in due):
        os.kill(os.getpid(), signal.SIGKILL)
    return _decide(self, due, now)
batch.BatchSimulation._decide = decide
"""
# SIGKILL half-way through writing the checkpoint file with this index (its temporary file is left)
KILL_MID_WRITE = """
import tempfile
from pathlib import Path
import evcd.utils.checkpoint as ckpt
_write, _count = ckpt.atomic_write_bytes, [0]
def atomic_write_bytes(path, data):
    path = Path(path)
    if path.suffix == ".pt":
        _count[0] += 1
        if _count[0] == {when}:
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{{path.name}}.", suffix=".tmp")
            os.write(fd, data[: len(data) // 2])
            os.kill(os.getpid(), signal.SIGKILL)
    return _write(path, data)
ckpt.atomic_write_bytes = atomic_write_bytes
"""


def run_train(*overrides: str, patch: str = "") -> subprocess.CompletedProcess:
    code = KILLER.format(patch=textwrap.dedent(patch), script=str(SCRIPT)) if patch else None
    return run_script("train.py", *overrides, code=code)


def compose_train(*overrides: str):
    return compose_config("train", *overrides)


@pytest.fixture(scope="module")
def scenario_dir(script_grid) -> Path:
    return script_grid


@pytest.fixture(scope="module")
def small(script_overrides) -> list[str]:
    """Overrides for a tiny training run on the grid."""
    return [
        *script_overrides, "learner.hidden=[16,16]", "learner.learning_starts=4", "learner.batch_size=4",
        "learner.target_update=5", "learner.exploration_steps=10", "eval.episodes=2",
        "eval.bootstrap_resamples=200",
    ]  # fmt: skip


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(f)]


def final_weights(run_dir: Path) -> dict[str, torch.Tensor]:
    agent = load_checkpoint(run_dir / "checkpoints")["agent"]
    return {**{f"online.{k}": v for k, v in agent["online"].items()},
            **{f"target.{k}": v for k, v in agent["target"].items()}}  # fmt: skip


# ---------------------------------------------------------------------------------------- configs
@pytest.mark.slow
@pytest.mark.parametrize("experiment", [e for e in EXPERIMENTS if e != "fleet"])  # the fleet's: its own file
@pytest.mark.parametrize("evs", [200, 300, 400])
def test_every_agent_and_experiment_composes_and_builds(experiment, evs, scenario_dir):
    for name in dispatcher_names():
        cfg = compose_train(
            f"agent={name}", f"experiment={experiment}", f"evs={evs}", f"scenario.path={scenario_dir}"
        )
        assert cfg.evs == evs and cfg.agent.name == name
        assert list(cfg.env.demand_seeds) == list(cfg.train.days)
        env = ChargingNavEnv(**env_kwargs(cfg))  # validates every env value; no SUMO
        assert env.config.demand_config.evs == evs
        agent_name, params = agent_params(cfg)
        params.pop("checkpoint", None)
        agent = make_dispatcher(agent_name, env, np.random.default_rng(0), **params)
        assert agent.name == name and agent.n_stations == 3


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_the_days_of_every_shipped_experiment_are_disjoint(experiment):
    """Training, tuning, calibration and evaluation days never meet, and each use draws on its own."""
    cfg = compose_train(f"experiment={experiment}")
    days = {use: set(seeds) for use, seeds in cfg.days.items()}
    assert set(days) == {"train", "tuning", "calibration", "evaluation"}
    for (a, x), (b, y) in itertools.combinations(days.items(), 2):
        assert not x & y, (experiment, a, b, sorted(x & y))
    assert set(cfg.train.days) <= days["train"] and set(cfg.env.demand_seeds) <= days["train"]
    assert set(cfg.eval.days) <= days["evaluation"]
    assert set(cfg.train.validation.days) <= days["tuning"]


@pytest.mark.slow
def test_training_departures_follow_train_departure_window(small, tmp_path):
    """train.departure_window narrows the training departures only: the evaluation keeps
    env.departure_window (06:00-06:30 on the grid)."""
    out = tmp_path / "run"
    proc = run_train(*small, "agent=dqn", "train.episodes=4", "train.checkpoint_every=2",
                     "train.departure_window=[22500,23400]", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    train = [float(r["departure"]) for r in read_csv(out / "train_episodes.csv")]
    evaluation = [float(r["departure"]) for r in read_csv(out / "episodes.csv")]
    assert len(train) == 4 and all(22500 <= d <= 23400 for d in train)
    assert all(21600 <= d <= 23400 for d in evaluation)
    proc = run_train(*small, "agent=dqn", "train.departure_window=[23400,21600]")
    out_text = proc.stdout + proc.stderr
    assert proc.returncode == 2 and "departure_window" in out_text and "23400" in out_text, out_text[-2000:]


@pytest.mark.slow
def test_each_seed_can_run_on_its_own_evaluation_day(small, tmp_path):
    out = tmp_path / "run"
    proc = run_train(*small, "agent=greedy", "eval.day_per_seed=true", "days.evaluation=[5,6,7]", "seed=4",
                     f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert {e["day"] for e in data["episodes"]} == {6}  # days[4 mod 3]


def test_experiments_exist_and_the_default_is_the_peak():
    assert {"peak", "paper"} <= set(EXPERIMENTS)
    cfg = compose_train()
    assert cfg.agent.name == "dueling_ddqn" and cfg.evs == 400
    assert list(cfg.env.departure_window) == [25200.0, 36000.0]
    assert list(cfg.eval.days) != list(cfg.train.days) and "greedy" in cfg.eval.baselines
    assert cfg.env.reward == "time" and cfg.learner.exploration == "episode"


def test_the_paper_experiment_has_the_papers_settings():
    cfg = compose_train("experiment=paper")
    learner = cfg.learner
    assert list(learner.hidden) == [512, 256] and learner.lr == 0.01 and learner.batch_size == 32
    assert learner.target_update == 8000 and learner.buffer_size == 10000
    assert (learner.epsilon_start, learner.epsilon_end) == (1.0, 0.1)
    assert cfg.train.episodes == 50 and cfg.env.reward == "paper" and learner.loss == "mse"
    assert list(cfg.env.departure_window) == [0.0, 86400.0]


def test_dqn_and_dueling_ddqn_configs_differ_only_in_the_switches():
    dqn = OmegaConf.to_container(compose_train("agent=dqn").agent)
    ddqn = OmegaConf.to_container(compose_train("agent=dueling_ddqn").agent)
    assert {k for k in dqn if dqn[k] != ddqn[k]} == {"name", "double", "dueling"}
    assert agent_class("dqn") is agent_class("dueling_ddqn") is DQNAgent


@pytest.mark.slow
def test_the_learner_block_is_the_dqn_config():
    """The learner block is DQNConfig itself (a structured config): its fields and defaults, a
    preset changing some, an override reaching the agent; an unknown key or a mistyped value is
    refused when Hydra composes, a value out of range when the agent's config is made."""
    base = compose_train("~experiment").learner
    assert OmegaConf.to_object(base) == DQNConfig()
    _name, built = agent_params(compose_train("learner.lr=0.005"))
    assert built["config"] == dataclasses.replace(learner_of(compose_train()), lr=0.005)
    assert built["double"] is True and built["dueling"] is True
    peak = learner_of(compose_train("experiment=peak"))
    assert (peak.gamma, peak.exploration, peak.loss, peak.target_update) == (0.9, "episode", "huber", 250)
    assert peak.n_step == 3  # the peak experiment's own addition to the preset
    preset = learner_of(compose_train("~experiment", "learner=peak"))
    assert peak == dataclasses.replace(preset, n_step=3, network="station")
    table = learner_of(compose_train("experiment=table"))
    # the peak preset + three
    assert table == dataclasses.replace(preset, gamma=0.97, exploration_steps=2000, network="station")
    with pytest.raises(ConfigCompositionException, match="bogus"):
        compose_train("learner.bogus=1")
    with pytest.raises(ConfigCompositionException, match="lr"):
        compose_train("learner.lr=fast")
    with pytest.raises(ValueError, match=r"gamma=1\.5"):
        agent_params(compose_train("learner.gamma=1.5"))


def learner_of(cfg) -> DQNConfig:
    return agent_params(cfg)[1]["config"]


# ---------------------------------------------------------------------------------------- runs
@pytest.mark.slow
def test_a_tiny_training_run_end_to_end(small, tmp_path):
    out = tmp_path / "run"
    proc = run_train(
        *small, "agent=dqn", "train.episodes=4", "train.checkpoint_every=2", f"hydra.run.dir={out}"
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert data["agent"] == "dqn" and data["training"]["episodes"] == 4
    assert data["training"]["transitions"] >= 4 and data["baselines"]["greedy"]["paired"]["pairs"] <= 2
    assert data["config"]["agent"]["name"] == "dqn"
    assert len(read_csv(out / "train_episodes.csv")) == 4 and len(read_csv(out / "episodes.csv")) == 2
    ckpt = load_checkpoint(out / "checkpoints")
    assert (
        ckpt["trainer"]["episodes_done"] == 4
        and ckpt["agent"]["counters"]["steps"] == data["training"]["transitions"]
    )
    events = list((out / "tensorboard").glob("events.out.tfevents.*"))
    assert events
    acc = EventAccumulator(str(out / "tensorboard"))
    acc.Reload()
    assert {"charts/travel_time", "charts/epsilon", "losses/td_loss", "eval/travel_time"} <= set(
        acc.Tags()["scalars"]
    )
    assert len(acc.Scalars("charts/travel_time")) == 4
    log = proc.stdout + proc.stderr
    assert "vs greedy on the same" in log and "vs queue_aware on the same" in log
    assert "mean travel time" in log
    days = sorted({int(r["day"]) for r in read_csv(out / "episodes.csv")})
    assert days == [101, 102]  # the peak regime's two evaluation days, one episode each
    assert all(f"evaluation day {d} (1 episodes): dqn " in log for d in days)
    # the trained policy runs in the evaluation command too, and sees what it was trained on (raw
    # observations) whether the environment normalises them or not: the same actions
    plain = [o for o in small if not o.startswith(("learner.", "eval."))]
    for normalize in ("false", "true"):
        ev = tmp_path / f"eval_{normalize}"
        proc = run_script(
            "evaluate.py",
            *plain,
            "agent=dqn",
            f"agent.checkpoint={out}",
            "episodes=2",
            "env.demand_seeds=[101,102]",  # the peak regime's evaluation days
            "env.reward=time",
            f"env.normalize_obs={normalize}",
            f"hydra.run.dir={ev}",
        )  # fmt: skip  (peak's reward)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert read_csv(ev / "episodes.csv") == read_csv(out / "episodes.csv")
        # the training's world, on days it never saw: nothing to say (evcd.cli.trained_world)
        world = json.loads((ev / "results.json").read_text())["trained_world"]
        assert world == {"differences": [], "training_days": [], "tuning_days": [], "forecast_days": None}
    # another departure window, on a training day: played, and both named in the log and results.json
    ev = tmp_path / "eval_elsewhere"
    proc = run_script("evaluate.py", *plain, "agent=dqn", f"agent.checkpoint={out}", "episodes=1",
                      "env.demand_seeds=[0]", "env.reward=time", "env.departure_window=[21600,22500]",
                      f"hydra.run.dir={ev}")  # fmt: skip
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-3000:]
    assert "env.departure_window: [21600, 23400] -> [21600, 22500]" in log, log[-3000:]
    assert "evaluated on days the policy trained on: [0]" in log
    world = json.loads((ev / "results.json").read_text())["trained_world"]
    assert world["training_days"] == [0] and len(world["differences"]) == 1
    # the policy under a name that means other switches, or another learner's: refused, naming why
    names = {"dueling_ddqn": "evaluate it under the name it was trained as",
             "ppo": "does not hold a PPO agent"}  # fmt: skip
    cases = [[*plain, f"agent={name}", f"agent.checkpoint={out}", "episodes=1",
              f"hydra.run.dir={tmp_path / ('refused_' + name)}"] for name in names]  # fmt: skip
    for (code, log), needle in zip(run_refusals("evaluate.py", cases, tmp_path / "refused"), names.values(),
                                   strict=True):  # fmt: skip
        assert code == 2 and needle in log, log[-2000:]


@pytest.mark.slow
def test_a_rule_agent_goes_through_the_same_script(small, tmp_path):
    out = tmp_path / "run"
    proc = run_train(*small, "agent=queue_aware", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert data["training"]["episodes"] == 0 and not (out / "checkpoints").exists()
    assert data["baselines"]["greedy"]["paired"] is not None


def reference_run(small: list[str], out: Path, engine: str) -> Path:
    proc = run_train(*small, "agent=dueling_ddqn", "train.episodes=6", "train.checkpoint_every=2",
                     f"engine={engine}", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def uninterrupted(small, tmp_path_factory) -> Path:
    folder = shared_folder(tmp_path_factory, "train_script_reference",
                           lambda root: reference_run(small, root / "run", "batched"))
    return folder / "run"


@pytest.mark.slow
@pytest.mark.parametrize(
    "patch,checkpoint,engine",
    [(KILL_MID_BATCH.format(when=3), 2, "batched"),  # killed in the 4th training episode: resumes after 2
     (KILL_MID_EPISODE.format(when=3), 2, "single"),
     (KILL_MID_WRITE.format(when=2), 2, "batched")],  # killed writing the checkpoint after episode 4
    ids=["mid-episode", "mid-episode-single-engine", "mid-checkpoint-write"],
)  # fmt: skip
def test_a_killed_run_resumes_to_the_same_result(small, uninterrupted, tmp_path, patch, checkpoint, engine):
    """Killed, then resumed: the weights, episodes and pairs of the uninterrupted run; a new run (not
    resumed) into the killed run's directory is refused (checked once: it does not depend on the kill)."""
    out = tmp_path / "run"
    if engine != "batched":
        uninterrupted = reference_run(small, tmp_path / "reference", engine)
    args = [
        *small,
        "agent=dueling_ddqn",
        "train.episodes=6",
        "train.checkpoint_every=2",
        f"engine={engine}",
        f"hydra.run.dir={out}",
    ]
    killed = run_train(*args, patch=patch)
    assert killed.returncode == -9, killed.stderr[-3000:]
    assert load_checkpoint(out / "checkpoints")["trainer"]["episodes_done"] == checkpoint
    assert not (out / "results.json").exists()
    if patch == KILL_MID_BATCH.format(when=3):
        refused = run_train(*args)  # a new run must not reuse that directory
        assert refused.returncode == 2 and "resume=true" in refused.stdout + refused.stderr
    resumed = run_train(*args, "resume=true")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "resuming after" in resumed.stdout + resumed.stderr
    mine, ref = final_weights(out), final_weights(uninterrupted)
    assert mine.keys() == ref.keys() and all(torch.equal(mine[k], ref[k]) for k in mine)
    for name in ("train_episodes.csv", "episodes.csv", "baseline_greedy_episodes.csv"):
        assert read_csv(out / name) == read_csv(uninterrupted / name), name
    a, b = (json.loads((d / "results.json").read_text()) for d in (out, uninterrupted))
    assert a["summary"]["mean_travel_time"] == b["summary"]["mean_travel_time"]
    for rule in ("greedy", "queue_aware"):
        assert a["baselines"][rule]["paired"] == b["baselines"][rule]["paired"]
    assert a["training"]["sessions"] == 2
    assert not list((out / "checkpoints").glob(".*.tmp"))  # the half-written file was cleaned up


@pytest.mark.slow
def test_a_sweep_writes_one_run_directory_per_job(small, tmp_path):
    sweep = tmp_path / "sweep"
    proc = run_train("-m", *small, "agent=greedy,dqn", "train.episodes=2", f"hydra.sweep.dir={sweep}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    for job, agent in (("0_greedy_evs30_seed0", "greedy"), ("1_dqn_evs30_seed0", "dqn")):
        assert json.loads((sweep / job / "results.json").read_text())["agent"] == agent


#: Settings train.py refuses before SUMO starts, and what its message says.
BAD_VALUES = [
    ("train.episodes=0", "train.episodes=0"),
    ("learner.batch_size=0", "batch_size=0"),
    ("learner.lr=-0.1", "lr=-0.1"),
    ("learner.buffer_size=2", "buffer_size=2 < batch_size=4"),
    ("learner.hidden=[]", "hidden=[]"),
    ("learner.epsilon_start=1.5", "epsilon_start=1.5"),
    ("learner.loss=l1", "loss='l1'"),
    ("learner.in_turn=true", "learner.in_turn=true: this setting left evcd; commit c467250 is the last"),
    ("learner.rule_prior=false", "learner.rule_prior=false: this setting left evcd; commit c467250"),
    ("eval.episodes=0", "eval.episodes=0"),
    ("agent.name=dqnn", "dqnn"),
    ("evs=-1", "evs=-1"),
    ("eval.days=[]", "eval.days=[]"),
    ("env.demand_seeds=[4]", "train.days"),
    ("eval.baselines=[dqn]", "eval.baselines: 'dqn' is a learner, not a rule; the rules: random"),
    ("eval.baselines=[foo]", "eval.baselines: 'foo' is not a rule; the rules: random, greedy"),
    ("train.validation.every=2 train.validation.rules=[dqn]", "validation.rules: 'dqn' is a learner"),
    ("train.episodes=4 learner.learning_starts=1000", "learning_starts=1000: the 4 training episodes"),
    ("resume=true", "no checkpoint"),
    ("agent.checkpoint=x.pt", "agent.checkpoint"),
    ("engine=fast", "engine='fast'"),
    ("batch_episodes=0", "batch_episodes=0"),
    ("train.validation.every=3", "validation.every=3: must be a multiple of train.checkpoint_every"),
    ("train.validation.every=2 train.validation.days=[0]", "train.validation.days share [0]"),
    ("eval.days=[-1]", "eval.days=[-1]"),
    ("train.validation.every=0 train.validation.select_best=true", "select_best=true needs a validation"),
    ("train.validation.every=2 train.validation.select_best=maybe", "select_best='maybe'"),
    ("train.validation.every=2 train.validation.at_start=true", "validation.at_start=true: this setting"),
    ("agent=central +agent.switch_margin_s=300", "agent.switch_margin_s=300: this setting left evcd"),
    ("agent=ppo learner.lr=0.01", "agent=ppo does not read the DQN learners' `learner` block"),
]


@pytest.fixture(scope="module")
def refused(small, tmp_path_factory) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_VALUES` run by train.py (in one process: :func:`run_refusals`), each into
    its own run directory with its own snapshot cache."""
    root = shared_folder(tmp_path_factory, "train_script_refused")
    kept = [o for o in small if not o.startswith("env.cache_dir=")]
    cases = [[*kept, "agent=dqn", "train.checkpoint_every=2", *override.split(),
              f"env.cache_dir={root / f'cache{i}'}", f"hydra.run.dir={root / f'run{i}'}"]
             for i, (override, _) in enumerate(BAD_VALUES)]  # fmt: skip
    return root, run_refusals("train.py", cases, root)


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(BAD_VALUES)), ids=[override for override, _ in BAD_VALUES])
def test_bad_values_stop_before_sumo(refused, case):
    root, runs = refused
    code, log = runs[case]
    assert code == 2, log[-2000:]
    assert BAD_VALUES[case][1] in log
    assert not (root / f"cache{case}").exists()  # no day was simulated
    assert not (root / f"run{case}" / "results.json").exists()


@pytest.mark.slow
def test_a_refusal_exits_with_code_2_in_a_process_of_its_own(small, tmp_path):
    """What the batched refusals above stand for: ``python scripts/train.py`` itself, refused, exits
    with code 2 and the message, before any day is simulated, leaving no run directory behind."""
    kept = [o for o in small if not o.startswith("env.cache_dir=")]
    log = run_refused("train.py", kept, "agent=dqn", "learner.lr=-0.1", f"hydra.run.dir={tmp_path / 'run'}",
                      cache=tmp_path / "cache")  # fmt: skip
    assert "lr=-0.1" in log and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_learner_that_took_no_gradient_step_is_not_reported(small, tmp_path):
    out = tmp_path / "run"
    proc = run_train(*small, "agent=dqn", "train.episodes=2", "train.checkpoint_every=2",
                     "learner.learning_starts=200", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "took no gradient step in 2 training episodes" in proc.stdout + proc.stderr
    assert not (out / "results.json").exists() and not (out / "episodes.csv").exists()
    assert load_checkpoint(out / "checkpoints")["trainer"]["episodes_done"] == 2  # kept


@pytest.mark.slow
def test_single_and_batched_engines_play_the_same_episodes(small, tmp_path):
    rows = {}
    for engine in ("single", "batched"):
        out = tmp_path / engine
        proc = run_train(
            *small, "agent=greedy", "eval.episodes=6", f"engine={engine}", f"hydra.run.dir={out}"
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        rows[engine] = read_csv(out / "episodes.csv")
    key = ("episode", "seed", "departure", "origin", "day")
    assert [[r[k] for k in key] for r in rows["single"]] == [[r[k] for k in key] for r in rows["batched"]]
    t = {e: [float(r["travel_time"]) for r in rows[e]] for e in rows}
    assert sum(abs(a - b) for a, b in zip(t["single"], t["batched"], strict=True)) <= 0.05 * sum(t["single"])


@pytest.mark.slow
def test_unknown_experiment_lists_the_known_ones(tmp_path):
    proc = run_train("experiment=nope", f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode != 0
    assert "experiment/nope" in proc.stderr and "peak" in proc.stderr and "paper" in proc.stderr


@pytest.mark.slow
def test_a_corrupted_checkpoint_is_reported_on_resume(small, uninterrupted, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(uninterrupted, out)
    (out / "results.json").unlink()
    ckpt = out / "checkpoints" / json.loads((out / "checkpoints" / "latest.json").read_text())["file"]
    ckpt.write_bytes(ckpt.read_bytes()[:1000])
    proc = run_train(*small, "agent=dueling_ddqn", "train.episodes=6", "train.checkpoint_every=2",
                     "resume=true", f"hydra.run.dir={out}")  # fmt: skip
    assert proc.returncode == 2 and "truncated" in proc.stdout + proc.stderr


@pytest.mark.slow
def test_the_table_experiment_runs_without_a_baseline_in_the_calibrated_world(small, tmp_path):
    cfg = compose_train("experiment=table")
    assert cfg.regime == "table" and list(cfg.eval.baselines) == []
    assert cfg.scenario.charging_points == 1 and cfg.scenario.path == "sumo_net/jurong_west"
    assert list(cfg.env.departure_window) == [0.0, 86400.0] and cfg.env.max_travel_time == 14400.0
    assert not set(cfg.train.days) & set(cfg.eval.days)
    out = tmp_path / "run"
    proc = run_train("experiment=table", *small, "agent=greedy", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert data["config"]["regime"] == "table" and data["config"]["scenario"]["charging_points"] == 1
    assert "baselines" not in data
    assert not list(out.glob("baseline_*")) and len(read_csv(out / "episodes.csv")) == 2
