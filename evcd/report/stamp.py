"""What made a table: the environment's version, evcd's version and commit, and the machine of each job.

    stamp = job_stamp(results_json)               # one job's, from its parsed results.json
    lines = stamp_markdown(stamps, "evcd/ChargingNav-v1")

Every results page says which environment version, which code and which machine its numbers come from,
read from the ``environment``, ``code`` and ``machine`` records of its jobs' ``results.json``
(:mod:`evcd.loops.run_files`). A job made before those records existed reads ``not recorded``; a page
whose jobs ran on another version of the environment than today's says so in its first lines, so that
a reader never takes an old number for today's dynamics.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: What a field reads where a job's ``results.json`` has no record of it (made by older code).
NOT_RECORDED = "not recorded"


@dataclass(frozen=True)
class JobStamp:
    """Where one job's numbers come from.

    Attributes:
        environment: the environment's versioned id (``evcd/ChargingNav-v1``, ``evcd_fleet_v1``).
        evcd: evcd's version.
        commit: the git commit (full hash), ``not a git checkout`` or :data:`NOT_RECORDED`; with
            ``+ uncommitted changes`` where the checkout differed from it.
        machine: the CPU, the instruction set torch's kernels used and torch's version.
    """

    environment: str = NOT_RECORDED
    evcd: str = NOT_RECORDED
    commit: str = NOT_RECORDED
    machine: str = NOT_RECORDED


def job_stamp(data: Mapping[str, Any]) -> JobStamp:
    """The :class:`JobStamp` of a job's parsed ``results.json`` (:data:`NOT_RECORDED` where a record is
    missing)."""
    code = data.get("code") if isinstance(data.get("code"), Mapping) else {}
    commit = str(code.get("commit", NOT_RECORDED))
    if code.get("dirty"):
        commit += " + uncommitted changes"
    machine = data.get("machine")
    if isinstance(machine, Mapping):
        torch = (machine.get("packages") or {}).get("torch", "?")
        where = f"{machine.get('cpu', '?')} ({machine.get('cpu_capability', '?')}), torch {torch}"
    else:
        where = NOT_RECORDED
    return JobStamp(
        environment=str(data.get("environment", NOT_RECORDED)),
        evcd=str(code.get("evcd", NOT_RECORDED)),
        commit=commit,
        machine=where,
    )


#: The provenance columns of a table's csv (absent from one made before results recorded them).
STAMP_COLUMNS = ("environment", "evcd", "commit", "machine")


def row_stamp(row: Mapping[str, str]) -> JobStamp:
    """The :class:`JobStamp` of a csv row with the :data:`STAMP_COLUMNS` (:data:`NOT_RECORDED` where a
    column is missing or empty)."""
    return JobStamp(*(row.get(k) or NOT_RECORDED for k in STAMP_COLUMNS))


def _values(counts: Counter[str], total: int) -> str:
    if len(counts) == 1:
        return f"`{next(iter(counts))}`"
    return "; ".join(f"`{v}` ({n} of {total} jobs)" for v, n in sorted(counts.items()))


def stamp_markdown(stamps: Sequence[JobStamp], current: str) -> list[str]:
    """The page's provenance lines: each field's values over the jobs (with their counts where the jobs
    differ), and a warning first where any job ran on another environment than ``current`` (today's
    versioned id) or did not record it."""
    total = len(stamps)
    envs = Counter(s.environment for s in stamps)
    lines: list[str] = []
    older = total - envs.get(current, 0)
    if older:
        lines += [
            f"**Made with another environment than today's `{current}`** ({older} of {total} jobs: "
            f"{_values(envs, total)}): these numbers belong to the code named below, and a re-run with "
            "today's code may differ.",
            "",
        ]
    lines += [
        f"- Environment: {_values(envs, total)}",
        f"- evcd: {_values(Counter(s.evcd for s in stamps), total)}, commit "
        f"{_values(Counter(s.commit for s in stamps), total)}",
        f"- Machine: {_values(Counter(s.machine for s in stamps), total)}",
    ]
    return lines


def _short(commit: str) -> str:
    """A full hash shortened to git's 7 characters (other values, ``not recorded``, kept whole)."""
    head, _, rest = commit.partition(" ")
    if len(head) == 40 and all(c in "0123456789abcdef" for c in head):
        return " ".join(filter(None, (head[:7], rest)))
    return commit


def _counted(counts: Counter[str], total: int) -> str:
    """One value as is; several with their job counts, most jobs first (``a (69 of 90 jobs), b (11)``)."""
    if len(counts) == 1:
        return f"`{next(iter(counts))}`"
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    parts = [f"`{v}` ({n} of {total} jobs)" if i == 0 else f"`{v}` ({n})" for i, (v, n) in enumerate(ranked)]
    return ", ".join(parts[:-1]) + " and " + parts[-1]


def stamp_sentence(stamps: Sequence[JobStamp]) -> str:
    """The jobs' provenance in one sentence, for a headline: the environment, evcd's version, the
    machine and the commits (shortened), each field's values with their job counts where the jobs
    differ; a sentence that says so where no job recorded any of them (made by older code)."""
    if all(s == JobStamp() for s in stamps):
        return "Its jobs recorded no environment version, code or machine (made before results did)."
    total = len(stamps)
    commits = Counter(_short(s.commit) for s in stamps)
    return (
        f"Made with {_counted(Counter(s.environment for s in stamps), total)}, evcd "
        f"{_counted(Counter(s.evcd for s in stamps), total)}, on "
        f"{_counted(Counter(s.machine for s in stamps), total)}, by "
        f"{'commit' if len(commits) == 1 else 'commits'} {_counted(commits, total)}."
    )
