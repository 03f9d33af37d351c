"""Where a page's rendering differs from the data the page commits, cell by cell.

    found, notes = compare_page(page, Path("out/rendered"), root=Path("."))
    for line in found: print(line)    # docs/results.csv: row regime=table agent=dqn evs=400 seed=3: ...

Three comparisons (a page's ``compare`` entries, :class:`evcd.report.reproduce.spec.Compare`):

- ``csv``: a rendered CSV against a committed one, rows matched by the job key, every column both
  have but the ignored ones (where, when and by what a job ran) compared; numbers as numbers
  (``1.0`` is ``1``, ``nan`` is ``nan``); a row on one side only is a difference.
- ``markdown``: each table of a rendered Markdown file against the table with the same header in the
  committed page (in ``section``, if given; the k-th such table for the k-th), rows matched by their
  first cells, then cell by cell as :func:`evcd.report.pages.differences` says it (bold ignored). A
  rendered row the page lacks is a difference; the page's rows made by other runs are only counted. A
  rendered table the page lacks is noted; none of them on the page is a difference (the page shows
  tables of another shape than its jobs make).
- ``regions``: a page's generated regions (``<!-- generated: ... -->``) rendered from the new data in
  place of the committed files (:func:`evcd.report.pages.render_page`), against the page; but the
  ignored ones (what the jobs cost on the machine that ran them).
"""

from __future__ import annotations

import csv
import math
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

from evcd.report.markdown import section_lines, tables
from evcd.report.pages import differences, regions, render_page
from evcd.report.reproduce.spec import Compare, Page


# ---------------------------------------------------------------------------------------- CSV
def _same(a: str, b: str) -> bool:
    if a == b:
        return True
    try:
        x, y = float(a), float(b)
    except ValueError:
        return False
    return x == y or (math.isnan(x) and math.isnan(y))


def _key_value(value: str) -> str:
    try:
        return repr(float(value))
    except ValueError:
        return value


def _read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def csv_differences(
    rendered: Path, committed: Path, key: Sequence[str], ignore: Sequence[str], name: str
) -> tuple[list[str], list[str]]:
    """(differences, notes) between two CSVs of job rows, matched by ``key`` (``name``: the committed
    file as the messages call it)."""
    new_cols, new_rows = _read_csv(rendered)
    old_cols, old_rows = _read_csv(committed)
    lacking = [k for k in key if k not in new_cols or k not in old_cols]
    if lacking:
        return [f"{name}: no key column {', '.join(lacking)} on both sides (rendered: {rendered})"], []
    columns = [c for c in new_cols if c in old_cols and c not in ignore and c not in key]
    notes = [
        f"{name}: column {c!r} only in the rendering: not compared" for c in new_cols if c not in old_cols
    ]
    notes += [
        f"{name}: column {c!r} only in the committed file: not compared"
        for c in old_cols
        if c not in new_cols
    ]

    def index(rows: list[dict[str, str]]) -> dict[tuple[str, ...], dict[str, str]]:
        return {tuple(_key_value(r[k]) for k in key): r for r in rows}

    new, old = index(new_rows), index(old_rows)
    found = []
    for k in sorted(set(new) | set(old), key=lambda k: [(len(x), x) for x in k]):
        label = " ".join(f"{c}={(new.get(k) or old[k])[c]}" for c in key)
        if k not in old:
            found.append(f"{name}: row {label}: rendered, not in the committed file")
        elif k not in new:
            found.append(f"{name}: row {label}: in the committed file, not rendered")
        else:
            found += [f"{name}: row {label}: column {c!r}: {old[k][c]!r} -> {new[k][c]!r}"
                      for c in columns if not _same(old[k][c], new[k][c])]  # fmt: skip
    return found, notes


# ---------------------------------------------------------------------------------------- Markdown
def _key_width(rows: Sequence[list[str]]) -> int:
    width = min((len(r) for r in rows), default=1)
    for n in range(1, width):
        if len({tuple(r[:n]) for r in rows}) == len(rows):
            return n
    return max(width - 1, 1)


def _row_text(header: Sequence[str], cells: Sequence[str]) -> str:
    return "\n".join(["| " + " | ".join(header) + " |", "|---|", "| " + " | ".join(cells) + " |"])


