"""The perturbed worlds' numbers on the README, rendered from the perturbed page's goal table.

``docs/PERTURBED.md``'s section "The goal, in one table" holds each task's learner against the strongest
rule of its world (the rows ``scripts/reproduce.py perturbed --check`` holds to its runs); the README's
line on the perturbed worlds reads that table (:mod:`evcd.report.pages`).
"""

from __future__ import annotations

from pathlib import Path

from evcd.report.markdown import read_interval, section_lines, signed_interval, tables, verdict

PAGE = Path("docs") / "PERTURBED.md"
GOAL = "## The goal, in one table"


def goal(root: Path) -> str:
    """The README's line on the perturbed worlds: where the single target's plain learner stands against
    its strongest rule, and whether any learner of either task is ahead of its world's strongest rule."""
    found = tables(section_lines((Path(root) / PAGE).read_text(), GOAL))
    if not found:
        raise ValueError(f"{PAGE}: no table under {GOAL!r}")
    _, header, rows = found[0]
    column = header.index("learner - rule (s)")
    stats = [(cells[0], cells[1], cells[2], read_interval(cells[column])) for _, cells in rows]
    task, learner, rule, first = stats[0]
    ahead = [f"{t}: {le} ahead of {r}" for t, le, r, s in stats if verdict(s) == "ahead of"]
    beats = ("no learner beats every rule there, on either task" if not ahead else
             "ahead of its world's strongest rule: " + "; ".join(ahead))  # fmt: skip
    return (f"- Perturbed peak ({task}): the learner ({learner}) is {verdict(first)} {rule} "
            f"({signed_interval(first)} s); {beats} ([`docs/PERTURBED.md`](docs/PERTURBED.md)).")
