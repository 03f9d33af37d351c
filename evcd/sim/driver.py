"""One SUMO simulation, owned by one object.

:class:`SumoDriver` is the only place in evcd that starts, steps, snapshots and closes SUMO. It runs
SUMO in-process through libsumo (fast, one simulation per process) or, for ``sumo-gui``, through a
TraCI connection; both expose the same API as :attr:`SumoDriver.api`, so callers write
``driver.api.vehicle.getRoadID(vid)`` whatever the backend.

    with SumoDriver("net.net.xml", ["stations.add.xml"], ["routes.rou.xml"], seed=7) as driver:
        driver.add_listener(controller.update)   # called after every simulation step
        driver.step(until=3600)
"""

from __future__ import annotations

import contextlib
import gzip
import itertools
import logging
import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, ClassVar

import libsumo
from traci.exceptions import FatalTraCIError
from traci.exceptions import TraCIException as TraciTraCIException

from evcd.utils.sumo_tools import binary

log = logging.getLogger(__name__)

#: Exceptions a SUMO API call may raise (libsumo and TraCI have distinct classes).
SUMO_ERRORS: tuple[type[Exception], ...] = (libsumo.TraCIException, TraciTraCIException, FatalTraCIError)

#: A step listener: called as ``fn(api, time)`` after every simulation step.
StepListener = Callable[[Any, float], None]

_EPS = 1e-6
_labels = itertools.count()


@contextlib.contextmanager
def _captured_stderr() -> Iterator[list[str]]:
    """Redirect file descriptor 2 (where SUMO's C++ code writes) into a list of lines.

    libsumo reports a failed start as a bare ``TraCIException('Process Error')`` and prints the
    reason to the process's stderr; capturing the descriptor is the only way to put the reason into
    the exception we raise.
    """
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines.extend(tmp.read().decode("utf-8", errors="replace").splitlines())


def _check_net_head(path: Path, head_bytes: int = 1 << 18) -> None:
    """Reject a file that cannot be a SUMO network before SUMO sees it.

    SUMO 1.28 (libsumo and the ``sumo`` binary alike) segfaults on a ``<net>`` without its
    ``<location>`` element, which kills the Python process. Every network written by netconvert or
    netgenerate has it within the first few kilobytes (after the options comment).
    """
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rb") as f:
            head = f.read(head_bytes)
    except OSError as exc:
        raise RuntimeError(f"cannot read SUMO network {path}: {exc}") from exc
    if b"<location" not in head:
        raise RuntimeError(
            f"{path} is not a SUMO network: no <location> element near its top "
            "(write networks with netconvert/netgenerate)"
        )


