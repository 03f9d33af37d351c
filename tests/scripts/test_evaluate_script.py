"""``scripts/evaluate.py`` end to end (real Hydra, real SUMO, grid scenario) and its configs."""

from __future__ import annotations

import csv
import inspect
import json
import subprocess
from dataclasses import asdict
from importlib.metadata import version
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from evcd.agents import agent_names, make_agent_for_env
from evcd.env import ChargingNavEnv
from evcd.env.fleet import FleetEnv
from evcd.experiments.worlds import demand_config, env_kwargs, fleet_kwargs
from evcd.loops.fleet_bound import fleet_dispatcher_names
from evcd.loops.hindsight import dispatcher_names, make_dispatcher
from evcd.loops.run_files import CSV_FIELDS
from evcd.scenario.demand import DemandConfig
from evcd.utils.provenance import git_commit
from tests.conftest import CONF, ROOT, compose_config, run_refusals, run_script, shared_folder

#: A fleet on the script grid: enough charging EVs departing 06:00-07:00 to guide.
FLEET = ["task=fleet", "evs=300", "scenario.demand.charging_share=0.6", "env.departure_window=[21600,25200]",
         "episodes=1"]  # fmt: skip

#: Set by the scenario group, the top-level `evs` or derived: not in conf/env.
NOT_IN_ENV_GROUP = {"self", "scenario", "evs", "charging_points", "demand", "perturbations"}


def run_evaluate(*overrides: str) -> subprocess.CompletedProcess:
    return run_script("evaluate.py", *overrides, timeout=600)


def compose_evaluate(*overrides: str):
    return compose_config("evaluate", *overrides)


@pytest.fixture(scope="module")
def scenario_dir(script_grid) -> Path:
    return script_grid


@pytest.fixture(scope="module")
def small(script_overrides) -> list[str]:
    """Overrides for a tiny, quick run on the grid."""
    return list(script_overrides)


# ---------------------------------------------------------------------------------------- configs
def test_env_group_equals_the_env_defaults():
    cfg = compose_evaluate()
    params = inspect.signature(ChargingNavEnv.__init__).parameters
    defaults = {k: p.default for k, p in params.items() if k not in NOT_IN_ENV_GROUP}
    yaml = OmegaConf.to_container(cfg.env)
    assert set(yaml) == set(defaults)
    for key, default in defaults.items():
        value = tuple(yaml[key]) if isinstance(default, tuple) else yaml[key]
        assert value == default and type(value) is type(default), key


def test_defaults_of_the_evaluate_config():
    cfg = compose_evaluate()
    assert (cfg.agent.name, cfg.evs, cfg.episodes, cfg.seed) == ("greedy", 400, 50, 0)
    assert cfg.scenario.path == "sumo_net/jurong_west"
    lib = asdict(DemandConfig())
    assert asdict(demand_config(cfg)) == lib


@pytest.mark.slow
def test_every_agent_config_builds_its_agent(scenario_dir):
    import numpy as np

    env = ChargingNavEnv(**env_kwargs(compose_evaluate(f"scenario.path={scenario_dir}")))  # no SUMO yet
    files = {p.stem for p in (CONF / "agent").glob("*.yaml")}
    assert files <= set(dispatcher_names()) | set(fleet_dispatcher_names())  # no file for an unknown agent
    named = set(dispatcher_names()) | set(fleet_dispatcher_names())
    assert named == {*agent_names(), "hindsight", "fleet_bound"}
    for name in dispatcher_names():
        params = OmegaConf.to_container(compose_evaluate(f"agent={name}").agent)
        assert params.pop("name") == name
        agent = make_dispatcher(name, env, np.random.default_rng(0), **params)
        assert agent.name == name and agent.n_stations == 3


