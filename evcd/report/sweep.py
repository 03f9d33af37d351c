"""Read a Hydra multirun sweep of ``scripts/train.py``: which jobs finished, which are missing or failed.

    collection = collect([Path("outputs/train_multirun/2026-11-23_10-00-00")])
    for job in collection.jobs: ...  # JobResult: regime, agent, evs, seed and the job's results.json

The sweep's ``multirun.yaml`` names its overrides (``hydra.overrides.task``); their cartesian product
(Hydra's own override parser and sweep iteration, :func:`expand_sweep`) is the set of jobs expected.
Each job subdirectory is matched to its combination through its ``.hydra/overrides.yaml``. A combination
without a subdirectory is *missing*, a subdirectory without a readable ``results.json`` has *failed*
(:class:`JobGap`, with the last error of the job's log, or, where its log has none, as a job stopped
or still running); either stops :func:`collect`
(:class:`IncompleteSweepError`) unless ``allow_incomplete``. A plain run directory (``results.json``
and ``.hydra/``) counts as a sweep of one job.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import math
import re
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol

from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from evcd.env.observation import OPTIONS
from evcd.loops.run_files import RESULTS_JSON
from evcd.report.stamp import JobStamp, job_stamp

log = logging.getLogger(__name__)

# the names Hydra writes
MULTIRUN_YAML = "multirun.yaml"
OVERRIDES_YAML = Path(".hydra") / "overrides.yaml"


class ResultsError(ValueError):
    """The inputs cannot make a table (not a run directory, duplicated jobs, ...)."""


class WrongTaskError(ResultsError):
    """A finished job of the other task (a fleet run in the single target's table, or the reverse):
    the whole table is refused, since its jobs are not missing but of another kind."""


class IncompleteSweepError(ResultsError):
    """Jobs of a sweep are missing or failed; :attr:`gaps` lists them."""

    def __init__(self, gaps: Sequence[JobGap], expected: int) -> None:
        self.gaps = tuple(gaps)
        lines = "\n".join(f"  {g.describe()}" for g in self.gaps)
        super().__init__(
            f"{len(self.gaps)} of {expected} expected jobs did not finish (allow_incomplete builds the table "
            f"from the others and lists these):\n{lines}"
        )


@dataclass(frozen=True)
class JobResult:
    """One finished job, from its ``results.json`` (NaN where it has null): a row of the results table.

    ``eval_days`` are the days its evaluation episodes ran on (from the episodes themselves), with
    the mean travel time on each in ``day_means``.
    """

    KEY_NAMES: ClassVar[tuple[str, ...]] = ("regime", "agent", "evs", "seed")
    regime: str
    agent: str
    evs: int
    seed: int
    eval_episodes: int
    completed: int
    truncated: int
    mean_travel_time: float
    median_travel_time: float
    ci_low: float
    ci_high: float
    mean_queue_wait: float
    train_episodes: int
    train_mean_travel_time: float
    train_wall_s: float
    day_build_s: float
    train_days: tuple[int, ...]
    eval_days: tuple[int, ...]
    day_means: tuple[tuple[int, float], ...]  # per evaluation day: (day, mean travel time)
    environment: str  # the environment's versioned id; the four provenance columns: evcd.report.stamp
    evcd: str
    commit: str
    machine: str
    job_dir: Path
    #: per evaluation episode: (reset seed, travel time; NaN if truncated), for paired comparisons
    episode_travel: tuple[tuple[int, float], ...] = dataclasses.field(default=(), repr=False, compare=False)
    #: the periodic held-out validation: (training episodes done, mean travel time) per point
    validation: tuple[tuple[int, float], ...] = dataclasses.field(default=(), repr=False, compare=False)
    #: the rules' mean travel times on the same validation episodes, by rule
    validation_rules: tuple[tuple[str, float], ...] = dataclasses.field(default=(), repr=False, compare=False)

    @property
    def stamp(self) -> JobStamp:
        """Where the job's numbers come from (environment, code, machine)."""
        return JobStamp(self.environment, self.evcd, self.commit, self.machine)

    @property
    def key(self) -> tuple[str, str, int, int]:
        """``(regime, agent, evs, seed)``: what a job stands for in the tables."""
        return self.regime, self.agent, self.evs, self.seed


class Job(Protocol):
    """What :func:`collect` needs of a job: the cell it stands for (``key``, its fields named by
    ``KEY_NAMES``) and its directory (a single-target :class:`JobResult`, or a fleet job,
    :class:`evcd.report.fleet_table.FleetJob`)."""

    KEY_NAMES: ClassVar[tuple[str, ...]]

    @property
    def key(self) -> tuple[Any, ...]: ...

    @property
    def job_dir(self) -> Path: ...


#: Reads a job's parsed ``results.json`` (raising KeyError, TypeError or ValueError if malformed).
Parser = Callable[[Mapping[str, Any], Path], Any]


@dataclass(frozen=True)
class JobGap:
    """A job expected but not finished: ``status`` is ``"missing"`` (no subdirectory) or ``"failed"``."""

    status: str
    overrides: tuple[str, ...]
    job_dir: Path | None
    reason: str = ""

    def describe(self) -> str:
        """One line naming the job by its overrides, its directory and why it has no results."""
        where = f" in {self.job_dir}" if self.job_dir is not None else ""
        why = f": {self.reason}" if self.reason else ""
        return f"{self.status}: {' '.join(self.overrides) or '(no overrides)'}{where}{why}"


@dataclass(frozen=True)
class Collection:
    """The finished jobs (sorted by their ``key``) and the gaps of the directories read."""

    jobs: tuple[Any, ...]
    gaps: tuple[JobGap, ...]
    expected: int
    sources: tuple[Path, ...]


# ---------------------------------------------------------------------------------------- overrides
def _parse(overrides: Sequence[str]) -> list[Any]:
    try:
        return OverridesParser.create().parse_overrides(list(overrides))
    except Exception as exc:  # Hydra's parse errors share no base class with ValueError
        raise ResultsError(f"cannot parse the overrides {list(overrides)}: {exc}") from exc


def expand_sweep(task_overrides: Sequence[str]) -> list[tuple[str, ...]]:
    """The jobs a basic-sweeper multirun of ``task_overrides`` runs: each job's override strings.

    ``["agent=random,greedy", "seed=range(2)", "evs=200"]`` gives four jobs, e.g.
    ``("agent=random", "seed=0", "evs=200")``; a key given twice keeps its last value, as Hydra does.

    Raises:
        ResultsError: an override does not parse, or is a sweep that cannot be enumerated (interval).
    """
    axes: dict[str, list[str]] = {}
    for override in _parse(task_overrides):
        key = override.get_key_element()
        if not override.is_sweep_override():
            axes[key] = [f"{key}={override.get_value_element_as_str()}"]
        elif override.is_discrete_sweep():
            axes[key] = [f"{key}={value}" for value in override.sweep_string_iterator()]
        else:
            raise ResultsError(f"{override.input_line}: a {override.value_type.name} cannot be enumerated")
    return [tuple(combo) for combo in itertools.product(*axes.values())]


def canonical_overrides(overrides: Sequence[str]) -> frozenset[tuple[str, str]]:
    """Overrides as (key, value) pairs, spelled as Hydra's parser spells them (``progress=false`` and
    ``progress=False`` are one override)."""
    return frozenset((o.get_key_element(), o.get_value_element_as_str()) for o in _parse(overrides))


# ---------------------------------------------------------------------------------------- the jobs
def _load_yaml(path: Path) -> Any:
    try:
        return OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    except Exception as exc:  # OmegaConf/yaml errors
        raise ResultsError(f"{path}: unreadable ({exc})") from exc


#: Overrides that never change a job's results: a run continued from its checkpoint is the job it
#: continues, and where the days are cached is where, not what (the cache is safe to delete).
NOT_DEFINING = frozenset({"resume", "env.cache_dir"})


def job_defining(overrides: Any) -> list[str]:
    """Overrides but those of :data:`NOT_DEFINING`: what makes a job the job it is."""
    return [str(o) for o in overrides or () if str(o).partition("=")[0].lstrip("+~") not in NOT_DEFINING]


def _task_overrides(sweep_dir: Path) -> list[str]:
    data = _load_yaml(sweep_dir / MULTIRUN_YAML)
    try:
        task = data["hydra"]["overrides"]["task"]
    except (KeyError, TypeError) as exc:
        raise ResultsError(f"{sweep_dir / MULTIRUN_YAML}: no hydra.overrides.task") from exc
    return job_defining(task)


def job_overrides(job_dir: Path) -> tuple[str, ...]:
    """The overrides a run directory records (``.hydra/overrides.yaml``; none if it has no record), but
    those that never change its results (:data:`NOT_DEFINING`: ``resume``, ``env.cache_dir``)."""
    path = job_dir / OVERRIDES_YAML
    return tuple(job_defining(_load_yaml(path))) if path.is_file() else ()


def _log_reason(job_dir: Path) -> str:
    """The last error of the job's log: the exception line of the last traceback, or the last ERROR line."""
    logs = sorted(job_dir.glob("*.log"), key=lambda p: p.name != "train.log")
    if not logs:
        return ""
    lines = [line.rstrip() for line in logs[0].read_text(errors="replace").splitlines()]
    traceback = max((i for i, line in enumerate(lines) if line.startswith("Traceback")), default=-1)
    error = max((i for i, line in enumerate(lines) if re.search(r"\bERROR\b", line)), default=-1)
    if traceback > error:  # the frames are indented; the exception follows them
        tail = [line for line in lines[traceback + 1 :] if line.strip() and not line.startswith(" ")]
        return f"{logs[0].name}: {tail[0] if tail else lines[traceback]}"
    return f"{logs[0].name}: {lines[error].strip()}" if error >= 0 else ""


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


def day_list(value: Any) -> tuple[int, ...]:
    """The days of a saved config's list (any sequence but a string; anything else: none)."""
    return tuple(int(d) for d in value) if isinstance(value, Sequence) and not isinstance(value, str) else ()


def world_label(config: Mapping[str, Any]) -> str:
    """A run's world: its regime, the kinds of perturbation it played, and the observation options'
    blocks its agents saw, with the forecaster behind ``F`` where it is not the default ``history``
    (``"peak"`` for a calm run without them; ``"fleet +outages sees PTF (anomaly)"``)."""
    regime = str(config.get("regime") or "unknown")
    kinds = sorted(k for k, v in (config.get("perturbations") or {}).items() if v is not None)
    env = config.get("env") or {}
    seen = "".join(OPTIONS[o] for o in OPTIONS if o in (env.get("observe") or ()))
    forecaster = env.get("forecaster") or "history"
    name = str(forecaster.get("name") if isinstance(forecaster, Mapping) else forecaster)
    if "F" in seen and name != "history":
        seen += f" ({name})"
    return regime + (f" +{'/'.join(kinds)}" if kinds else "") + (f" sees {seen}" if seen else "")


def job_result(data: Mapping[str, Any], job_dir: Path) -> JobResult:
    """The :class:`JobResult` of a job's parsed ``results.json``.

    Raises:
        WrongTaskError: a fleet run.
        KeyError, TypeError, ValueError: a field is missing or malformed.
    """
    if data.get("task") == "fleet":
        raise WrongTaskError(f"{job_dir} is a fleet run (task=fleet): make its table with "
                             "scripts/make_table.py --fleet")  # fmt: skip
    summary, training = data["summary"], data.get("training") or {}
    config = data.get("config")
    if not isinstance(config, Mapping):
        raise KeyError("config")
    episodes = data.get("episodes") or []
    validation = data.get("validation") or {}
    played = sorted({int(e["day"]) for e in episodes if int(e.get("day", -1)) >= 0})
    configured = (config.get("eval") or {}).get("days", (config.get("env") or {}).get("demand_seeds"))
    travel = tuple((int(e["seed"]), math.nan if e["truncated"] else float(e["travel_time"]))
                   for e in episodes)  # fmt: skip
    day_means = []
    for day in played:
        charged = [float(e["travel_time"]) for e in episodes if int(e["day"]) == day and not e["truncated"]]
        day_means.append((day, sum(charged) / len(charged) if charged else math.nan))
    return JobResult(
        regime=world_label(config),  # a perturbed or better-informed world is a table of its own
        agent=str(data["agent"]),
        evs=int(config["evs"]),
        seed=int(data["seed"]),
        eval_episodes=int(summary["episodes"]),
        completed=int(summary["completed"]),
        truncated=int(summary["truncated"]),
        mean_travel_time=_float(summary["mean_travel_time"]),
        median_travel_time=_float(summary["median_travel_time"]),
        ci_low=_float(summary["ci_low"]),
        ci_high=_float(summary["ci_high"]),
        mean_queue_wait=_float(summary["mean_queue_wait"]),
        train_episodes=int(training.get("episodes", 0)),
        train_mean_travel_time=_float(training.get("mean_travel_time")),
        train_wall_s=_float(training.get("wall_s", 0.0)),
        day_build_s=_float(training.get("day_build_s", 0.0)),
        train_days=day_list((config.get("train") or {}).get("days")),
        eval_days=tuple(played) if played else day_list(configured),
        day_means=tuple(day_means),
        **dataclasses.asdict(job_stamp(data)),
        job_dir=job_dir,
        episode_travel=travel,
        validation=tuple(
            (int(p["episodes_done"]), _float(p.get("mean"))) for p in validation.get("points", ())
        ),
        validation_rules=tuple((str(k), _float(v)) for k, v in (validation.get("rule_means") or {}).items()),
    )


def read_job(job_dir: Path, overrides: Sequence[str] = (), parse: Parser = job_result) -> Any:
    """The job's results (``parse`` of its ``results.json`` and its run directory, links resolved: a
    rendering's view of a sweep names where each job ran; a :class:`JobResult` by default), or a
    ``"failed"`` :class:`JobGap` if ``results.json`` is absent or unreadable."""
    path = job_dir / RESULTS_JSON
    if not path.is_file():
        error = _log_reason(job_dir) or "no error in its log: stopped, or still running"
        reason = f"no {RESULTS_JSON}; {error}"
        return JobGap("failed", tuple(overrides), job_dir, reason)
    try:
        return parse(json.loads(path.read_text()), job_dir.resolve())
    except WrongTaskError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as exc:
        reason = f"{RESULTS_JSON} unreadable ({type(exc).__name__}: {exc})"
        return JobGap("failed", tuple(overrides), job_dir, reason)


def _collect_sweep(sweep_dir: Path, parse: Parser) -> tuple[list[Any], list[JobGap], int]:
    expected = expand_sweep(_task_overrides(sweep_dir))
    found: dict[frozenset[tuple[str, str]], list[Path]] = defaultdict(list)
    for path in sorted(sweep_dir.glob(f"*/{OVERRIDES_YAML.as_posix()}")):
        job_dir = path.parent.parent
        found[canonical_overrides(job_overrides(job_dir))].append(job_dir)
    jobs: list[Any] = []
    gaps: list[JobGap] = []
    for combo in expected:
        read = [read_job(d, combo, parse) for d in found.pop(canonical_overrides(combo), [])]
        done = [r for r in read if not isinstance(r, JobGap)]
        if not read:
            gaps.append(JobGap("missing", combo, None, f"no job directory in {sweep_dir}"))
        elif done:
            jobs += done
            for r in read:
                if isinstance(r, JobGap):
                    log.info("%s: superseded by a finished job of the same overrides", r.describe())
        else:
            gaps += [r for r in read if isinstance(r, JobGap)]
    for dirs in found.values():  # not in the sweep's product (e.g. a run copied in): used, with a warning
        for job_dir in dirs:
            r = read_job(job_dir, job_overrides(job_dir), parse)
            log.warning("%s: not a job of the sweep %s; %s", job_dir, sweep_dir,
                        "ignored (no results)" if isinstance(r, JobGap) else "included")  # fmt: skip
            if not isinstance(r, JobGap):
                jobs.append(r)
    log.info("%s: %d of %d expected jobs finished", sweep_dir, len(jobs), len(expected))
    return jobs, gaps, len(expected)


def collect(
    dirs: Sequence[str | Path], allow_incomplete: bool = False, parse: Parser = job_result
) -> Collection:
    """Read the jobs of multirun directories (``multirun.yaml``) and single run directories, each
    ``results.json`` through ``parse`` (single-target jobs by default).

    Raises:
        IncompleteSweepError: a job is missing or failed and ``allow_incomplete`` is false.
        ResultsError: a directory is neither kind, two finished jobs stand for the same cell (their
            ``key``), or no job finished.
    """
    if not dirs:
        raise ResultsError("no directory given")
    jobs: list[Any] = []
    gaps: list[JobGap] = []
    expected = 0
    for d in map(Path, dirs):
        if (d / MULTIRUN_YAML).is_file():
            more_jobs, more_gaps, n = _collect_sweep(d, parse)
        elif (d / RESULTS_JSON).is_file() or (d / ".hydra").is_dir():
            r = read_job(d, job_overrides(d), parse)
            more_jobs, more_gaps, n = ([], [r], 1) if isinstance(r, JobGap) else ([r], [], 1)
        else:
            raise ResultsError(f"{d}: neither a multirun directory (no {MULTIRUN_YAML}) nor a run directory "
                               f"(no {RESULTS_JSON}, no .hydra/)")  # fmt: skip
        jobs += more_jobs
        gaps += more_gaps
        expected += n
    by_key: dict[tuple[Any, ...], list[Path]] = defaultdict(list)
    for job in jobs:
        by_key[job.key].append(job.job_dir)
    twice = {k: v for k, v in by_key.items() if len(v) > 1}
    if twice:
        names = type(jobs[0]).KEY_NAMES
        lines = "\n".join("  " + " ".join(f"{n}={x}" for n, x in zip(names, k, strict=False)) + ": "
                          + ", ".join(map(str, v)) for k, v in twice.items())  # fmt: skip
        raise ResultsError(f"jobs stand for the same ({', '.join(names)}) and would be averaged "
                           f"together; pass directories without the duplicates:\n{lines}")  # fmt: skip
    if gaps and not allow_incomplete:
        raise IncompleteSweepError(gaps, expected)
    if not jobs:
        raise ResultsError(f"no finished job in {', '.join(map(str, dirs))}")
    for gap in gaps:
        log.warning("%s", gap.describe())
    jobs.sort(key=lambda job: job.key)
    return Collection(tuple(jobs), tuple(gaps), expected, tuple(map(Path, dirs)))