def markdown_differences(
    rendered: str, committed: str, name: str, section: str | None = None, ignore: Sequence[str] = ()
) -> tuple[list[str], list[str]]:
    """(differences, notes): each table of ``rendered`` against the committed page's table of the same
    header (see the module's docstring); messages ``name:line: column 'x' of row 'y': 'old' -> 'new'``."""
    try:
        page_tables = tables(section_lines(committed, section))
    except ValueError as exc:
        return [f"{name}: {exc}"], []
    found: list[str] = []
    notes: list[str] = []
    seen: dict[tuple[str, ...], int] = {}
    where = f" under {section!r}" if section else ""
    made = tables(section_lines(rendered, None))
    compared = 0
    for _, header, rows in made:
        k = seen[tuple(header)] = seen.get(tuple(header), -1) + 1
        same = [t for t in page_tables if t[1] == header]
        title = " | ".join(header)[:60]
        if len(same) <= k:
            notes.append(f"{name}: no table '{title}' on the page{where}")
            continue
        line0, _, old_rows = same[k]
        compared += 1
        width = _key_width([cells for _, cells in rows])
        old = {tuple(cells[:width]): (n, cells) for n, cells in reversed(old_rows)}
        for _, cells in rows:
            if tuple(cells[:width]) not in old:
                found.append(
                    f"{name}:{line0}: row {' | '.join(cells[:width])!r} of table '{title}': not on the page"
                )
                continue
            n, before = old.pop(tuple(cells[:width]))
            kept = [new if h in ignore else c for h, c, new in zip(header, before, cells, strict=False)]
            before = kept + before[len(kept) :]
            label = " | ".join(cells[:width])
            for diff in differences(_row_text(header, before), _row_text(header, cells), name):
                diff = diff.replace(f"{name}:3:", f"{name}:{n}:", 1)  # the row's line in the page
                found.append(diff.replace(f" of row {cells[0]!r}:", f" of row {label!r}:", 1))
        if old:
            notes.append(f"{name}:{line0}: {len(old)} row(s) of table '{title}' not made by this page's jobs")
    if made and not compared:
        shown = ", ".join(f"'{' | '.join(h)[:60]}'" for _, h, _ in page_tables) or "none"
        found.append(f"{name}: none of the {len(made)} rendered table(s) is on the page{where} "
                     f"(its tables: {shown})")  # fmt: skip
    return found, notes


# ---------------------------------------------------------------------------------------- regions
def _mirror(src: Path, dst: Path, replace: Mapping[tuple[str, ...], Path]) -> None:
    """``dst`` as ``src`` through links, but for the files of ``replace`` (path parts -> new file)."""
    dst.mkdir(parents=True, exist_ok=True)
    heads = {parts[0] for parts in replace}
    if src.is_dir():
        for entry in src.iterdir():
            if entry.name not in heads:
                (dst / entry.name).symlink_to(entry)
    for head in heads:
        below = {parts[1:]: new for parts, new in replace.items() if parts[0] == head}
        if () in below:
            shutil.copyfile(below[()], dst / head)
        else:
            _mirror(src / head, dst / head, below)


def region_differences(
    page: str, root: Path, data: Mapping[str, Path], ignore: Sequence[str] = ()
) -> list[str]:
    """Where the page ``page`` (relative to ``root``) differs from its generated regions rendered with
    the committed files of ``data`` replaced by the new ones; the regions named in ``ignore`` are not
    rendered (one the page lacks is a difference)."""
    text = (Path(root) / page).read_text()
    names = [name for name, _, _ in regions(text)]
    lacking = [f"{page}: no generated region {name!r} to ignore (its regions: {', '.join(names)})"
               for name in ignore if name not in names]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        _mirror(Path(root), Path(tmp), {Path(rel).parts: Path(new) for rel, new in data.items()})
        rendered = render_page(text, Path(tmp), keep=ignore)
    return lacking + differences(text, rendered, page)


# ---------------------------------------------------------------------------------------- a page
def compare_one(entry: Compare, folder: Path, root: Path) -> tuple[list[str], list[str]]:
    """(differences, notes) of one compare entry; a missing file is a difference."""
    committed = Path(root) / entry.committed
    if not committed.is_file():
        return [f"{entry.committed}: no such committed file (under {root})"], []
    if entry.kind == "regions":
        data = {k: folder / v for k, v in entry.data.items()}
        return region_differences(entry.committed, root, data, entry.ignore_regions), []
    rendered = folder / entry.file
    if not rendered.is_file():
        return [f"{rendered}: not rendered"], []
    if entry.kind == "csv":
        return csv_differences(rendered, committed, entry.key, entry.ignore_columns, entry.committed)
    return markdown_differences(rendered.read_text(), committed.read_text(), entry.committed, entry.section,
                                entry.ignore_columns)  # fmt: skip


def compare_page(page: Page, rendered: Path, root: Path) -> tuple[list[str], list[str]]:
    """(differences, notes) of every compare entry of every render of ``page`` (rendered into
    ``rendered/<render>``) against the committed files under ``root``."""
    found: list[str] = []
    notes: list[str] = []
    for render in page.renders:
        for entry in render.compare:
            more, more_notes = compare_one(entry, Path(rendered) / render.name, root)
            found += more
            notes += more_notes
    return found, notes
