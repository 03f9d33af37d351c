"""Regions of the documentation pages that are rendered from committed data, never typed.

    python scripts/render_pages.py            # rewrite every generated region from the data
    python scripts/render_pages.py --check    # list, cell by cell, where a page differs (exit 1)

A page marks a generated region with two HTML comments (invisible on the rendered page)::

    <!-- generated: results-headline -->
    | EVs | random | ...
    <!-- end generated -->

and :data:`GENERATORS` maps the name to a function of the repository root that returns the region's
Markdown from the data files committed beside the page (``docs/results.csv`` for the results table's
headline and paired line, and the results page's tables of the README regime for the first command's
line, :mod:`evcd.report.results_regions`; ``docs/fleet_table/fleet_results.csv`` for the fleet table's,
:mod:`evcd.report.fleet_regions`; the perturbed page's goal table for the README's perturbed line,
:mod:`evcd.report.perturbed_regions`). :func:`render_page` replaces
every region of a page; :func:`differences` compares a page with its rendering line by line and,
inside tables, cell by cell.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection
from pathlib import Path

from evcd.report import fleet_regions, perturbed_regions, results_regions, room_regions

BEGIN = re.compile(r"^<!-- generated: ([a-z0-9-]+) -->$")
END = "<!-- end generated -->"
#: The pages that hold generated regions, relative to the repository root.
PAGES = ("README.md", "docs/FLEET.md")


class PageError(ValueError):
    """A page's generated regions are malformed (unclosed, nested, unknown name)."""


#: Region name -> its renderer (of the repository root).
GENERATORS: dict[str, Callable[[Path], str]] = {"results-headline": results_regions.headline,
                                                "results-paired": results_regions.paired,
                                                "readme-regime": results_regions.regime,
                                                "fleet-headline": fleet_regions.headline,
                                                "fleet-share-one": fleet_regions.share_one,
                                                "fleet-per-share": fleet_regions.per_share,
                                                "fleet-against-rules": fleet_regions.against_rules,
                                                "fleet-share-verdicts": fleet_regions.share_verdicts,
                                                "fleet-per-day": fleet_regions.per_day,
                                                "fleet-cost": fleet_regions.cost,
                                                "fleet-room": room_regions.room,
                                                "fleet-room-shares": room_regions.room_shares,
                                                "fleet-room-worlds": room_regions.room_worlds,
                                                "perturbed-goal": perturbed_regions.goal}  # fmt: skip


def regions(text: str) -> list[tuple[str, int, int]]:
    """``(name, first line, end line)`` of each generated region of ``text`` (0-based line numbers of
    the content between the markers: ``lines[first:end]``).

    Raises:
        PageError: an unclosed, nested or unnamed region, or a name without a generator.
    """
    out, lines, open_at = [], text.splitlines(), None
    name = ""
    for i, line in enumerate(lines):
        m = BEGIN.match(line.strip())
        if m:
            if open_at is not None:
                raise PageError(f"line {i + 1}: region {m.group(1)!r} opens inside region {name!r}")
            name, open_at = m.group(1), i + 1
            if name not in GENERATORS:
                raise PageError(f"line {i + 1}: no generator named {name!r}; the generators: "
                                f"{', '.join(GENERATORS)}")  # fmt: skip
        elif line.strip() == END:
            if open_at is None:
                raise PageError(f"line {i + 1}: {END} without a region to close")
            out.append((name, open_at, i))
            open_at = None
    if open_at is not None:
        raise PageError(f"line {open_at}: region {name!r} is never closed ({END})")
    return out


def render_page(text: str, root: Path, keep: Collection[str] = ()) -> str:
    """``text`` with every generated region's content rendered from the data under ``root``, but the
    regions named in ``keep``, left as they are."""
    lines = text.splitlines()
    for name, first, end in reversed(regions(text)):
        if name not in keep:
            lines[first:end] = GENERATORS[name](root).splitlines()
    return "\n".join(lines) + ("\n" if text.endswith("\n") else "")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def differences(text: str, rendered: str, page: str = "page") -> list[str]:
    """Where ``text`` differs from ``rendered``: one line per differing line, or per cell where both
    are table rows of the same width (``page:line: column 'x': 'old' -> 'new'``)."""
    old, new = text.splitlines(), rendered.splitlines()
    out = []
    header: list[str] = []
    for i in range(max(len(old), len(new))):
        a = old[i] if i < len(old) else "<missing>"
        b = new[i] if i < len(new) else "<missing>"
        if b.startswith("| ") and not b.startswith("|---"):
            header = header if i > 0 and new[i - 1].startswith("|") else _cells(b)
        if a == b:
            continue
        if a.startswith("|") and b.startswith("|") and len(_cells(a)) == len(_cells(b)):
            for j, (x, y) in enumerate(zip(_cells(a), _cells(b), strict=True)):
                if x != y:
                    column = header[j] if j < len(header) else str(j + 1)
                    out.append(f"{page}:{i + 1}: column {column!r} of row {_cells(b)[0]!r}: {x!r} -> {y!r}")
        else:
            out.append(f"{page}:{i + 1}: {a!r} -> {b!r}")
    return out