class SumoDriver:
    """Owns one SUMO simulation: command line, start, step, snapshots, close.

    Args:
        net_file: the SUMO network (``.net.xml``).
        additional_files: additional files (stations, vehicle types, ...), loaded in order.
        route_files: route/demand files.
        seed: SUMO's random seed (``--seed``); derive it from the run's generator.
        begin: simulation begin time (s).
        end: simulation end time (s); ``None`` runs until the demand is exhausted. (libsumo keeps
            stepping past it when :meth:`step` asks.)
        step_length: simulation step (s).
        time_to_teleport: seconds a vehicle may be stuck before SUMO teleports it; ``-1`` disables.
        warnings: ``False`` adds ``--no-warnings``.
        state_precision: decimals of the values in saved states (SUMO's default, 2, rounds positions
            to centimetres, so a run continued from a snapshot drifts from the uninterrupted one).
        gui: run ``sumo-gui`` through TraCI (for looking at a scenario, not for training).
        use_traci: run headless ``sumo`` through TraCI instead of libsumo (slow; for tests and
            for running several simulations in one process).
        extra_args: further SUMO options, appended last.

    Only one libsumo simulation may run per process: starting a second one while another is running
    raises ``RuntimeError`` (libsumo itself would silently replace the first).
    """

    _libsumo_owner: ClassVar[SumoDriver | None] = None

    def __init__(
        self,
        net_file: str | Path,
        additional_files: Sequence[str | Path] = (),
        route_files: Sequence[str | Path] = (),
        *,
        seed: int,
        begin: float = 0.0,
        end: float | None = None,
        step_length: float = 1.0,
        time_to_teleport: float = 300.0,
        warnings: bool = True,
        state_precision: int = 8,
        gui: bool = False,
        use_traci: bool = False,
        extra_args: Sequence[str] = (),
    ) -> None:
        if step_length <= 0:
            raise ValueError(f"step_length={step_length} must be > 0")
        if end is not None and end <= begin:
            raise ValueError(f"end={end} must be > begin={begin}")
        self.net_file = Path(net_file)
        self.additional_files = [Path(p) for p in additional_files]
        self.route_files = [Path(p) for p in route_files]
        self.seed = int(seed)
        self.begin = float(begin)
        self.end = None if end is None else float(end)
        self.step_length = float(step_length)
        self.time_to_teleport = float(time_to_teleport)
        self.warnings = warnings
        self.state_precision = int(state_precision)
        self.gui = gui
        self.use_traci = use_traci or gui
        self.extra_args = [str(a) for a in extra_args]
        self._api: Any = None
        self._listeners: list[StepListener] = []

    # ------------------------------------------------------------------ command line and life cycle
    def command(self) -> list[str]:
        """The full SUMO command line this driver starts (binary first)."""
        cmd = [binary("sumo-gui" if self.gui else "sumo"), "--net-file", str(self.net_file)]
        if self.additional_files:
            cmd += ["--additional-files", ",".join(map(str, self.additional_files))]
        if self.route_files:
            cmd += ["--route-files", ",".join(map(str, self.route_files))]
        cmd += [
            "--seed", str(self.seed),
            "--begin", f"{self.begin:g}",
            "--step-length", f"{self.step_length:g}",
            "--time-to-teleport", f"{self.time_to_teleport:g}",
            "--no-step-log", "true",
            "--save-state.precision", str(self.state_precision),
        ]  # fmt: skip
        if self.end is not None:
            cmd += ["--end", f"{self.end:g}"]
        if not self.warnings:
            cmd += ["--no-warnings", "true"]
        if self.gui:
            cmd += ["--start", "true"]
        return cmd + self.extra_args

    def start(self) -> SumoDriver:
        """Start the simulation; return ``self``.

        Raises:
            FileNotFoundError: an input file does not exist.
            RuntimeError: this driver already runs, another libsumo simulation runs in this
                process, or SUMO refused the inputs (the message carries SUMO's own error).
        """
        if self._api is not None:
            raise RuntimeError("this SumoDriver is already running")
        for path in [self.net_file, *self.additional_files, *self.route_files]:
            if not path.is_file():
                raise FileNotFoundError(f"SUMO input file not found: {path}")
        _check_net_head(self.net_file)
        cmd = self.command()
        log.debug("starting SUMO: %s", " ".join(cmd))
        if self.use_traci:
            self._api = self._start_traci(cmd)
        else:
            self._api = self._start_libsumo(cmd)
        return self

    def _start_libsumo(self, cmd: list[str]) -> Any:
        owner = SumoDriver._libsumo_owner
        if owner is not None or libsumo.simulation.isLoaded():
            raise RuntimeError(
                "a libsumo simulation is already running in this process"
                + (f" (net {owner.net_file})" if owner is not None else "")
                + "; close it first, or run each simulation in its own process"
            )
        with _captured_stderr() as lines:
            try:
                libsumo.start(cmd)
                failure = None
            except SUMO_ERRORS as exc:
                failure = exc
        if failure is not None:
            if libsumo.simulation.isLoaded():  # e.g. a bad route: the network stays loaded
                with contextlib.suppress(*SUMO_ERRORS):
                    libsumo.close()
            reason = "\n".join(lines) or str(failure)
            raise RuntimeError(f"SUMO failed to start: {reason}\ncommand: {' '.join(cmd)}") from failure
        for line in lines:  # loading warnings go through logging, not the raw console
            log.warning("sumo: %s", line)
        SumoDriver._libsumo_owner = self
        return libsumo

    def _start_traci(self, cmd: list[str]) -> Any:
        import traci  # only the GUI / TraCI path needs the socket client

        label = f"evcd-{os.getpid()}-{next(_labels)}"
        try:
            traci.start(cmd, label=label)
        except (*SUMO_ERRORS, OSError) as exc:
            raise RuntimeError(f"SUMO (TraCI) failed to start: {exc}\ncommand: {' '.join(cmd)}") from exc
        return traci.getConnection(label)

    def close(self) -> None:
        """Close the simulation (idempotent); a new driver may start afterwards."""
        api, self._api = self._api, None
        if api is None:
            return
        if SumoDriver._libsumo_owner is self:
            SumoDriver._libsumo_owner = None
        try:
            api.close()
        except SUMO_ERRORS as exc:  # closing a simulation that already died must not mask the cause
            log.warning("error while closing SUMO: %s", exc)

    def __enter__(self) -> SumoDriver:
        if self._api is None:
            self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @classmethod
    def active(cls) -> SumoDriver | None:
        """The driver that runs this process's libsumo simulation, if any."""
        return cls._libsumo_owner

    # ------------------------------------------------------------------ running
    @property
    def api(self) -> Any:
        """The SUMO API: the ``libsumo`` module or a TraCI connection (same methods)."""
        if self._api is None:
            raise RuntimeError("SumoDriver is not running; call start() or use it as a context manager")
        return self._api

    @property
    def running(self) -> bool:
        """Whether the simulation is started and not closed."""
        return self._api is not None

    @property
    def time(self) -> float:
        """Current simulation time (s)."""
        return self.api.simulation.getTime()

    def add_listener(self, listener: StepListener) -> None:
        """Call ``listener(api, time)`` after every simulation step, in registration order."""
        self._listeners.append(listener)

    def remove_listener(self, listener: StepListener) -> None:
        """Stop calling ``listener``."""
        self._listeners.remove(listener)

    def step(self, until: float | None = None) -> float:
        """Advance one step, or step until the time reaches ``until``; return the new time.

        Listeners run after every single step, so with listeners registered this loops step by step;
        without them it hands ``until`` to SUMO in one call.
        """
        api = self.api
        if until is None:
            api.simulationStep()
            self._notify(api)
        elif not self._listeners:
            if until > api.simulation.getTime() + _EPS:
                api.simulationStep(until)
        else:
            while api.simulation.getTime() < until - _EPS:
                api.simulationStep()
                self._notify(api)
        return api.simulation.getTime()

    def _notify(self, api: Any) -> None:
        if self._listeners:
            now = api.simulation.getTime()
            for listener in self._listeners:
                listener(api, now)

    # ------------------------------------------------------------------ snapshots
    def save_state(self, path: str | Path) -> Path:
        """Save the simulation state to ``path`` atomically (temp file in the same folder + rename).

        SUMO picks the format from the name: ``.xml``, or ``.xml.gz`` compressed (1.28 writes XML
        whatever the name, also for the once-binary ``.sbx``).
        Step listeners keep their own state (e.g. :meth:`ChargingController.state_dict`).
        """
        path = Path(path)
        api = self.api
        # same folder (atomic rename) and same suffixes (SUMO chooses the format from the name)
        tmp = path.with_name(f".tmp-{os.getpid()}-{path.name}")
        try:
            api.simulation.saveState(str(tmp))
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return path

    def load_state(self, path: str | Path) -> float:
        """Replace the running simulation's state by the snapshot at ``path``; return its time.

        Restore step listeners' state separately (e.g. ``controller.load_state_dict``).

        SUMO 1.28 crashes (segfault) when a state with parked vehicles is loaded while vehicles are
        parked, so parked vehicles are removed first; the loaded state replaces them anyway.

        Raises:
            FileNotFoundError: no such snapshot.
            RuntimeError: SUMO could not load it.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"SUMO state file not found: {path}")
        api = self.api
        capture = _captured_stderr() if not self.use_traci else contextlib.nullcontext([])
        with capture as lines:
            try:
                for pa in api.parkingarea.getIDList():
                    for vid in api.parkingarea.getVehicleIDs(pa):
                        api.vehicle.remove(vid)
                api.simulation.loadState(str(path))
                failure = None
            except SUMO_ERRORS as exc:
                failure = exc
        # the removals above print one "aborts stop" warning per parked vehicle: expected noise
        lines = [line for line in lines if "aborts stop" not in line]
        if failure is not None:
            reason = "\n".join(lines) or str(failure)
            raise RuntimeError(f"SUMO failed to load state {path}: {reason}") from failure
        for line in lines:
            log.warning("sumo: %s", line)
        return api.simulation.getTime()