def test_env_kwargs_resolve_paths_and_leave_demand_to_a_route_file(scenario_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    kw = env_kwargs(compose_evaluate("scenario.path=grid", "env.cache_dir=cache", "evs=7"))
    assert kw["scenario"] == str(tmp_path / "grid") and kw["cache_dir"] == str(tmp_path / "cache")
    assert kw["evs"] == 7 and kw["demand"].evs == 7 and kw["departure_window"] == (0.0, 86400.0)
    kw = env_kwargs(compose_evaluate("env.route_file=day.rou.xml"))
    assert kw["route_file"] == str(tmp_path / "day.rou.xml") and "evs" not in kw and "demand" not in kw


@pytest.mark.parametrize("override", ["no_such_option=3", "env.no_such_option=1", "agent.no_such_option=2"])
def test_unknown_keys_are_rejected_by_hydra(override):
    with pytest.raises(ConfigCompositionException, match="no_such_option"):
        compose_evaluate(override)


# ---------------------------------------------------------------------------------------- the script
@pytest.mark.slow
def test_evaluate_end_to_end(small, tmp_path):
    out = tmp_path / "run"
    proc = run_evaluate(*small, "agent=random", "episodes=2", "seed=4", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    with open(out / "episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 and tuple(rows[0]) == CSV_FIELDS
    data = json.loads((out / "results.json").read_text())
    assert {"agent", "seed", "summary", "episodes", "config"} <= set(data)
    assert data["agent"] == "random" and data["seed"] == 4 and data["config"]["episodes"] == 2
    # which environment and which code made the numbers (this checkout's commit)
    assert data["environment"] == "evcd/ChargingNav-v1"
    commit, dirty = git_commit(ROOT)
    assert data["code"] == {"evcd": version("evcd"), "commit": commit, "dirty": dirty}
    s = data["summary"]
    assert {"mean_travel_time", "median_travel_time", "ci_low", "ci_high", "truncated", "mean_wall_s"} <= set(
        s
    )
    assert s["episodes"] == 2 and s["completed"] + s["truncated"] == 2
    for row in rows:  # random keeps its first choice
        assert len(set(row["choices"].split("-"))) == 1
    log = proc.stdout + proc.stderr
    assert "mean travel time" in log and "95% CI" in log


@pytest.mark.slow
def test_a_sweep_writes_one_run_dir_per_job(small, tmp_path):
    sweep = tmp_path / "sweep"
    proc = run_evaluate("-m", *small, "agent=greedy,queue_aware", "episodes=1", f"hydra.sweep.dir={sweep}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    for job in ("0_greedy_evs30_seed0", "1_queue_aware_evs30_seed0"):
        data = json.loads((sweep / job / "results.json").read_text())
        assert data["agent"] == job.split("_", 1)[1].rsplit("_evs", 1)[0]
        assert (sweep / job / "episodes.csv").is_file()


#: Settings evaluate.py refuses before SUMO starts, and what its message says.
BAD_VALUES = [
    ("episodes=0", "episodes=0"),
    ("agent.name=dqnn", "dqnn"),
    ("evs=-1", "evs=-1"),
    ("evs=1.5", "evs=1.5"),
    ("env.protocol=slow", "protocol='slow'"),
]
#: Settings of task=fleet (over :data:`FLEET`) evaluate.py refuses before SUMO starts, and its message.
BAD_FLEET = [
    (["fleet.guided_share=0"], "guided_share=0"),
    (["fleet.guided_share=1.5"], "guided_share=1.5"),
    (["agent=hindsight"], "agent 'hindsight' is not an agent of task=fleet"),
    (["agent=dueling_ddqn"], "agent 'dueling_ddqn' learns: give the trained policy"),
    (["agent=dqn", "agent.checkpoint=nowhere"], "nowhere"),
    (["env.protocol=paper"], "env.protocol=paper is for the single target"),
    (["env.departure_window=[3600,3660]"], "nothing to guide"),
]
#: A fleet rule on the single task, refused: evaluate.py's message.
CENTRAL_ON_SINGLE = "agent 'central' reads the fleet's observation [D, N, Z, H]: use it with task=fleet"

#: A refused run: its run directory, exit code and output.
Refusal = tuple[Path, int, str]


@pytest.fixture(scope="module")
def refused(small: list[str], tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Refusal]]:
    """Every case of :data:`BAD_VALUES` and :data:`BAD_FLEET`, and agent=central on the single task, run
    by evaluate.py in one process (:func:`run_refusals`), each into its own run directory."""
    root = shared_folder(tmp_path_factory, "evaluate_script_refused")
    groups = {
        "single": [[*small, override] for override, _ in BAD_VALUES],
        "fleet": [[*small, *FLEET, *overrides] for overrides, _ in BAD_FLEET],
        "central": [[*small, "agent=central"]],
    }
    cases = [(name, case) for name, group in groups.items() for case in group]
    runs = run_refusals("evaluate.py", [[*case, f"hydra.run.dir={root / f'run{i}'}"]
                                        for i, (_, case) in enumerate(cases)], root)  # fmt: skip
    out: dict[str, list[Refusal]] = {name: [] for name in groups}
    for i, ((name, _), (code, log)) in enumerate(zip(cases, runs, strict=True)):
        out[name].append((root / f"run{i}", code, log))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(BAD_VALUES)), ids=[override for override, _ in BAD_VALUES])
def test_bad_values_stop_before_sumo(refused, case):
    out, code, log = refused["single"][case]
    assert code == 2, log[-2000:]
    assert BAD_VALUES[case][1] in log
    assert "simulating the day" not in log and not (out / "results.json").exists()


@pytest.mark.slow
def test_unknown_agent_group_lists_the_known_ones(tmp_path):
    proc = run_evaluate("agent=dqnn", f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode != 0
    assert "agent/dqnn" in proc.stderr and "greedy" in proc.stderr and "random" in proc.stderr


@pytest.mark.slow
def test_an_existing_results_file_is_not_overwritten(small, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "results.json").write_text("{}")
    proc = run_evaluate(*small, "episodes=1", f"hydra.run.dir={out}")
    assert proc.returncode == 2 and "results.json exists" in proc.stdout + proc.stderr
    assert (out / "results.json").read_text() == "{}" and not (out / "episodes.csv").exists()


# ---------------------------------------------------------------------------------------- task=fleet
@pytest.mark.slow
def test_the_fleet_task_composes_its_defaults_and_builds_every_fleet_rule(small):
    import numpy as np

    cfg = compose_evaluate("task=fleet")
    assert cfg.task == "fleet" and cfg.fleet.guided_share == 1.0
    assert cfg.episodes == compose_evaluate().episodes  # the task does not change how many
    assert list(cfg.env.departure_window) == [25200.0, 36000.0] and cfg.env.reward == "time"
    assert compose_evaluate().task == "single"
    cfg = compose_evaluate(*small, *FLEET, "fleet.guided_share=0.5")
    env = FleetEnv(**fleet_kwargs(cfg))  # no SUMO
    assert env.guided_share == 0.5 and env.config.departure_window == (21600.0, 25200.0)
    for name in agent_names("fleet"):
        params = OmegaConf.to_container(compose_evaluate(*small, *FLEET, f"agent={name}").agent)
        assert params.pop("name") == name
        assert make_agent_for_env(name, env, np.random.default_rng(0), **params).name == name


@pytest.mark.slow
def test_evaluate_a_fleet_end_to_end(small, tmp_path):
    out = tmp_path / "run"
    proc = run_evaluate(*small, *FLEET, "agent=reservation", "fleet.guided_share=0.5", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    with open(out / "fleet_episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1 and int(rows[0]["guided"]) >= 2
    assert int(rows[0]["guided_charged"]) + int(rows[0]["truncated"]) == int(rows[0]["guided"])
    data = json.loads((out / "results.json").read_text())
    s = data["summary"]
    assert s["guided_travel"] == pytest.approx(float(rows[0]["guided_travel"]))
    assert data["config"]["task"] == "fleet" and data["config"]["fleet"]["guided_share"] == 0.5
    assert data["environment"] == "evcd_fleet_v1" and data["code"]["evcd"] == version("evcd")
    assert (out / "fleet_trace.png").stat().st_size > 10_000
    assert "guided EVs" in proc.stdout + proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(BAD_FLEET)), ids=[" ".join(o) for o, _ in BAD_FLEET])
def test_bad_fleet_settings_stop_before_sumo(refused, case):
    out, code, log = refused["fleet"][case]
    assert code == 2, log[-2000:]
    assert BAD_FLEET[case][1] in log
    assert "simulating the day" not in log and not (out / "results.json").exists()


@pytest.mark.slow
def test_a_fleet_rule_on_the_single_task_is_refused(refused):
    ((_, code, log),) = refused["central"]
    assert code == 2
    assert CENTRAL_ON_SINGLE in log
