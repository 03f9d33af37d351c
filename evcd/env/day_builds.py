"""A world's background days built side by side before the first episode needs them.

    built = build_days(config, days=[0, 2, 3], workers=2)     # {day: wall s}, each in a process of its own

A day not cached is simulated once (:class:`~evcd.sim.snapshots.DayCache`, a few minutes on Jurong
West) in a SUMO of its own, and libsumo runs one simulation per process: days built one after the
other leave every other core idle, and so does a sweep whose jobs wait for each other's builds (the
cache's lock lets one process build a day, the others wait). :func:`build_days` starts one fresh
Python process per day missing (``python -m evcd.env.day_builds``: a plain subprocess, so it works
inside a launcher's worker process whatever that worker's multiprocessing setup, and nothing that
holds libsumo is forked), ``workers`` at a time, each rebuilding the world from its
:class:`~evcd.env.config.EnvConfig` (the scenario cannot be sent to a process) and building that day
under the cache's lock, so that processes of other runs that need the same day still build it once.
A built day is the same files whichever process built it.
"""

from __future__ import annotations

import logging
import os
import pickle
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO

from evcd.env.config import EnvConfig
from evcd.sim.snapshots import DayCache

log = logging.getLogger(__name__)

#: The last lines of a failed build's output that its error quotes.
TAIL_LINES = 20


class DayBuildError(RuntimeError):
    """A day's build process failed (the message quotes the end of its output)."""


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def build_days(config: EnvConfig, days: Sequence[int], workers: int) -> dict[int, float]:
    """Build the snapshots of each of ``days`` (indices into the world's days) in processes of their
    own, ``workers`` at a time; the wall time of each, by day (a day another process had built or was
    building takes the time it waited).

    Raises:
        DayBuildError: a build process failed (its day and the end of its output named).
    """
    if not days:
        return {}
    workers = max(1, min(workers, len(days)))
    t0 = time.perf_counter()
    walls: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="evcd_day_build_") as tmp:
        recipe = Path(tmp) / "config.pickle"
        recipe.write_bytes(pickle.dumps(config))
        todo, running = list(days), []
        while todo or running:
            while todo and len(running) < workers:
                day = todo.pop(0)
                out = open(Path(tmp) / f"day{day}.log", "w+b")  # noqa: SIM115  (closed when it ends)
                command = [sys.executable, "-m", "evcd.env.day_builds", str(recipe), str(day)]
                process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=child_env())
                running.append((day, process, out, time.perf_counter()))
            time.sleep(0.2)
            for entry in [e for e in running if e[1].poll() is not None]:
                running.remove(entry)
                day, process, out, started = entry
                walls[day] = time.perf_counter() - started
                tail = output_tail(out)
                out.close()
                if process.returncode != 0:
                    for _, other, other_out, _ in running:
                        other.kill()
                        other.wait()
                        other_out.close()
                    raise DayBuildError(f"building day {day} in a process of its own failed (exit "
                                        f"{process.returncode}):\n" + "\n".join(tail))  # fmt: skip
    each = ", ".join(f"day {d}: {walls[d]:.1f} s" for d in days)
    log.info("built %d background days %d at a time in %.1f s (%s)", len(days), workers,
             time.perf_counter() - t0, each)  # fmt: skip
    return {d: walls[d] for d in days}


def output_tail(out: IO[bytes]) -> list[str]:
    """The last :data:`TAIL_LINES` lines a child process wrote to ``out`` (its open log file)."""
    out.seek(0)
    return out.read().decode(errors="replace").splitlines()[-TAIL_LINES:]


def child_env() -> dict[str, str]:
    """This process's environment, the folder that holds this evcd first on the import path (so that
    a child finds the same evcd, installed or a checkout run in place)."""
    home = str(Path(__file__).resolve().parents[2])
    rest = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != home]
    return {**os.environ, "PYTHONPATH": os.pathsep.join([home, *rest])}


def _build_day(config: EnvConfig, day: int) -> None:
    """Day ``day`` of the world of ``config`` made ready (its snapshots built if missing, as the world's
    simulation would: :meth:`~evcd.env.simulation.EpisodeSimulation.prepare`). The parent times it."""
    _, days = config.load()
    times = config.snapshot_times()
    DayCache(days[day], config.cache_dir).ensure(times)


def main(argv: Sequence[str]) -> int:
    """``python -m evcd.env.day_builds CONFIG_PICKLE DAY``: build one day (what :func:`build_days` runs)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    config = pickle.loads(Path(argv[0]).read_bytes())
    _build_day(config, int(argv[1]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
