"""``perturbations=...`` through the scripts (real Hydra, real SUMO on the grid): the group composes
into the environments' arguments, a perturbed run plays its days' outages, bad values stop the run
before SUMO starts, and ``none`` leaves every argument as before."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException

from evcd.env import ChargingNavEnv
from evcd.experiments.worlds import env_kwargs, fleet_kwargs, split_kwargs
from tests.conftest import compose_config, run_refusals, run_refused, run_script, shared_folder


def test_none_is_the_default_and_adds_nothing():
    cfg = compose_config("train")
    assert env_kwargs(cfg)["perturbations"] is None
    assert env_kwargs(compose_config("train", "perturbations=none")) == env_kwargs(cfg)
    assert compose_config("evaluate").perturbations == {}


def test_outages_reach_every_split_and_the_fleet():
    cfg = compose_config("train", "perturbations=outages", "perturbations.outages.per_day=4")
    for split in ("train", "tuning", "eval"):
        assert split_kwargs(cfg, split, 0)["perturbations"]["outages"]["per_day"] == 4
    fleet = compose_config("train", "experiment=fleet", "perturbations=outages")
    assert fleet_kwargs(fleet)["perturbations"]["outages"]["minutes"] == [30.0, 180.0]


def test_mixed_composes_every_kind_with_its_own_settings():
    cfg = compose_config("train", "perturbations=mixed", "perturbations.rain.chance=1.0")
    p = env_kwargs(cfg)["perturbations"]
    assert sorted(p) == ["incidents", "outages", "rain", "roadworks"]
    assert (
        p["rain"]["chance"] == 1.0
        and p["incidents"] == compose_config("train", "perturbations=incidents").perturbations.incidents
    )


@pytest.mark.parametrize("kind", ["incidents", "outages", "rain"])
def test_each_peak_kind_is_mixed_peaks_kind_alone(kind):
    """``<kind>_peak`` holds mixed_peak's settings of that kind and no other kind: with each kind on
    its own random stream, its days hold exactly mixed_peak's events of that kind (docs/PERTURBED.md,
    by kind)."""
    alone = env_kwargs(compose_config("train", f"perturbations={kind}_peak"))["perturbations"]
    mixed = env_kwargs(compose_config("train", "perturbations=mixed_peak"))["perturbations"]
    assert list(alone) == [kind] and alone[kind] == mixed[kind]
    assert alone[kind] != env_kwargs(compose_config("train", f"perturbations={kind}"))["perturbations"][kind]


def test_an_unknown_option_is_refused_by_hydra():
    with pytest.raises(ConfigCompositionException, match="perturbations"):
        compose_config("train", "perturbations=hail")


@pytest.mark.slow
def test_a_perturbed_run_plays_its_days_outages(script_overrides, tmp_path):
    run = tmp_path / "run"
    proc = run_script(
        "train.py",
        *script_overrides,
        "agent=queue_aware",
        "eval.episodes=3",
        "eval.baselines=[]",
        "perturbations=outages",
        "perturbations.outages.per_day=20",
        "perturbations.outages.start_window=[18000,23400]",
        f"hydra.run.dir={run}",
    )
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert data["config"]["perturbations"]["outages"]["per_day"] == 20
    cfg = compose_config(
        "train",
        *script_overrides,
        "perturbations=outages",
        "perturbations.outages.per_day=20",
        "perturbations.outages.start_window=[18000,23400]",
    )
    env = ChargingNavEnv(**split_kwargs(cfg, "eval", 0))
    try:  # the days the run evaluated on have outages in the window, in their cache keys
        assert all(day.outages and "outages" in day.fields for day in env.world.days)
    finally:
        env.close()


#: Perturbation settings (over perturbations=outages) train.py refuses before SUMO starts, and what its
#: message says.
BAD_PERTURBATIONS = [
    ("perturbations.outages.per_day=-1", "perturbations.outages.per_day"),
    ("perturbations.outages.minutes=[100,10]", "perturbations.outages.minutes=[100, 10]"),
    ("+perturbations.rain={factor: 0.8}", "perturbations.rain.factor: unknown"),
    ("+perturbations.rain={speed_factor: 1.5}", "perturbations.rain.speed_factor"),
    ("+perturbations.incidents={minutes: [0, 30]}", "perturbations.incidents.minutes=[0, 30]"),
    ("+perturbations.roadworks={lanes_closed: -1}", "perturbations.roadworks.lanes_closed"),
]
#: train.py's forecast rule on the oracle (the last case run by ``refused``), and what its message says.
ORACLE = (["agent=queue_forecast", "env.observe=[forecast]", "env.forecaster=oracle"],
          "env.forecaster=oracle reads the day's own future")  # fmt: skip


@pytest.fixture(scope="module")
def refused(
    script_overrides: list[str], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[tuple[int, str]]]:
    """Every case of :data:`BAD_PERTURBATIONS`, then :data:`ORACLE`, run by train.py in one process
    (:func:`run_refusals`), each into its own run directory with its own snapshot cache."""
    root = shared_folder(tmp_path_factory, "perturbations_script_refused")
    kept = [o for o in script_overrides if not o.startswith("env.cache_dir=")]
    args = [["agent=greedy", "perturbations=outages", override] for override, _ in BAD_PERTURBATIONS]
    cases = [[*kept, *extra, f"env.cache_dir={root / f'cache{i}'}", f"hydra.run.dir={root / f'run{i}'}"]
             for i, extra in enumerate([*args, ORACLE[0]])]  # fmt: skip
    return root, run_refusals("train.py", cases, root)


@pytest.mark.slow
@pytest.mark.parametrize(
    "case", range(len(BAD_PERTURBATIONS)), ids=[override for override, _ in BAD_PERTURBATIONS]
)
def test_bad_perturbations_stop_the_run_before_sumo(refused, case):
    root, runs = refused
    code, log = runs[case]
    assert code == 2, log[-2000:]
    assert not (root / f"cache{case}").exists()  # no day was simulated
    assert BAD_PERTURBATIONS[case][1] in log


@pytest.mark.slow
def test_a_learner_trains_on_the_observation_options_in_a_perturbed_world(script_overrides, tmp_path):
    """A DQN with ``env.observe=[points_in_service,route_time]`` in a mixed world: it trains and is
    evaluated beside queue_aware reading the same blocks; its saved policy evaluates in the same
    world, and a world without the options is refused, naming the sizes, before any episode."""
    world = [
        *script_overrides, "perturbations=mixed", "perturbations.incidents.start_window=[21600,23400]",
        "perturbations.rain.chance=1", "perturbations.rain.start_window=[21700,22000]",
        "perturbations.rain.hours=[0.1,0.2]",
        "perturbations.outages.start_window=[21600,23400]", "env.observe=[points_in_service,route_time]",
    ]  # fmt: skip
    run = tmp_path / "run"
    proc = run_script(
        "train.py", *world, "agent=dqn", "learner.hidden=[16]", "learner.learning_starts=4",
        "learner.batch_size=4", "train.episodes=4", "train.checkpoint_every=2", "eval.episodes=2",
        "eval.baselines=[queue_aware]", "eval.bootstrap_resamples=100", f"hydra.run.dir={run}",
    )  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "SUMO error" not in proc.stdout + proc.stderr  # the roads played into every batch cleanly
    data = json.loads((run / "results.json").read_text())
    assert data["config"]["env"]["observe"] == ["points_in_service", "route_time"]
    assert (
        data["agent"] == "dqn" and len(data["episodes"]) == 2 and list(data["baselines"]) == ["queue_aware"]
    )
    ev = tmp_path / "eval"
    proc = run_script("evaluate.py", *world, "agent=dqn", f"agent.checkpoint={run}", "episodes=1",
                      f"hydra.run.dir={ev}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    plain = [o for o in world if not o.startswith("env.observe")]
    proc = run_script("evaluate.py", *plain, "agent=dqn", f"agent.checkpoint={run}", "episodes=1",
                      f"hydra.run.dir={tmp_path / 'refused'}")  # fmt: skip
    log = proc.stdout + proc.stderr
    assert proc.returncode == 2 and "observe" in log, log[-2000:]


@pytest.mark.slow
def test_the_forecast_rule_runs_on_the_training_days_history_and_the_oracle_is_refused(
    script_overrides, refused, tmp_path
):
    """train.py with env.observe=[forecast]: the history forecaster learns from the training days
    (the environments are given them), queue_forecast plays beside queue_aware; the oracle stops the
    run before SUMO, and so does evaluate.py's history without forecast_days."""
    run = tmp_path / "run"
    proc = run_script("train.py", *script_overrides, "agent=queue_forecast", "env.observe=[forecast]",
                      "eval.episodes=3", "eval.baselines=[queue_aware]", f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    data = json.loads((run / "results.json").read_text())
    assert data["agent"] == "queue_forecast" and list(data["baselines"]) == ["queue_aware"]
    cfg = compose_config("train", *script_overrides, "env.observe=[forecast]")
    assert split_kwargs(cfg, "eval", 0)["forecast_days"] == tuple(cfg.days.train)
    root, runs = refused  # train.py's oracle: the last case of the batched refusals
    code, log = runs[len(BAD_PERTURBATIONS)]
    assert code == 2, log[-2000:]
    assert not (root / f"cache{len(BAD_PERTURBATIONS)}").exists()  # no day was simulated
    assert ORACLE[1] in log, log[-2000:]
    log = run_refused("evaluate.py", script_overrides, "agent=queue_forecast", "env.observe=[forecast]",
                      f"hydra.run.dir={tmp_path / 'evaluate.py'}", cache=tmp_path / "cache")  # fmt: skip
    assert "forecaster=history needs training days: forecast_days=[...]" in log, log[-2000:]
