"""Day snapshots: simulate a background day once, start every episode from a saved state.

A *day* is everything that shapes the background traffic of one simulated day: the scenario files, the
charging points, the demand (config and seed, or a fixed route file), SUMO's step length and teleport
threshold, the versions of SUMO, numpy (which draws the demand) and sumolib (which reads the network), and
the evcd code that generates and drives the day. Its :class:`DaySpec` hashes all of that into a key;
:class:`DayCache` keeps, in a folder named by the key,

    routes.rou.xml.gz            the day's demand (generated once)
    state_<t>.xml.gz             SUMO state at time t (:meth:`SumoDriver.save_state`)
    charging_<t>.json            ChargingController state at time t (``state_dict()``)
    manifest.json                files and their SHA-256, written last and atomically
    .lock                        fcntl lock: one process builds, the others wait and reuse

A file that the manifest does not list, or whose checksum differs, is never used: the missing snapshots are
rebuilt by simulating the day again from 00:00 (always from 00:00, so that every snapshot is a state of the
uninterrupted day, as in the paper protocol). Snapshots are only saved for the times an episode can start
from (see :func:`snapshot_times`).

The cache lives in ``$EVCD_CACHE``, else ``$XDG_CACHE_HOME/evcd``, else ``~/.cache/evcd``
(:func:`default_cache_dir`); the folder is safe to delete.

SUMO 1.28's loadState and how evcd copes (tested in ``tests/sim/test_snapshots.py`` and ``tests/env``):

- parked vehicles must be removed before a load (segfault otherwise): :meth:`SumoDriver.load_state`;
- random number generators are not restored: the vehicle types drive with ``sigma = 0`` and the demand
  writes per-vehicle speed factors, so nothing random is drawn inside SUMO;
- vehicles departing after the snapshot come from the route file, which SUMO re-reads after a load but
  without the vehicles it already took from a *later* snapshot: the environment restarts SUMO before going
  back in time (:mod:`evcd.env.simulation`);
- the charging queues live in Python: each snapshot carries the controller's ``state_dict()``;
- the state is not restored bit for bit (routing weights, some car-park bookkeeping), so a run continued
  from a snapshot may drift from the uninterrupted day by a step here and there:
  :mod:`evcd.bench.equivalence` measures the effect on travel times.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import math
import os
import time as wallclock
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from evcd.scenario.demand import generate_demand, write_demand
from evcd.sim.charging import ChargingController
from evcd.sim.day_spec import DaySpec
from evcd.sim.driver import SumoDriver
from evcd.sim.road_player import attach
from evcd.utils.atomic import atomic_write_text
from evcd.utils.digest import file_sha256

log = logging.getLogger(__name__)

CACHE_ENV = "EVCD_CACHE"
MANIFEST = "manifest.json"
ROUTES = "routes.rou.xml.gz"
_ENTRY_FIELDS = {"state", "state_sha256", "controller", "controller_sha256"}
_told = [False]  # whether the one-time explanation of a day build was logged in this process
# a progress bar over simulated time (of day) with the wall time left
_BAR = "{desc}: {percentage:3.0f}% of {total:.0f} sim s [{elapsed}<{remaining}]"


def default_cache_dir() -> Path:
    """``$EVCD_CACHE``, else ``$XDG_CACHE_HOME/evcd``, else ``~/.cache/evcd``."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "evcd"


def snapshot_times(window: tuple[float, float], every: float) -> list[float]:
    """Snapshot times an episode departing in ``[window[0], window[1])`` may start from.

    Multiples of ``every`` from the last one at or before the window's start to the last one
    before its end.
    """
    lo, hi = window
    if every <= 0:
        raise ValueError(f"snapshot_every={every}: must be > 0")
    first = math.floor(lo / every)
    last = max(first, math.ceil(hi / every) - 1)
    return [float(k * every) for k in range(first, last + 1)]


@dataclass(frozen=True)
class Snapshot:
    """One saved moment of a day."""

    time: float
    state: Path
    controller: Path
    state_sha256: str
    controller_sha256: str


class CacheError(RuntimeError):
    """The cache could not be read or built."""


