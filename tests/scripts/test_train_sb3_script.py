"""``scripts/train_sb3.py`` end to end: stable-baselines3's PPO and DQN trained through the batched
engine on the grid (real SUMO, real SB3 training on tiny budgets), evaluated by evcd's evaluation on
the episodes ``train.py`` evaluates on; same seed, same result; bad settings refused before SUMO."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3 import DQN, PPO

from evcd.env import ChargingNavEnv
from evcd.env.observation import unit_divisors
from evcd.experiments.sb3_train import SB3Policy, SB3Settings
from tests.conftest import compose_config, run_refusals, run_script, shared_folder

TINY = ["sb3.envs=4", "eval.episodes=4"]


def _travel(run: Path, name: str = "episodes.csv") -> list[tuple[str, str, str]]:
    with open(run / name, newline="") as f:
        return [(r["seed"], r["travel_time"], r["station"]) for r in csv.DictReader(f)]


@pytest.fixture(scope="module")
def ppo_run(script_overrides, tmp_path_factory) -> Path:
    """A finished SB3 PPO run (made once per test run: :func:`shared_folder`)."""

    def train(root: Path) -> None:
        proc = run_script("train_sb3.py", *script_overrides, *TINY, "sb3=ppo", "sb3.timesteps=256", "seed=3",
                          "eval.baselines=[greedy,queue_aware,hindsight]",
                          f"hydra.run.dir={root / 'ppo'}")  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]

    return shared_folder(tmp_path_factory, "train_sb3_script_ppo", train) / "ppo"


@pytest.mark.slow
def test_ppo_run_writes_evcd_results_with_sb3_training(ppo_run):
    data = json.loads((ppo_run / "results.json").read_text())
    assert data["agent"] == "sb3_ppo" and data["seed"] == 3 and data["task"] == "single"
    training = data["training"]
    # PPO collects whole rollouts: n_steps 64 x 4 targets = 256 decisions, exactly the budget
    assert training["transitions"] == training["timesteps"] == 256
    assert training["episodes"] > 0 and training["sweeps"] >= 1
    # one rollout of 256, 10 epochs of 4 minibatches of 64 (conf/sb3/ppo.yaml)
    assert training["gradient_steps"] == 40
    assert len(training["policy_sha256"]) == 64
    assert data["config"]["agent"]["name"] == "sb3_ppo" and "learner" not in data["config"]
    assert set(data["baselines"]) == {"greedy", "queue_aware", "hindsight"}
    assert data["baselines"]["greedy"]["paired"]["pairs"] == 4
    # the hindsight bound as a baseline, as in train.py: on the same episodes
    assert data["baselines"]["hindsight"]["paired"]["pairs"] == 4
    hindsight = _travel(ppo_run, "baseline_hindsight_episodes.csv")
    assert [s for s, _, _ in hindsight] == [s for s, _, _ in _travel(ppo_run, "baseline_greedy_episodes.csv")]
    assert len(_travel(ppo_run)) == 4
    assert (ppo_run / "sb3_model.zip").is_file() and (ppo_run / ".hydra" / "config.yaml").is_file()


@pytest.mark.slow
def test_the_saved_model_is_the_policy_evaluated(ppo_run, script_overrides):
    """``PPO.load`` of the run's zip, as an evcd dispatcher, decides the evaluation's stations again."""
    from evcd.experiments.worlds import split_kwargs
    from evcd.loops.evaluate import evaluate

    model = PPO.load(ppo_run / "sb3_model.zip", device="cpu")
    cfg = compose_config("train_sb3", *script_overrides, "seed=3")
    env = ChargingNavEnv(**split_kwargs(cfg, "eval", 3))
    try:
        result = evaluate(env, SB3Policy.for_env(env, model, "sb3_ppo"), episodes=4, seed=3, progress=False)
    finally:
        env.close()
    stations = [str(r.station) for r in result.rows]
    assert stations == [s for _, _, s in _travel(ppo_run)]


@pytest.mark.slow
def test_the_baselines_play_train_py_episodes(ppo_run, script_overrides, tmp_path):
    """The rules of an SB3 run play the very episodes ``train.py`` evaluates its agents on (same seed):
    queue_aware's travel times equal episode by episode, so the SB3 rows pair with evcd's."""
    run = tmp_path / "qa"
    proc = run_script(
        "train.py",
        *script_overrides,
        "agent=queue_aware",
        "eval.episodes=4",
        "seed=3",
        "eval.baselines=[]",
        f"hydra.run.dir={run}",
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert _travel(run) == _travel(ppo_run, "baseline_queue_aware_episodes.csv")


@pytest.mark.slow
def test_same_seed_same_result_for_dqn(script_overrides, tmp_path):
    """Two DQN runs of one seed: the same policy (SHA-256 of its tensors) and the same evaluation; a
    different seed trains another policy."""
    runs = {}
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        runs[name] = tmp_path / name
        proc = run_script(
            "train_sb3.py",
            *script_overrides,
            *TINY,
            "sb3=dqn",
            "sb3.timesteps=400",
            "sb3.params.learning_starts=100",
            "sb3.params.target_update_interval=100",
            "eval.baselines=[]",
            f"seed={seed}",
            f"hydra.run.dir={runs[name]}",
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
    sha = {
        k: json.loads((r / "results.json").read_text())["training"]["policy_sha256"] for k, r in runs.items()
    }
    assert sha["a"] == sha["b"] != sha["c"]
    assert _travel(runs["a"]) == _travel(runs["b"])
    assert json.loads((runs["a"] / "results.json").read_text())["training"]["gradient_steps"] == 300
    assert DQN.load(runs["a"] / "sb3_model.zip", device="cpu").num_timesteps == 400


#: Settings train_sb3.py refuses before SUMO starts, and what its message says.
BAD_SETTINGS = [
    ("sb3.algo=a2c", "sb3.algo='a2c': must be one of ppo, dqn"),
    ("sb3.envs=0", "sb3.envs"),
    ("sb3.timesteps=-5", "sb3.timesteps"),
    ("+sb3.params.not_an_argument=1", "not_an_argument"),
    ("+sb3.params.seed=4", "sb3.params.seed: evcd sets it"),
    ("eval.baselines=[dqn]", "eval.baselines: 'dqn' is a learner, not a rule; the rules: random"),
    ("eval.baselines=[foo]", "eval.baselines: 'foo' is not a rule"),
    ("experiment=fleet", "trains the single target"),
]


@pytest.fixture(scope="module")
def refused(
    script_overrides: list[str], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_SETTINGS` run by train_sb3.py in one process (:func:`run_refusals`), each
    into its own run directory with its own snapshot cache."""
    root = shared_folder(tmp_path_factory, "train_sb3_script_refused")
    kept = [o for o in script_overrides if not o.startswith("env.cache_dir=")]
    cases = [[*kept, f"env.cache_dir={root / f'cache{i}'}", override, f"hydra.run.dir={root / f'run{i}'}"]
             for i, (override, _) in enumerate(BAD_SETTINGS)]  # fmt: skip
    return root, run_refusals("train_sb3.py", cases, root)


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(BAD_SETTINGS)), ids=[override for override, _ in BAD_SETTINGS])
def test_bad_settings_stop_before_sumo(refused, case):
    root, runs = refused
    code, log = runs[case]
    assert code == 2, log[-2000:]
    assert not (root / f"cache{case}").exists()  # no day was simulated
    assert BAD_SETTINGS[case][1] in log
    assert not (root / f"run{case}" / "results.json").exists()


