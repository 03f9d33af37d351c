"""Markdown pieces of the results tables: numbers, intervals across seeds, tables."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from evcd.report.seed_stats import SeedStat


def num(x: float, digits: int = 1) -> str:
    """``x`` with ``digits`` decimals, ``—`` if it is not finite."""
    return f"{x:.{digits}f}" if math.isfinite(x) else "—"


def signed(x: float, digits: int = 1) -> str:
    """``x`` with its sign and ``digits`` decimals (a difference), ``—`` if it is not finite."""
    return f"{x:+.{digits}f}" if math.isfinite(x) else "—"


def format_stat(stat: SeedStat, digits: int = 1, sign: bool = False) -> str:
    """``mean [low, high] n=k`` (no interval for one seed, ``—`` for none); ``sign``: each number with
    its sign (a difference)."""
    if stat.n == 0:
        return "—"
    show = signed if sign else num
    if stat.n == 1:
        return f"{show(stat.mean, digits)} n=1"
    return f"{show(stat.mean, digits)} [{show(stat.low, digits)}, {show(stat.high, digits)}] n={stat.n}"


def interval(stat: SeedStat) -> str:
    """A mean over seeds with its interval: ``303.9 [243.8, 364.0]``."""
    return f"{stat.mean:.1f} [{stat.low:.1f}, {stat.high:.1f}]"


def signed_interval(stat: SeedStat) -> str:
    """A difference over seeds: ``+1.2 [-0.3, +2.7]``."""
    return f"{signed(stat.mean)} [{signed(stat.low)}, {signed(stat.high)}]"


def marked_interval(stat: SeedStat) -> str:
    """:func:`signed_interval`, in bold where the interval leaves out 0."""
    text = signed_interval(stat)
    return f"**{text}**" if stat.low > 0 or stat.high < 0 else text


def verdict(stat: SeedStat) -> str:
    """Where ``a`` stands against ``b`` from the interval of ``a - b`` (a travel time: lower is better):
    ``behind`` (the interval above 0), ``ahead of`` (below) or ``level with`` (it holds 0)."""
    return "behind" if stat.low > 0 else "ahead of" if stat.high < 0 else "level with"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A Markdown table: the first column left-aligned, the others right-aligned."""
    rule = "|---|" + "---:|" * (len(header) - 1)
    return ["| " + " | ".join(header) + " |", rule, *("| " + " | ".join(r) + " |" for r in rows)]