class DayCache:
    """The snapshots of one day in the cache folder (shared by runs and processes).

    Args:
        spec: the day.
        cache_dir: the cache root; default :func:`default_cache_dir`.

    Raises:
        ValueError: the cache root is a file.
    """

    def __init__(self, spec: DaySpec, cache_dir: str | Path | None = None) -> None:
        self.spec = spec
        self.root = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
        if self.root.exists() and not self.root.is_dir():
            source = "cache_dir" if cache_dir is not None else f"${CACHE_ENV} (or the default cache folder)"
            raise ValueError(f"the day cache {self.root} (from {source}) is a file, not a folder: point it "
                             "at a folder, or unset it for ~/.cache/evcd")  # fmt: skip
        self._verified: dict[Path, tuple[int, int]] = {}  # path -> (size, mtime_ns) when checked
        self._snapshots: dict[float, Snapshot] = {}
        self.built_times: list[float] = []  # snapshot times this object built (0 if it reused all)

    @cached_property
    def dir(self) -> Path:
        """The day's folder (``<root>/days/<key>``)."""
        return self.root / "days" / self.spec.key

    @property
    def routes_file(self) -> Path:
        """The day's route file (the given one, or the generated one in the cache)."""
        return self.spec.route_file if self.spec.route_file is not None else self.dir / ROUTES

    # ------------------------------------------------------------------ public
    def ensure_routes(self) -> Path:
        """Generate the day's route file unless a verified one is cached; return its path."""
        if self.spec.route_file is not None:
            return self.spec.route_file
        if self._valid_routes(self._read_manifest()):
            return self.routes_file
        with self._locked():
            manifest = self._read_manifest()
            if not self._valid_routes(manifest):
                manifest = self._write_routes()
        return self.routes_file

    def ensure(self, times: Sequence[float]) -> list[Snapshot]:
        """Make sure snapshots at ``times`` exist and are intact (build what is missing).

        Returns them in time order. Builds run under the day's lock, so processes that need the
        same day wait for one build instead of repeating it.
        """
        wanted = sorted({float(t) for t in times})
        missing = self._missing(self._read_manifest(), wanted)
        if missing:
            with self._locked():
                manifest = self._read_manifest()  # another process may have built meanwhile
                missing = self._missing(manifest, wanted)
                if missing:
                    self._build(manifest, missing)
        snaps = [self._snapshots[t] for t in wanted]
        return snaps

    def has(self, times: Sequence[float]) -> bool:
        """Whether intact snapshots at all ``times`` are cached (nothing is built)."""
        return not self._missing(self._read_manifest(), sorted({float(t) for t in times}))

    def latest_before(self, time: float) -> Snapshot:
        """The snapshot (among those :meth:`ensure` returned) with the latest time <= ``time``."""
        best = [t for t in self._snapshots if t <= time + 1e-9]
        if not best:
            raise KeyError(f"no snapshot at or before t={time} (have {sorted(self._snapshots)})")
        return self._snapshots[max(best)]

    def load(self, snapshot: Snapshot, driver: SumoDriver, controller: ChargingController) -> float:
        """Restore ``snapshot`` into a running ``driver`` (for this day) and ``controller``.

        The files are checked again if they changed on disk since :meth:`ensure` verified them.

        Raises:
            CacheError: a snapshot file is missing or corrupted (call :meth:`ensure` to rebuild).
        """
        for path, sha in (
            (snapshot.state, snapshot.state_sha256),
            (snapshot.controller, snapshot.controller_sha256),
        ):
            if not self._check(path, sha):
                self._snapshots.pop(snapshot.time, None)
                raise CacheError(f"snapshot file {path} is missing or corrupted")
        state = json.loads(snapshot.controller.read_text(encoding="utf-8"))
        t = driver.load_state(snapshot.state)
        controller.load_state_dict(state)
        return t

    def make_driver(self, **kwargs: Any) -> SumoDriver:
        """An (unstarted) :class:`SumoDriver` for this day; ``kwargs`` override its options."""
        sc = self.spec.scenario
        options = {
            "seed": self.spec.sumo_seed,
            "step_length": self.spec.step_length,
            "time_to_teleport": self.spec.time_to_teleport,
            "warnings": False,
        }
        options.update(kwargs)
        return SumoDriver(sc.net_file, sc.additional_files, [self.routes_file], **options)

    def size_bytes(self) -> int:
        """Bytes the day's folder holds."""
        return sum(p.stat().st_size for p in self.dir.glob("*") if p.is_file())

    # ------------------------------------------------------------------ manifest and checks
    def _read_manifest(self) -> dict[str, Any]:
        path = self.dir / MANIFEST
        try:
            manifest = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            log.warning("day cache %s: unreadable manifest (%s); rebuilding", self.dir, exc)
            return {}
        if not isinstance(manifest, dict) or manifest.get("key") != self.spec.key:
            log.warning("day cache %s: manifest of another day; rebuilding", self.dir)
            return {}
        return manifest

    def _write_manifest(self, manifest: dict[str, Any]) -> None:
        manifest = {**manifest, "key": self.spec.key, "fields": self.spec.fields}
        atomic_write_text(self.dir / MANIFEST, json.dumps(manifest, indent=1, sort_keys=True))

    def _check(self, path: Path, sha: str | None) -> bool:
        """Whether ``path`` exists and has checksum ``sha`` (re-hashed only when it changed)."""
        try:
            st = path.stat()
        except FileNotFoundError:
            return False
        stamp = (st.st_size, st.st_mtime_ns)
        if self._verified.get(path) == stamp:
            return True
        ok = sha is not None and file_sha256(path) == sha
        if ok:
            self._verified[path] = stamp
        else:
            self._verified.pop(path, None)
            log.warning("day cache: %s does not match its checksum; it will be rebuilt", path)
        return ok

    def _valid_routes(self, manifest: dict[str, Any]) -> bool:
        if self.spec.route_file is not None:
            return True
        entry = manifest.get("routes")
        return entry is not None and self._check(self.dir / ROUTES, entry.get("sha256"))

    def _missing(self, manifest: dict[str, Any], wanted: list[float]) -> list[float]:
        if not self._valid_routes(manifest):
            return wanted
        entries = manifest.get("snapshots", {})
        missing = []
        for t in wanted:
            entry = entries.get(_tkey(t))
            if not isinstance(entry, dict) or not entry.keys() >= _ENTRY_FIELDS:
                missing.append(t)
                continue
            snap = Snapshot(
                t,
                self.dir / entry["state"],
                self.dir / entry["controller"],
                entry["state_sha256"],
                entry["controller_sha256"],
            )
            if self._check(snap.state, snap.state_sha256) and self._check(
                snap.controller, snap.controller_sha256
            ):
                self._snapshots[t] = snap
            else:
                missing.append(t)
        return missing

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        self.dir.mkdir(parents=True, exist_ok=True)
        with open(self.dir / ".lock", "a+") as f:
            t0 = wallclock.perf_counter()
            fcntl.flock(f, fcntl.LOCK_EX)
            waited = wallclock.perf_counter() - t0
            if waited > 1.0:
                log.info("day cache %s: waited %.1f s for another process", self.dir, waited)
            try:
                yield
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)

    # ------------------------------------------------------------------ building (under the lock)
    def _write_routes(self) -> dict[str, Any]:
        spec = self.spec
        assert spec.demand is not None
        demand = generate_demand(
            spec.scenario.net, list(spec.scenario.stations), spec.demand, spec.demand_seed
        )
        write_demand(demand, self.dir / ROUTES)
        manifest = {"routes": {"file": ROUTES, "sha256": file_sha256(self.dir / ROUTES)}, "snapshots": {}}
        self._write_manifest(manifest)  # new routes: every older snapshot is void
        return manifest

    def _build(self, manifest: dict[str, Any], missing: list[float], progress: bool = True) -> None:
        if not self._valid_routes(manifest):
            manifest = self._write_routes() if self.spec.route_file is None else {"snapshots": {}}
        if SumoDriver.active() is not None:
            raise CacheError("building day snapshots needs this process's libsumo: close the running one")
        t0 = wallclock.perf_counter()
        entries = dict(manifest.get("snapshots", {}))
        controller = ChargingController(self.spec.scenario.stations, outages=self.spec.outages)
        log.info(
            "day cache %s: simulating the day to %.0f s for %d snapshots", self.dir, missing[-1], len(missing)
        )
        if not _told[0]:
            _told[0] = True
            log.warning(
                "simulating a background day once to cache its snapshots (a few minutes per day, only "
                "the first time a day is used; later runs load them): %s", self.dir.parent,
            )  # fmt: skip
        with (
            self.make_driver() as driver,
            tqdm(total=missing[-1], unit="sim s", desc="background day", mininterval=2.0,
                 disable=not progress, bar_format=_BAR) as bar,
        ):  # fmt: skip
            driver.add_listener(controller.update)
            attach(driver, self.spec.roads)  # the day's incidents, rain and road works, if any
            for t in missing:
                driver.step(until=t)
                bar.update(t - bar.n)
                name = _tkey(t)
                state = driver.save_state(self.dir / f"state_{name}.xml.gz")
                ctrl = atomic_write_text(
                    self.dir / f"charging_{name}.json", json.dumps(controller.state_dict())
                )
                snap = Snapshot(t, state, ctrl, file_sha256(state), file_sha256(ctrl))
                entries[name] = {
                    "time": t,
                    "state": state.name,
                    "state_sha256": snap.state_sha256,
                    "controller": ctrl.name,
                    "controller_sha256": snap.controller_sha256,
                }
                self._snapshots[t] = snap
                self._verified.pop(state, None)
                self._verified.pop(ctrl, None)
        wall = wallclock.perf_counter() - t0
        self._write_manifest({**manifest, "snapshots": entries, "last_build_wall_s": round(wall, 3)})
        self.built_times = list(missing)
        log.info("day cache %s: built %d snapshots in %.1f s", self.dir, len(missing), wall)


def _tkey(t: float) -> str:
    """File-name form of a snapshot time (zero-padded seconds, decimals only if needed)."""
    return f"{t:08.0f}" if float(t).is_integer() else f"{t:010.3f}"
