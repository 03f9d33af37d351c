"""Where the reference pages read their words: the comments of ``conf/``'s YAML files, the
``Attributes:`` sections of the code's docstrings, and a few Markdown helpers.

The YAML reader knows the layout evcd's configs are written in (and that a test keeps): a key's
explanation is the block of ``#`` lines right above it (a blank line ends a block), nested keys are
indented under their parent, a ``defaults:`` entry's comment explains its config group, and a file's
first comment lines (before any key) describe the file.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

_KEY = re.compile(r"^(?P<indent>\s*)(?P<key>[A-Za-z_][\w]*):(?P<rest>.*)$")
_DEFAULT = re.compile(r"^\s*-\s+(?:override\s+)?/?(?P<group>[\w/]+)\s*:\s*(?P<option>[\w.]+)")
_PACKAGE = re.compile(r"^#\s*@package\s+(?P<package>\S+)")


@dataclass
class YamlFile:
    """What one YAML file of ``conf/`` says about itself (see the module docstring).

    Attributes:
        path: the file.
        package: ``_global_`` for a file whose keys are at the root (``# @package _global_``), else
            ``None`` (its keys go under its group).
        header: the file's first comment lines (without the ``@package`` line), joined.
        header_lines: the same lines as written.
        keys: the explanation of every key that has one, by its dotted path inside the file.
        groups: the explanation of every ``defaults:`` entry that has one, by config group.
        defaults: the ``defaults:`` entries, as (group, option), in order.
    """

    path: Path
    package: str | None = None
    header: str = ""
    header_lines: list[str] = field(default_factory=list)
    keys: dict[str, str] = field(default_factory=dict)
    groups: dict[str, str] = field(default_factory=dict)
    defaults: list[tuple[str, str]] = field(default_factory=list)


def _inline_comment(rest: str) -> str:
    """The comment after a value on the key's own line (``key: 3  # why``), if any."""
    if " #" not in rest or rest.strip().startswith(("'", '"')):
        return ""
    return rest.split(" #", 1)[1].strip()


def read_yaml(path: Path) -> YamlFile:
    """The comments of the YAML file ``path`` (see :class:`YamlFile`)."""
    out = YamlFile(Path(path))
    pending: list[str] = []
    stack: list[tuple[int, str]] = []
    seen_key = False
    in_defaults = False
    for line in Path(path).read_text().splitlines():
        stripped = line.strip()
        if not stripped:
            if not seen_key and pending and not out.header:
                out.header = " ".join(pending)
            pending = []
            continue
        if stripped.startswith("#"):
            package = _PACKAGE.match(stripped)
            if package:
                out.package = package["package"]
                continue
            pending.append(stripped.lstrip("#").strip())
            if not seen_key and not out.header:
                out.header_lines.append(line.lstrip()[1:].rstrip().removeprefix(" "))
            continue
        default = _DEFAULT.match(line)
        if in_defaults and default:
            out.defaults.append((default["group"], default["option"]))
            if pending:
                out.groups[default["group"]] = " ".join(pending)
            pending = []
            continue
        key = _KEY.match(line)
        if key is None or stripped.startswith("-"):
            if not seen_key and pending and not out.header:  # a file that is one value (``{}``)
                out.header = " ".join(pending)
            pending = []  # a list item or a value's continuation line
            continue
        if not seen_key and not out.header and pending and not key["indent"]:
            out.header = " ".join(pending)
            if key["rest"].split("#")[0].strip():  # the file's description, not a scalar's
                pending = []
        seen_key = True
        indent = len(key["indent"])
        while stack and stack[-1][0] >= indent:
            stack.pop()
        stack.append((indent, key["key"]))
        dotted = ".".join(k for _, k in stack)
        in_defaults = dotted == "defaults"
        text = " ".join(pending) or _inline_comment(key["rest"])
        if text and dotted != "defaults":
            out.keys[dotted] = text
        pending = []
    if not seen_key and pending and not out.header:
        out.header = " ".join(pending)
    return out


def attributes(obj: Any) -> dict[str, str]:
    """The ``Attributes:`` (or ``Args:``) section of ``obj``'s Google-style docstring, by name.

    An entry naming several attributes (``a, b, c: text``) gives each the same text.
    """
    doc = inspect.cleandoc(inspect.getdoc(obj) or "")
    out: dict[str, str] = {}
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        if line.strip() in ("Attributes:", "Args:"):
            body = lines[i + 1 :]
            break
    else:
        return out
    indent: int | None = None
    names: list[str] = []
    for line in body:
        if not line.strip():
            continue
        depth = len(line) - len(line.lstrip())
        if indent is None:
            indent = depth
        if depth < indent:
            break
        entry = re.match(r"^([\w, ]+?)(?: \([^)]*\))?:\s+(.*)$", line.strip()) if depth == indent else None
        if entry:
            names = [n.strip() for n in entry[1].split(",")]
            for name in names:
                out[name] = entry[2].strip()
        elif names:
            for name in names:
                out[name] += " " + line.strip()
    return out


def first_sentence(text: str) -> str:
    """The first sentence of ``text`` (up to the first ``. `` or ``: `` that ends a clause)."""
    text = " ".join(text.split())
    match = re.search(r"(?<=[A-Za-z0-9)`])\.(\s|$)", text)
    return text[: match.start() + 1] if match else text


def plain_roles(text: str) -> str:
    """A docstring's Sphinx roles as inline code (``:class:`~a.B``` -> ```B```), which Markdown renders
    as it is."""

    def one(match: re.Match[str]) -> str:
        target = match[1]
        return f"`{target[1:].rsplit('.', 1)[-1]}`" if target.startswith("~") else f"`{target}`"

    return re.sub(r":\w+:`([^`]+)`", one, text)


def cell(text: Any) -> str:
    """``text`` made safe for a Markdown table cell (no ``|``, no line break)."""
    return " ".join(str(text).split()).replace("|", "\\|")


def code(value: Any) -> str:
    """``value`` as inline code, written as YAML writes it (``null``, ``true``, lists in brackets)."""
    return f"`{yaml_text(value)}`"


def yaml_text(value: Any) -> str:
    """``value`` as one line of YAML flow style."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {yaml_text(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(yaml_text(v) for v in value) + "]"
    return str(value)


def table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A Markdown pipe table (cells made safe by :func:`cell`)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)
