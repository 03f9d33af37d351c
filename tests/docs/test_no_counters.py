"""No internal counters in what a user reads.

The project's work was once counted in "stops" and "issues" of its own tracker ("stop 42", "stops
48-53", "issue 31"); those numbers mean nothing to a reader. What a user reads names a date and a
commit instead (``2026-11-27, c6745f5``), or nothing. Only the research notes (``docs/NOTES.md``) and
the changelogs (``docs/changelog.md``, ``CHANGELOG.md``) are records, and they are not scanned.

Scanned: ``README.md``; every ``docs/**/*.md`` but those two; the comments and string literals
(docstrings, messages) of ``evcd/**/*.py``, ``scripts/*.py`` and ``examples/**/*.py``; the comments of
``conf/**/*.yaml``.

The rule, as :data:`COUNTER` and :func:`counters` apply it:

- ``stop N`` / ``stops N`` / ``stop-N`` and ``issue N`` / ``issues N`` / ``issue #N`` (either case of
  the first letter) are counters;
- not where the number is a quantity: a decimal (``stop 1.5``) or a number followed by a unit (``SUMO
  stops 300 s later``, ``stops 2 km short``, ``5 times``);
- not an issue of another project: ``issue N`` is left alone where the word before it names that
  project in a form this project's own counters never took (``owner/repo``, a name with ``-``, ``.``
  or ``_`` such as ``pytest-xdist``, or one with a capital past its first letter such as ``SUMO`` or
  ``GitHub``), or where the line carries the issue's address (``http://`` or ``https://``). A bare
  ``#N`` (``pytest-xdist #1386``) or ``owner/repo#N`` is never matched: that is how other projects'
  tracker numbers are cited, and this project's counters never were.
"""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

from tests.conftest import ROOT

#: A counter: "stop(s)" or "issue(s)", a space or hyphen, an optional "#", a whole number that is not a
#: decimal nor followed by a unit.
COUNTER = re.compile(
    r"\b(?P<word>[Ss]tops?|[Ii]ssues?)[ -]#?\d+\b(?![.,]\d)"
    r"(?!\s*(?:%|(?:s|ms|min|minutes?|h|hours?|seconds?|m|km|EVs?|vehicles?|times|episodes?)\b))"
)
#: The word before an "issue N" that names another project: owner/repo, a name with - . _, or a capital
#: past the first letter (SUMO, GitHub, PyTorch).
OTHER_PROJECT = re.compile(r"(?:\w{2,}[/._-]\w{2,}\S*|\S+[A-Z]\S*)$")
#: Records, not scanned.
RECORDS = {"docs/NOTES.md", "docs/changelog.md"}


def counters(text: str) -> list[str]:
    """The internal counters in one line of text (the rule of the module's docstring)."""
    found = []
    for m in COUNTER.finditer(text):
        if m.group("word").lower().startswith("issue"):
            before = text[: m.start()].rstrip()
            word = before.split()[-1] if before.split() else ""
            word = re.sub(r"'s$", "", word.lstrip("(["))
            if (word and OTHER_PROJECT.search(word)) or re.search(r"https?://", text):
                continue
        found.append(m.group(0))
    return found


def python_text(source: str):
    """(line, text) of every comment and string literal (docstrings and messages) of a Python source."""
    kinds = {tokenize.COMMENT, tokenize.STRING}
    if hasattr(tokenize, "FSTRING_MIDDLE"):  # Python 3.12+
        kinds.add(tokenize.FSTRING_MIDDLE)
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type in kinds:
            for k, line in enumerate(tok.string.split("\n")):
                yield tok.start[0] + k, line


def yaml_comments(source: str):
    """(line, text) of every comment of a YAML source (from a ``#`` at the start or after a blank)."""
    for k, line in enumerate(source.split("\n"), 1):
        m = re.search(r"(?:^|\s)#(.*)$", line)
        if m:
            yield k, m.group(1)


def markdown_text(source: str):
    yield from enumerate(source.split("\n"), 1)


def scanned_files(root: Path) -> list[tuple[Path, object]]:
    """The files a user reads, each with the reader of its user-visible text."""
    files = [(root / "README.md", markdown_text)]
    files += [(p, markdown_text) for p in sorted((root / "docs").rglob("*.md"))
              if p.relative_to(root).as_posix() not in RECORDS and "_build" not in p.parts]  # fmt: skip
    for pattern in ("evcd/**/*.py", "scripts/*.py", "examples/**/*.py"):
        files += [(p, python_text) for p in sorted(root.glob(pattern))]
    files += [(p, yaml_comments) for p in sorted(root.glob("conf/**/*.yaml"))]
    return [(p, reader) for p, reader in files if p.is_file()]


def hits_in(path: Path, reader, root: Path) -> list[str]:
    """``file:line: text`` for every line of path's user-visible text holding a counter."""
    out = []
    for line, text in reader(path.read_text(encoding="utf-8")):
        if counters(text):
            out.append(f"{path.relative_to(root).as_posix()}:{line}: {text.strip()}")
    return out


def test_no_internal_counters_in_what_a_user_reads():
    files = scanned_files(ROOT)
    assert len(files) > 50  # the globs found the project
    hits = [h for path, reader in files for h in hits_in(path, reader, ROOT)]
    assert not hits, "internal counters (name a date and commit instead):\n" + "\n".join(hits)


@pytest.mark.parametrize("text", [
    "the rules re-run in stop 40", "Stop 41's learners", "stops 48-53", "the stop-47 evaluate.py lines",
    "(issue 28, measured)", "the first perturbation of issue #31", "Issues 30 and 31", "as stop 44 said",
    "e.g. issue 12",
])  # fmt: skip
def test_a_counter_is_found(text):
    assert counters(text)


@pytest.mark.parametrize("text", [
    "pytest-xdist #1386", "a GitHub issue", "eclipse-sumo/sumo#12345", "SUMO stops 300 s later",
    "the EV's next stop is off its route", "a stop 1.5 km away", "pytest-xdist issue 1386",
    "SUMO issue 1234 says so", "see [the issue 1234](https://github.com/eclipse-sumo/sumo/issues/1234)",
    "the bound stops them", "stops 5% short", "commit c467250 is the last that has them",
])  # fmt: skip
def test_legitimate_text_is_not_a_counter(text):
    assert counters(text) == []


def test_each_kind_of_file_is_read_where_a_user_reads_it(tmp_path):
    """A counter planted in a Markdown line, a Python comment and docstring and a YAML comment is found;
    the same words in Python code or a YAML value are not user-visible text and are not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("# Results\n\nMeasured in stop 42.\n")
    (tmp_path / "docs" / "NOTES.md").write_text("stop 42: a record, not scanned\n")
    (tmp_path / "README.md").write_text("fine\n")
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "run.py").write_text(
        '"""Run it (issue 31)."""\n\nstop_42 = 1  # the fix of stop 42\nissue = 31\n'
    )
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "a.yaml").write_text("name: stop 3  # chosen in stop 45\nother: 1\n")
    hits = [h for path, reader in scanned_files(tmp_path) for h in hits_in(path, reader, tmp_path)]
    assert sorted(hits) == sorted(
        [
            "docs/page.md:3: Measured in stop 42.",
            'scripts/run.py:1: """Run it (issue 31)."""',
            "scripts/run.py:3: # the fix of stop 42",
            "conf/a.yaml:1: chosen in stop 45",
        ]
    )
