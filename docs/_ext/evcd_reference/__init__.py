"""A Sphinx extension that writes the reference pages' tables from the code and ``conf/`` at build time.

A page (``docs/reference/*.md``) holds its prose and, where a table belongs, a block

    ```{evcd-reference} experiments
    ```

that this extension replaces, as Sphinx reads the page, with the Markdown its generator writes
(:data:`GENERATORS`): the experiments composed by Hydra split by split
(:mod:`.experiments`), every config group and key with default, type and meaning
(:mod:`.configuration`), a dataclass's fields with their docstrings (:mod:`.metrics`).

Why at build time rather than a script that commits the pages with a test that they are current:
nothing generated is committed, so nothing can go stale, and no one has to remember a regeneration
step after editing a YAML comment; the site's build (``tests/docs/test_site.py``, warnings as
errors) already runs on every change. The price is a few seconds of Hydra composition per build. The
generated blocks are plain Markdown, so MyST renders them as it renders the hand-written parts
(headings in the navigation, links, anchors). An unknown block name stops the build.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: A block to replace: ```{evcd-reference} <generator> <arguments>``` with nothing inside.
BLOCK = re.compile(r"^```\{evcd-reference\}[ \t]*(?P<args>[^\n]*)\n```[ \t]*$", re.M)


def _conf_dir() -> Path:
    from evcd.experiments import CONF_DIR

    return CONF_DIR


def _experiments(*args: str) -> str:
    from . import experiments

    return experiments.markdown(_conf_dir())


def _config_groups(*args: str) -> str:
    from . import configuration

    return configuration.groups_markdown(_conf_dir())


def _config_keys(*args: str) -> str:
    from . import configuration

    return configuration.keys_markdown(_conf_dir())


def _config_evaluate(*args: str) -> str:
    from . import configuration

    return configuration.evaluate_markdown(_conf_dir())


def _fields(dotted: str, prefix: str = "", *args: str) -> str:
    from . import metrics

    return metrics.fields_markdown(dotted, prefix)


#: The generators a page may name, with their arguments.
GENERATORS: dict[str, Callable[..., str]] = {
    "experiments": _experiments,
    "config-groups": _config_groups,
    "config-keys": _config_keys,
    "config-evaluate": _config_evaluate,
    "fields": _fields,
}


def render(text: str) -> str:
    """``text`` with every ``evcd-reference`` block replaced by its generator's Markdown.

    Raises:
        ValueError: a block names no generator.
    """

    def one(match: re.Match[str]) -> str:
        name, *args = match["args"].split()
        if name not in GENERATORS:
            raise ValueError(f"{{evcd-reference}} {name}: unknown; the generators: {', '.join(GENERATORS)}")
        return GENERATORS[name](*args)

    return BLOCK.sub(one, text)


def _source_read(app: Any, docname: str, source: list[str]) -> None:
    if "{evcd-reference}" not in source[0]:
        return
    source[0] = render(source[0])
    conf = _conf_dir()
    for path in [*conf.rglob("*.yaml"), *Path(__file__).parent.glob("*.py")]:
        app.env.note_dependency(str(path))


def setup(app: Any) -> dict[str, Any]:
    """Register the replacement of the ``evcd-reference`` blocks."""
    app.connect("source-read", _source_read)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
