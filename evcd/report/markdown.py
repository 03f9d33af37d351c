"""Markdown pieces of the results tables: numbers, intervals across seeds, tables."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from evcd.report.seed_stats import SeedStat


def num(x: float, digits: int = 1) -> str:
    """``x`` with ``digits`` decimals, ``—`` if it is not finite."""
    return f"{x:.{digits}f}" if math.isfinite(x) else "—"


def format_stat(stat: SeedStat, digits: int = 1) -> str:
    """``mean [low, high] n=k`` (no interval for one seed, ``—`` for none)."""
    if stat.n == 0:
        return "—"
    if stat.n == 1:
        return f"{num(stat.mean, digits)} n=1"
    return f"{num(stat.mean, digits)} [{num(stat.low, digits)}, {num(stat.high, digits)}] n={stat.n}"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A Markdown table: the first column left-aligned, the others right-aligned."""
    rule = "|---|" + "---:|" * (len(header) - 1)
    return ["| " + " | ".join(header) + " |", rule, *("| " + " | ".join(r) + " |" for r in rows)]
