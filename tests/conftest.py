"""Shared fixtures and helpers: small real SUMO scenarios generated in the session, environments on
them, and the scripts run as a user runs them (a subprocess) or composed as Hydra composes them.

- ``small_scenario``: a 4 x 4 grid with two stations (hand-built days, :mod:`tests.env.handmade`);
- :func:`make_grid_scenario` / ``grid_env_dir``: an 8 x 8 grid with three stations; ``make_env`` makes
  environments on it with a light, short background day (:data:`GRID_ENV`);
- ``make_fleet`` / ``make_small_fleet``: fleets (:mod:`evcd.env.fleet`) on the 8 x 8 grid and on
  hand-built days of the small grid;
- :func:`run_script`, :func:`run_refusals`, :func:`compose_config` and ``script_overrides`` (a tiny run
  of a script on the 8 x 8 grid): what the script tests share.

The session's scenarios and snapshot caches are built once per test run, not once per pytest-xdist
worker: they live in a folder every worker of the run shares (:func:`shared_folder`), and the first
worker that needs one builds it under a lock while the others wait (the day caches lock each day
themselves).
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sumolib
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from evcd.env import ChargingNavEnv
from evcd.env.fleet import FleetEnv, parallel_env
from evcd.experiments.schema import register_configs
from evcd.scenario.placement import place_stations
from evcd.scenario.scenario import STATIONS_FILE, VTYPES_FILE
from evcd.scenario.stations_file import Station, write_stations
from evcd.scenario.vtypes import write_vtypes
from evcd.utils.sumo_tools import run_tool

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
SCRIPTS = ROOT / "scripts"


def shared_folder(
    tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], Any] | None = None
) -> Path:
    """The folder ``name`` that every pytest-xdist worker of this test run shares (under the run's
    temporary root; without xdist, under the session's own), made once: the first worker to ask runs
    ``build(folder)`` (:func:`build_once`), the others wait and reuse it. For whatever a test module
    makes once and several tests read (a scenario, a training run, a batch of refused runs): a
    module-scoped fixture alone is made again on every worker its tests land on."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name
    folder.mkdir(exist_ok=True)
    build_once(folder, "folder", (lambda: build(folder)) if build is not None else (lambda: None))
    return folder


def build_once(folder: Path, name: str, build: Callable[[], Any]) -> None:
    """Run ``build()`` once per ``name`` in ``folder`` across the processes of this test run: under a
    lock in the folder, unless a marker says an earlier call finished (a build that failed is redone)."""
    with open(folder / f".{name}.lock", "a+") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / f".{name}.done").exists():
            build()
            (folder / f".{name}.done").touch()


@pytest.fixture(scope="session", autouse=True)
def _isolated_snapshot_cache(tmp_path_factory: pytest.TempPathFactory):
    """Day snapshots built by tests (and the scripts they start) go to a temporary cache, never ~/.cache."""
    patch = pytest.MonkeyPatch()
    patch.setenv("EVCD_CACHE", str(shared_folder(tmp_path_factory, "evcd_cache")))
    yield
    patch.undo()


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Small networks: one torch thread is faster and keeps the numbers independent of the machine."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# ---------------------------------------------------------------------------------------- scenarios
@dataclass(frozen=True)
class SmallScenario:
    """A 4 x 4 left-hand grid (200 m blocks, one lane per direction) with two stations.

    ``cs1`` (2 points) sits on ``B1C1``, ``cs2`` (1 point) on ``C2B2``; ``A1B1 B1C1 C1D1`` drives
    past ``cs1``'s car park.
    """

    root: Path
    net_file: Path
    stations_file: Path
    vtypes_file: Path
    stations: tuple[Station, ...]

    @property
    def additional_files(self) -> list[Path]:
        """Vehicle types first: route files refer to them."""
        return [self.vtypes_file, self.stations_file]


