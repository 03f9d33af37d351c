"""Markdown pieces of the results tables: numbers, intervals across seeds, tables; and the tables of a
committed page read back (a section's tables, their cells)."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence

from evcd.report.seed_stats import SeedStat

Table = tuple[int, list[str], list[tuple[int, list[str]]]]  # (header line, header cells, rows with lines)


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


def read_interval(cell: str) -> SeedStat:
    """A table cell ``+2.7 [-6.0, +11.4]`` (bold, and a tail such as ``n=5``, allowed) read back as a
    :class:`SeedStat` (mean, low, high; the seed count 0: a cell does not always say it).

    Raises:
        ValueError: the cell does not start with a mean and its interval.
    """
    m = re.match(r"([-+]?[\d.]+) \[([-+]?[\d.]+), ([-+]?[\d.]+)\]", cell.replace("**", "").strip())
    if m is None:
        raise ValueError(f"not a mean with its interval: {cell!r}")
    return SeedStat(*map(float, m.groups()), 0)


def _cells(line: str) -> list[str]:
    """A table row's cells, stripped, bold marks dropped."""
    return [c.replace("**", "").strip() for c in line.strip().strip("|").split("|")]


def section_lines(text: str, heading: str | None) -> list[tuple[int, str]]:
    """(line number from 1, line) of ``text``, or of its section under the line ``heading`` (to the next
    heading of the same or a higher level; lines in fenced code blocks are never headings).

    Raises:
        ValueError: no line is ``heading``.
    """
    lines = list(enumerate(text.splitlines(), 1))
    if heading is None:
        return lines
    fenced, start, level = False, None, 0
    for i, (_, line) in enumerate(lines):
        if line.startswith("```"):
            fenced = not fenced
            continue
        hashes = len(line) - len(line.lstrip("#"))
        if fenced or not hashes or not line[hashes:].startswith(" "):
            continue
        if start is None and line.strip() == heading.strip():
            start, level = i + 1, hashes
        elif start is not None and hashes <= level:
            return lines[start:i]
    if start is None:
        raise ValueError(f"no heading {heading!r}")
    return lines[start:]


def tables(lines: Sequence[tuple[int, str]]) -> list[Table]:
    """The Markdown tables of numbered lines: (header line, header cells, [(line, cells)])."""
    out: list[Table] = []
    i = 0
    while i + 1 < len(lines):
        (n, line), (_, rule) = lines[i], lines[i + 1]
        if line.startswith("|") and rule.startswith("|---"):
            rows = []
            j = i + 2
            while j < len(lines) and lines[j][1].startswith("|"):
                rows.append((lines[j][0], _cells(lines[j][1])))
                j += 1
            out.append((n, _cells(line), rows))
            i = j
        else:
            i += 1
    return out
