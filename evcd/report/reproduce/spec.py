"""A published page's jobs as data: ``docs/reproduce/<page>.yaml`` read into a :class:`Page`.

    page = load_page("results", Path("docs/reproduce"))
    for job in page.jobs(): ...              # PageJob: its sweep and its overrides
    page.sweeps[0].argv(Path("out/sweeps/table"))   # the multirun's arguments after the script

A page file names its **sweeps** (each a Hydra multirun of ``scripts/train.py``, ``evaluate.py`` or
``train_sb3.py``: its overrides, as the page documents the command, and the task and regime its jobs
record), its **renders** (what is made from which sweeps: ``table`` is ``scripts/make_table.py``,
``fleet_table`` its ``--fleet``, ``seed_rows`` a dispatcher's mean per seed, ``paired_rows`` paired
differences between two rows of worlds and dispatchers, ``compare`` ``scripts/compare_runs.py``'s table
of every world and dispatcher) and, per render, the **committed data** it is
compared with (``csv``: a committed CSV by job key and column; ``markdown``: the tables of a committed
page by header, row and column; ``regions``: a page's generated regions rendered from the new data,
but those named in ``ignore_regions``, measured costs that differ from run to run).
Unknown keys, kinds and scripts are refused with the allowed ones named (:class:`PageError`).
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from evcd.report.fleet_table import FleetJob
from evcd.report.sweep import JobResult, ResultsError, canonical_overrides, expand_sweep, job_defining

#: The scripts a sweep may run (each composes the config of its stem: ``train.py`` -> ``conf/train.yaml``).
SCRIPTS = ("train.py", "evaluate.py", "train_sb3.py")
TASKS = ("single", "fleet")
#: What a render makes: ``table`` (make_table), ``fleet_table`` (make_table --fleet), ``seed_rows``,
#: ``paired_rows``, ``compare`` (compare_runs; :mod:`evcd.report.reproduce.render`).
RENDER_KINDS = ("table", "fleet_table", "seed_rows", "paired_rows", "compare")
#: How a rendering is compared with committed data (:mod:`evcd.report.reproduce.check`).
COMPARE_KINDS = ("csv", "markdown", "regions")
#: Each table kind's job key: the columns a CSV row is matched by.
CSV_KEYS: dict[str, tuple[str, ...]] = {"table": JobResult.KEY_NAMES, "fleet_table": FleetJob.KEY_NAMES}
#: Columns that are not results (where and when a job ran, what made it): not compared unless a
#: compare entry names its own ``ignore_columns``.
NOT_RESULTS = ("job_dir", "train_wall_s", "day_build_s", "environment", "evcd", "commit", "machine")


class PageError(ValueError):
    """A page, its definition or the command line cannot be used (the script exits with code 2)."""


@dataclass(frozen=True)
class Sweep:
    """One Hydra multirun of a page: ``python scripts/<script> -m <overrides>``.

    Attributes:
        name: the sweep's name in the page (its folder under the output's ``sweeps/``).
        script: one of :data:`SCRIPTS`.
        task: the task its jobs record in ``results.json`` (``single`` or ``fleet``).
        regime: the regime their config records (the experiment's: ``table``, ``peak``, ``fleet``, ...).
        overrides: the multirun's overrides (sweeps as ``key=a,b``), as the page documents them.
    """

    name: str
    script: str
    task: str
    regime: str
    overrides: tuple[str, ...]

    def jobs(self, extra: Sequence[str] = ()) -> list[tuple[str, ...]]:
        """Each job's overrides (the sweep's, then ``extra``, which every job takes).

        Raises:
            PageError: an override does not parse or cannot be enumerated.
        """
        try:
            return expand_sweep([*self.overrides, *extra])
        except ResultsError as exc:
            raise PageError(f"sweep {self.name!r}: {exc}") from exc

    def argv(self, sweep_dir: Path, extra: Sequence[str] = (), hydra: Sequence[str] = ()) -> list[str]:
        """The arguments after the script: the multirun into ``sweep_dir``."""
        return ["-m", *self.overrides, *extra, *hydra, f"hydra.sweep.dir={sweep_dir}"]


@dataclass(frozen=True)
class Compare:
    """One comparison of a rendering with committed data (paths of ``committed`` and ``page``: relative
    to the repository root; ``file``: relative to the render's folder).

    Attributes:
        kind: ``csv``, ``markdown`` or ``regions`` (:data:`COMPARE_KINDS`).
        file: the rendered file compared (``csv``, ``markdown``).
        committed: the committed file (``csv``, ``markdown``) or page (``regions``).
        section: ``markdown``: only the tables under this heading of the committed page.
        ignore_columns: columns not compared (default :data:`NOT_RESULTS` for ``csv``).
        key: ``csv``: the columns rows are matched by (default: the table kind's job key).
        data: ``regions``: committed data file -> the rendered file that replaces it.
        ignore_regions: ``regions``: the page's regions not compared (measured costs, which differ from
            run to run).
    """

    kind: str
    file: str = ""
    committed: str = ""
    section: str | None = None
    ignore_columns: tuple[str, ...] = ()
    key: tuple[str, ...] = ()
    data: Mapping[str, str] = field(default_factory=dict)
    ignore_regions: tuple[str, ...] = ()


@dataclass(frozen=True)
class Render:
    """What is made from some of a page's sweeps (``kind``: :data:`RENDER_KINDS`), into a folder of
    its ``name``, and the comparisons of it with committed data; ``options``: the kind's settings."""

    name: str
    kind: str
    sweeps: tuple[str, ...]
    compare: tuple[Compare, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class PageJob:
    """One job of a page: its sweep and its overrides (every axis at one value)."""

    sweep: Sweep
    overrides: tuple[str, ...]

    @property
    def key(self) -> frozenset[tuple[str, str]]:
        """What a run directory's recorded overrides must equal (as Hydra's parser spells them; the
        same rule as make_table's, so that a page's view of its jobs reads as a complete sweep)."""
        return job_key(self.overrides)

    def describe(self) -> str:
        """``sweep: overrides`` on one line."""
        return f"{self.sweep.name}: {' '.join(self.overrides)}"


@dataclass(frozen=True)
class Page:
    """A page's definition: its sweeps, its renders, and what of the page they do not cover."""

    name: str
    title: str
    path: Path
    sweeps: tuple[Sweep, ...]
    renders: tuple[Render, ...]
    not_covered: tuple[str, ...] = ()

    def sweep(self, name: str) -> Sweep:
        """The sweep called ``name``."""
        return next(s for s in self.sweeps if s.name == name)

    def jobs(self, extra: Sequence[str] = ()) -> list[PageJob]:
        """Every job of every sweep, in the page's order (``extra``: overrides every job takes)."""
        return [PageJob(s, combo) for s in self.sweeps for combo in s.jobs(extra)]


def job_key(overrides: Sequence[str]) -> frozenset[tuple[str, str]]:
    """A job's identity from its overrides (:attr:`PageJob.key`): those that never change its results
    (:data:`evcd.report.sweep.NOT_DEFINING`) left out."""
    return canonical_overrides(job_defining(overrides))


def display(script: str, argv: Sequence[str]) -> str:
    """The command line a user types: ``python scripts/<script> args`` (quoted for a POSIX shell)."""
    return shlex.join(["python", f"scripts/{script}", *argv])


def split_overrides(overrides: Sequence[str]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Command-line overrides as (the jobs' own, Hydra's: ``hydra/...`` and ``hydra.*``, which choose
    the launcher and never change a job's results)."""
    hydra = tuple(o for o in overrides if o.lstrip("+~").startswith(("hydra/", "hydra.")))
    return tuple(o for o in overrides if o not in hydra), hydra


# ---------------------------------------------------------------------------------------- reading
def known_pages(pages_dir: Path) -> list[str]:
    """The pages defined in ``pages_dir`` (``<name>.yaml``)."""
    return sorted(p.stem for p in Path(pages_dir).glob("*.yaml"))


def load_page(name: str, pages_dir: Path) -> Page:
    """The page ``name`` of ``pages_dir``, or the page file ``name`` (a path ending in ``.yaml``).

    Raises:
        PageError: no such page (the known ones are named) or a malformed definition.
    """
    path = Path(name) if name.endswith((".yaml", ".yml")) else Path(pages_dir) / f"{name}.yaml"
    if not path.is_file():
        known = ", ".join(known_pages(pages_dir)) or "none"
        raise PageError(f"no page {name!r}: the pages are {known} (or give a page file, <path>.yaml)")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise PageError(f"{path}: not YAML ({exc})") from exc
    try:
        return _page(path, data)
    except PageError as exc:
        raise PageError(f"{path}: {exc}") from exc


def _fields(data: Any, what: str, required: Sequence[str], optional: Sequence[str] = ()) -> dict[str, Any]:
    if not isinstance(data, Mapping):
        raise PageError(f"{what}: expected a mapping, got {data!r}")
    unknown = sorted(set(data) - {*required, *optional})
    missing = [k for k in required if k not in data]
    if unknown or missing:
        allowed = ", ".join([*required, *optional])
        problems = [*(["unknown key(s) " + ", ".join(unknown)] if unknown else []),
                    *(["missing " + ", ".join(missing)] if missing else [])]  # fmt: skip
        raise PageError(f"{what}: {'; '.join(problems)} (its keys: {allowed})")
    return dict(data)


def _choice(value: Any, allowed: Sequence[str], what: str) -> str:
    if value not in allowed:
        raise PageError(f"{what}={value!r}: choose among {', '.join(allowed)}")
    return str(value)


def _strings(value: Any, what: str) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise PageError(f"{what}: expected a list of strings, got {value!r}")
    return tuple(str(v) for v in value)


def _sweep(data: Any) -> Sweep:
    d = _fields(data, "a sweep", ("name", "script", "task", "regime", "overrides"))
    what = f"sweep {d['name']!r}"
    return Sweep(
        name=str(d["name"]),
        script=_choice(d["script"], SCRIPTS, f"{what}: script"),
        task=_choice(d["task"], TASKS, f"{what}: task"),
        regime=str(d["regime"]),
        overrides=_strings(d["overrides"], f"{what}: overrides"),
    )


def _compare(data: Any, render: str, kind: str) -> Compare:
    optional = ("file", "committed", "section", "ignore_columns", "key", "data", "ignore_regions")
    d = _fields(data, f"render {render!r}: a compare entry", ("kind",), optional)
    ckind = _choice(d["kind"], COMPARE_KINDS, f"render {render!r}: compare kind")
    needs = {
        "csv": ("file", "committed"),
        "markdown": ("file", "committed"),
        "regions": ("committed", "data"),
    }
    missing = [k for k in needs[ckind] if not d.get(k)]
    if missing:
        raise PageError(f"render {render!r}: a {ckind} compare entry needs {', '.join(missing)}")
    key = _strings(d.get("key") or CSV_KEYS.get(kind, ()), f"render {render!r}: key")
    if ckind == "csv" and not key:
        raise PageError(f"render {render!r}: a csv compare entry of a {kind} render needs key (its columns)")
    default_ignore = NOT_RESULTS if ckind == "csv" else ()
    if d.get("ignore_regions") and ckind != "regions":
        raise PageError(f"render {render!r}: ignore_regions belongs to a regions compare entry, not {ckind}")
    data_map = d.get("data") or {}
    if not isinstance(data_map, Mapping):
        raise PageError(f"render {render!r}: data: expected committed file -> rendered file")
    return Compare(
        kind=ckind,
        file=str(d.get("file") or ""),
        committed=str(d["committed"]),
        section=None if d.get("section") is None else str(d["section"]),
        ignore_columns=_strings(
            d.get("ignore_columns", default_ignore), f"render {render!r}: ignore_columns"
        ),
        key=key,
        data={str(k): str(v) for k, v in data_map.items()},
        ignore_regions=_strings(d.get("ignore_regions") or (), f"render {render!r}: ignore_regions"),
    )


def _render(data: Any, sweeps: Sequence[str]) -> Render:
    d = _fields(data, "a render", ("name", "kind", "sweeps"), ("compare", "options"))
    name = str(d["name"])
    kind = _choice(d["kind"], RENDER_KINDS, f"render {name!r}: kind")
    used = _strings(d["sweeps"], f"render {name!r}: sweeps")
    unknown = [s for s in used if s not in sweeps]
    if unknown or not used:
        raise PageError(f"render {name!r}: sweeps {list(used)}: the page's sweeps are {', '.join(sweeps)}")
    options = d.get("options") or {}
    if not isinstance(options, Mapping):
        raise PageError(f"render {name!r}: options: expected a mapping")
    if options.get("figure") and not (kind == "compare" and options.get("against_calm")):
        raise PageError(f"render {name!r}: figure: {options['figure']!r} is drawn by a compare render with "
                        "against_calm: true (each row minus the same dispatcher calm)")  # fmt: skip
    compare = tuple(_compare(c, name, kind) for c in d.get("compare") or ())
    return Render(name, kind, used, compare, dict(options))


def _page(path: Path, data: Any) -> Page:
    d = _fields(data, "the page", ("title", "sweeps", "renders"), ("not_covered",))
    sweeps = tuple(_sweep(s) for s in d["sweeps"] or ())
    names = [s.name for s in sweeps]
    if not sweeps or len(set(names)) < len(names):
        raise PageError(f"sweeps {names}: a page needs sweeps, each with its own name")
    renders = tuple(_render(r, names) for r in d["renders"] or ())
    if len({r.name for r in renders}) < len(renders):
        raise PageError(f"renders {[r.name for r in renders]}: each needs its own name")
    not_covered = _strings(d.get("not_covered") or (), "not_covered")
    page = Page(path.stem, str(d["title"]), path, sweeps, renders, not_covered)
    keys = [job.key for job in page.jobs()]
    if len(set(keys)) < len(keys):
        raise PageError("two sweeps share a job (the same overrides): a run directory would stand for both")
    return page