SMALL_STATIONS = (
    Station(id="cs1", name="one", lane="B1C1_0", start_pos=60.0, end_pos=100.0, points=2),
    Station(id="cs2", name="two", lane="C2B2_0", start_pos=60.0, end_pos=100.0, points=1),
)


def _build_small_scenario(root: Path) -> None:
    run_tool("netgenerate", ["--grid", "--grid.number", 4, "--grid.length", 200, "--lefthand", "-o",
                             root / "grid.net.xml"])  # fmt: skip
    write_stations(list(SMALL_STATIONS), root / "stations.add.xml")
    write_vtypes(root / "vtypes.add.xml")


@pytest.fixture(scope="session")
def small_scenario(tmp_path_factory: pytest.TempPathFactory) -> SmallScenario:
    root = shared_folder(tmp_path_factory, "small_scenario", _build_small_scenario)
    return SmallScenario(root, root / "grid.net.xml", root / "stations.add.xml", root / "vtypes.add.xml",
                         SMALL_STATIONS)  # fmt: skip


def make_grid(path: Path, number: int = 8, length: float = 250.0) -> Path:
    """A left-hand grid network with 2-lane streets."""
    run_tool(
        "netgenerate",
        [
            "--grid", "--grid.number", number, "--grid.length", length,
            "--default.lanenumber", 2, "--default.speed", 13.89,
            "--lefthand", "--no-turnarounds", "false", "-o", path,
        ],
    )  # fmt: skip
    return path


def make_grid_scenario(folder: Path, k: int = 3, spacing: float = 700.0) -> Path:
    """A complete scenario folder on an 8 x 8 grid: network, stations, vehicle types."""
    folder.mkdir(parents=True, exist_ok=True)
    net_file = make_grid(folder / "grid.net.xml")
    net = sumolib.net.readNet(str(net_file))
    write_stations(place_stations(net, k, spacing, np.random.default_rng(0)), folder / STATIONS_FILE)
    write_vtypes(folder / VTYPES_FILE)
    return folder


# ---------------------------------------------------------------------------------------- environments
#: A light background day on the 8 x 8 grid with every departure in the first two hours, so that its
#: snapshots build in a couple of seconds and the paper protocol, stopped at PAPER_DAY_END, takes a
#: few seconds per episode.
GRID_DEMAND: dict[str, Any] = {
    "cars_per_day": 800,
    "evs": 40,
    "min_trip_m": 500.0,
    "charging_share": 0.5,
    "hourly_profile": [8.0, 8.0] + [0.0] * 22,
}
WINDOW = (1800.0, 3600.0)
PAPER_DAY_END = 5400.0
GRID_ENV: dict[str, Any] = {
    "demand": GRID_DEMAND,
    "departure_window": WINDOW,
    "snapshot_every": 300.0,
    "day_end": PAPER_DAY_END,
}


@pytest.fixture(scope="session")
def grid_env_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A scenario folder on the 8 x 8 grid (do not modify: shared by the session)."""
    return shared_folder(tmp_path_factory, "grid_env", make_grid_scenario)


@pytest.fixture(scope="session")
def env_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A snapshot cache shared by the session's environments (days are built once)."""
    return shared_folder(tmp_path_factory, "env_cache")


class EnvFactory:
    """Makes environments one at a time (libsumo: one simulation per process); closes them all."""

    def __init__(self) -> None:
        self.made = 0
        self._envs: list[ChargingNavEnv] = []

    def make(self, **kwargs: Any) -> ChargingNavEnv:
        self.close()
        env = ChargingNavEnv(**kwargs)
        self._envs.append(env)
        self.made += 1
        return env

    def close(self) -> None:
        for env in self._envs:
            env.close()


@pytest.fixture
def make_env(grid_env_dir: Path, env_cache: Path) -> Iterator[Callable[..., ChargingNavEnv]]:
    """``make_env(**overrides)``: a grid environment, closed after the test (one libsumo at a time)."""
    factory = EnvFactory()
    yield lambda **overrides: factory.make(
        **{"scenario": grid_env_dir, "cache_dir": env_cache, **GRID_ENV, **overrides}
    )
    factory.close()


