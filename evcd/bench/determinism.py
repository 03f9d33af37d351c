"""Same seed, same result: compare two finished runs of ``scripts/train.py`` (or ``evaluate.py``).

``scripts/bench.py --suite determinism`` trains the same short run twice, each in a fresh Python
process with its own heap layout (another working directory and hash seed; the first may build the
days, the second loads them), then compares the two run directories here: every episode row of
every episode file (the wall times aside) and a SHA-256 of the final agent state in the checkpoint
(networks, optimiser, replay buffer, generators), with the one of the policy the run evaluated (its
:meth:`~evcd.agents.Agent.policy_state_dict`, any learner's, recorded in ``results.json``) beside it.

    report = compare_runs(Path("outputs/a"), Path("outputs/b"))
    report["identical"], report["first_difference"]
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from evcd.utils.checkpoint import load_checkpoint, state_sha256

#: ``python -c`` code that runs ``script`` after an unrelated allocation pattern, so that the objects the
#: run allocates (SUMO's included) lie elsewhere in the heap than in a plain start.
ALLOCATE_FIRST = (
    "import runpy, sys\n"
    "junk = [bytearray(1000 + (i * 7919) % 50000) for i in range(4000)]\n"
    "del junk[::3]\n"
    "sys.argv = [{script!r}, *sys.argv[1:]]\n"
    "runpy.run_path({script!r}, run_name='__main__')\n"
)
#: Columns that measure the machine, not the run.
WALL_COLUMNS = ("wall_s",)
CHECKPOINTS = "checkpoints"


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of an episode file, without the wall-clock columns."""
    with open(path, newline="") as f:
        return [{k: v for k, v in row.items() if k not in WALL_COLUMNS} for row in csv.DictReader(f)]


def run_digest(run_dir: Path) -> dict[str, Any]:
    """A run's episode rows per file, its transition count, the digest of its final agent state
    (``None`` for a rule, which has no checkpoint), the one of the policy it evaluated (any
    learner's: ``results.json``'s ``training.policy_sha256``) and the machine it ran on (not
    compared: both runs of the suite run on one)."""
    run_dir = Path(run_dir)
    files = {p.name: read_rows(p) for p in sorted(run_dir.glob("*episodes.csv"))}
    agent = None
    if (run_dir / CHECKPOINTS).is_dir():
        agent = state_sha256(load_checkpoint(run_dir / CHECKPOINTS)["agent"])
    results = run_dir / "results.json"
    data = json.loads(results.read_text()) if results.is_file() else {}
    training = data.get("training", {})
    return {"files": files, "transitions": training.get("transitions"), "agent_sha256": agent,
            "policy_sha256": training.get("policy_sha256"), "machine": data.get("machine")}  # fmt: skip


def first_difference(a: Mapping[str, Any], b: Mapping[str, Any]) -> str | None:
    """Where two :func:`run_digest` results first differ (a sentence), or ``None`` if they do not."""
    if sorted(a["files"]) != sorted(b["files"]):
        return f"the runs wrote different episode files: {sorted(a['files'])} vs {sorted(b['files'])}"
    for name, rows_a in a["files"].items():
        rows_b = b["files"][name]
        for i, (x, y) in enumerate(zip(rows_a, rows_b, strict=False)):
            if x != y:
                cols = [k for k in x if x.get(k) != y.get(k)]
                return (f"{name}: row {i} (episode {x.get('episode')}) differs in {cols}: "
                        f"{[x.get(k) for k in cols]} vs {[y.get(k) for k in cols]}")  # fmt: skip
        if len(rows_a) != len(rows_b):
            return f"{name}: {len(rows_a)} rows vs {len(rows_b)}"
    for key in ("transitions", "policy_sha256", "agent_sha256"):
        if a[key] != b[key]:
            return f"{key}: {a[key]} vs {b[key]}"
    return None


def compare_runs(a: Path, b: Path) -> dict[str, Any]:
    """Compare two finished run directories: ``identical``, ``first_difference`` and what was compared."""
    da, db = run_digest(a), run_digest(b)
    diff = first_difference(da, db)
    return {
        "identical": diff is None,
        "first_difference": diff,
        "runs": [str(a), str(b)],
        "rows": {name: len(rows) for name, rows in da["files"].items()},
        "transitions": [da["transitions"], db["transitions"]],
        "policy_sha256": [da["policy_sha256"], db["policy_sha256"]],
        "agent_sha256": [da["agent_sha256"], db["agent_sha256"]],
        # a policy digest holds on the machine that made it: its CPU and kernels, its packages
        "machine": da["machine"],
    }