@pytest.mark.slow
def test_a_run_directory_with_results_is_not_overwritten(ppo_run, script_overrides):
    before = (ppo_run / "results.json").read_bytes()
    proc = run_script(
        "train_sb3.py", *script_overrides, *TINY, "sb3.timesteps=64", f"hydra.run.dir={ppo_run}"
    )
    assert proc.returncode == 2 and "already holds" in proc.stdout + proc.stderr
    assert (ppo_run / "results.json").read_bytes() == before


def test_policy_normalises_raw_observations_as_in_training():
    """On a raw environment the dispatcher divides by the units training used; on a normalised one it
    passes the observations through: the model sees the same input either way."""

    class Recorder:
        def __init__(self):
            self.seen = []

        def predict(self, x, deterministic):
            self.seen.append(x)
            return np.argmax(x[:, :3], axis=1), None

    points = [2, 4, 1]
    raw = np.array([[1500.0, 300.0, 2500.0, 20.0, 5.0, 0.0, 2.0, 8.0, 1.0]])
    normalised = (raw / unit_divisors(points)).astype(np.float32)
    a, b = Recorder(), Recorder()
    SB3Policy(a, 3, points, normalized=False, label="sb3_x").decide(raw, [None])
    SB3Policy(b, 3, points, normalized=True, label="sb3_x").decide(normalised, [None])
    np.testing.assert_allclose(a.seen[0], b.seen[0], rtol=1e-6)
    with pytest.raises(ValueError, match="observation of shape"):
        SB3Policy(a, 3, points, normalized=False, label="sb3_x").decide(np.zeros((1, 7)), [None])


def test_settings_refuse_bad_values_by_name():
    with pytest.raises(ValueError, match=r"sb3\.algo=.sac."):
        SB3Settings("sac", 4, 100)
    with pytest.raises(ValueError, match=r"sb3\.params\.env"):
        SB3Settings("ppo", 4, 100, {"env": None})
    assert SB3Settings("dqn", 1, 1).label == "sb3_dqn"