@pytest.fixture
def make_small_env(
    small_scenario: SmallScenario, env_cache: Path, tmp_path: Path
) -> Iterator[Callable[..., ChargingNavEnv]]:
    """``make_small_env(vehicles, **overrides)``: an environment whose background day is the
    hand-built ``vehicles`` (see ``tests/env/handmade.py``) on the small 4 x 4 grid."""
    from tests.env.handmade import write_routes

    factory = EnvFactory()

    def make(vehicles: list[str], **overrides: Any) -> ChargingNavEnv:
        routes = write_routes(tmp_path / f"day{factory.made}.rou.xml", vehicles)
        kwargs = {
            "scenario": small_scenario.root,
            "route_file": routes,
            "departure_window": (0.0, 600.0),
            "snapshot_every": 100.0,
            "cache_dir": env_cache,
            **overrides,
        }
        return factory.make(**kwargs)

    yield make
    factory.close()


def run_episode(
    env: ChargingNavEnv,
    seed: int,
    policy: Callable[[Any], int] | None = None,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Play one episode (greedy by ``D`` unless ``policy``); return its observations, actions, info."""
    m = int(env.action_space.n)
    obs, info = env.reset(seed=seed, options=options)
    observations, actions, rewards = [obs], [], []
    while True:
        action = policy(obs) if policy is not None else int(obs[:m].argmin())
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(reward)
        if terminated or truncated:
            return {
                "observations": observations,
                "actions": actions,
                "rewards": rewards,
                "terminated": terminated,
                "info": info,
            }


# ---------------------------------------------------------------------------------------- the fleet
#: A busier grid day: ~70 charging EVs in two hours, ~15 of them departing in the fleet's window.
FLEET_DEMAND = {**GRID_DEMAND, "evs": 120, "charging_share": 0.6}
FLEET_WINDOW = (1200.0, 3000.0)


@pytest.fixture
def make_fleet(grid_env_dir: Path, env_cache: Path) -> Iterator[Callable[..., FleetEnv]]:
    """``make_fleet(**overrides)``: a fleet on the 8 x 8 grid, closed after the test."""
    made: list[FleetEnv] = []

    def make(**overrides: Any) -> FleetEnv:
        for env in made:
            env.close()
        kwargs = {"scenario": grid_env_dir, "cache_dir": env_cache, "demand": FLEET_DEMAND,
                  "departure_window": FLEET_WINDOW, **overrides}  # fmt: skip
        made.append(parallel_env(**kwargs))
        return made[-1]

    yield make
    for env in made:
        env.close()


@pytest.fixture
def make_small_fleet(
    small_scenario: SmallScenario, env_cache: Path, tmp_path: Path
) -> Iterator[Callable[..., FleetEnv]]:
    """``make_small_fleet(vehicles, **overrides)``: a fleet whose day is the hand-built ``vehicles``
    on the 4 x 4 grid (``cs1``: index 0, 2 points; ``cs2``: index 1, 1 point)."""
    from tests.route_xml import write_routes

    made: list[FleetEnv] = []

    def make(vehicles: list[str], **overrides: Any) -> FleetEnv:
        for env in made:
            env.close()
        routes = write_routes(tmp_path / f"fleet{len(made)}.rou.xml", vehicles)
        kwargs = {"scenario": small_scenario.root, "route_file": routes, "departure_window": (0.0, 300.0),
                  "snapshot_every": 100.0, "cache_dir": env_cache, "decision_interval": 10.0,
                  **overrides}  # fmt: skip
        made.append(FleetEnv(**kwargs))
        return made[-1]

    yield make
    for env in made:
        env.close()


# ---------------------------------------------------------------------------------------- scripts
def run_script(
    script: str, *args: str, timeout: float = 900, cwd: Path = ROOT, code: str | None = None
) -> subprocess.CompletedProcess[str]:
    """``python scripts/<script> args...`` as a user runs it (or ``python -c code args...``)."""
    cmd = [sys.executable, "-c", code] if code is not None else [sys.executable, str(SCRIPTS / script)]
    return subprocess.run([*cmd, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def run_refused(script: str, overrides: Sequence[str], *args: str, cache: Path) -> str:
    """Run ``script`` with settings it must refuse before SUMO starts: on its own snapshot cache
    ``cache`` (in place of the overrides' ``env.cache_dir``) it exits with code 2 and simulates no day
    (``cache`` is never made). Returns its output (stdout + stderr) for the message."""
    kept = [o for o in overrides if not o.startswith("env.cache_dir=")]
    proc = run_script(script, *kept, f"env.cache_dir={cache}", *args)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 2, log[-2000:]
    assert not cache.exists()  # no day was simulated
    return log


#: Runs a script's ``__main__`` once per argument list of a JSON file, in this one process, and writes
#: each run's exit code and output (stdout and stderr) to another JSON file.
_REFUSALS_DRIVER = """
import contextlib, io, json, logging, runpy, sys
from hydra.core.global_hydra import GlobalHydra
script, cases, results = sys.argv[1:4]
out = []
for args in json.loads(open(cases).read()):
    buf, code = io.StringIO(), 0
    logging.getLogger().handlers.clear()  # the last run's handlers write to its own buffer
    sys.argv = [script, *args]
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            runpy.run_path(script, run_name="__main__")
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    GlobalHydra.instance().clear()
    out.append({"code": code, "log": buf.getvalue()})
open(results, "w").write(json.dumps(out))
"""


def run_refusals(script: str, cases: Sequence[Sequence[str]], folder: Path) -> list[tuple[int, str]]:
    """Run ``scripts/<script>`` once per argument list of ``cases``, as ``python scripts/<script> args``
    runs it (its ``__main__``: Hydra composes, the script checks, a refusal exits with code 2), all in
    ONE fresh Python process: the many bad-setting cases of a script pay its start once. Returns each
    run's exit code and output. ``folder`` holds the case and result files; in a folder of
    :func:`shared_folder` the cases run once for the whole test run (:func:`build_once`)."""
    import json

    folder.mkdir(parents=True, exist_ok=True)
    cases_file, results_file = folder / "cases.json", folder / "results.json"

    def run() -> None:
        cases_file.write_text(json.dumps([[str(a) for a in case] for case in cases]))
        proc = run_script(script, str(SCRIPTS / script), cases_file, results_file, code=_REFUSALS_DRIVER)
        assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]

    build_once(folder, f"refusals_{script}", run)
    return [(r["code"], r["log"]) for r in json.loads(results_file.read_text())]


def compose_config(config_name: str, *overrides: str, return_hydra_config: bool = False) -> DictConfig:
    """The config a script composes (``train``, ``evaluate``, ``inspect``) with ``overrides``."""
    register_configs(CONF)
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name, overrides=list(overrides), return_hydra_config=return_hydra_config)


@pytest.fixture(scope="session")
def script_grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The 8 x 8 grid scenario the script tests run on (read-only: shared by the session)."""
    folder = shared_folder(tmp_path_factory, "script_grid", lambda root: make_grid_scenario(root / "grid"))
    return folder / "grid"


@pytest.fixture(scope="session")
def script_overrides(script_grid: Path, tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """Overrides for a tiny, quick run of a script on the grid (its own snapshot cache, built once)."""
    cache = shared_folder(tmp_path_factory, "script_cache")
    return [
        f"scenario.path={script_grid}", "evs=30", "scenario.demand.cars_per_day=300",
        "scenario.demand.min_trip_m=500", "env.departure_window=[21600,23400]", f"env.cache_dir={cache}",
        "progress=false",
    ]  # fmt: skip
