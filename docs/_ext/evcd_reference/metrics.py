"""The logged-metrics page: the tables that the code's own dataclasses document, and the names a page
explains (what the tests compare with the tags and fields a real run writes).

The TensorBoard tags and the ``results.json`` blocks that no dataclass documents are explained by
hand on the page (``docs/reference/metrics.md``), CleanRL-style; the summaries and the per-episode
rows are dataclasses whose ``Attributes:`` say what each field is, so their tables come from there.
"""

from __future__ import annotations

import dataclasses
import importlib
import re

from .sources import attributes, plain_roles, table

#: A documented name in a table's first cell: backticked, with ``<placeholders>`` for names a run
#: chooses (a rule's, a package's).
_NAME = re.compile(r"`([^`\s]+)`")


def find(dotted: str) -> type:
    """The class ``package.module.Class``."""
    module, _, name = dotted.rpartition(".")
    return getattr(importlib.import_module(module), name)


def fields_markdown(dotted: str, prefix: str = "") -> str:
    """A table of the dataclass ``dotted``'s fields: name (after ``prefix``), type and meaning (its
    docstring's ``Attributes:``). A field its docstring leaves out is listed with no meaning, and
    :func:`undocumented_fields` reports it."""
    cls = find(dotted)
    docs = attributes(cls)
    rows = [[f"`{prefix}{f.name}`", f"`{f.type}`", plain_roles(docs.get(f.name, ""))]
            for f in dataclasses.fields(cls)]  # fmt: skip
    return table(["field", "type", "meaning"], rows) + f"\n\nFrom the docstring of `{dotted}`."


def undocumented_fields(dotted: str) -> list[str]:
    """The fields of the dataclass ``dotted`` its docstring does not explain."""
    cls = find(dotted)
    docs = attributes(cls)
    return [f.name for f in dataclasses.fields(cls) if not docs.get(f.name)]


def documented_names(markdown: str) -> set[str]:
    """Every name a page explains: the backticked names in the first cell of its tables' rows (a cell
    may name several, ``a``, ``b``)."""
    names = set()
    for line in markdown.splitlines():
        if not line.startswith("|") or set(line) <= set("|-: "):
            continue
        first = line.split("|")[1]
        names |= set(_NAME.findall(first))
    return names


def pattern(name: str) -> re.Pattern[str]:
    """A documented name as a pattern: a ``<placeholder>`` stands for any name without a dot."""
    parts = re.split(r"(<[^>]+>)", name)
    return re.compile("".join("[^./]+" if p.startswith("<") else re.escape(p) for p in parts) + "$")


def explained(name: str, documented: set[str]) -> bool:
    """Whether ``name`` (a tag, a field's dotted path) is one of ``documented`` or matches one."""
    return name in documented or any(pattern(d).match(name) for d in documented if "<" in d)
