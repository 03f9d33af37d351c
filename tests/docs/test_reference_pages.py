"""The reference pages written from the code when the site is built (docs/_ext/evcd_reference):
experiments, configuration and logged metrics.

Each page is compared with what it claims to describe, read independently: the experiments with
Hydra's own composition of every ``conf/experiment/*.yaml``, the configuration with every key
``scripts/train.py`` composes, the metrics with the event files, ``results.json`` and episode files of
a real training run (the one ``tests/scripts/test_train_script.py`` compares its resumed runs with,
built once per test run) and with every tag and field the code writes. Copies of ``conf/`` with one
thing changed show that a change in a YAML file reaches the page and that a key nobody explains is
caught.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import importlib
import json
import re
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from omegaconf import OmegaConf

from tests.conftest import CONF, ROOT, compose_config

# the training run of tests/scripts/test_train_script.py (dueling_ddqn, 6 episodes on the grid, beside
# greedy and queue_aware), made once per test run for both modules
from tests.scripts.test_train_script import small, uninterrupted  # noqa: F401

DOCS = ROOT / "docs"
REFERENCE = DOCS / "reference"
PAGES = ("experiments", "configuration", "metrics", "paper-differences")


def extension(name: str = "") -> ModuleType:
    """The Sphinx extension's package (or one of its modules), as ``docs/conf.py`` loads it."""
    ext = str(DOCS / "_ext")
    if ext not in sys.path:
        sys.path.insert(0, ext)
    return importlib.import_module(f"evcd_reference{'.' + name if name else ''}")


@functools.cache
def rendered(page: str) -> str:
    """A reference page's Markdown with its generated blocks filled in, as Sphinx reads it."""
    return extension().render((REFERENCE / f"{page}.md").read_text())


def section(markdown: str, heading: str) -> str:
    """The text of ``markdown`` under ``heading`` up to the next heading of the same level."""
    level = heading.split(" ", 1)[0]
    start = markdown.index(heading + "\n")
    rest = markdown[start + len(heading) + 1 :]
    end = re.search(rf"^{level} ", rest, flags=re.M)
    return rest[: end.start()] if end else rest


def table_row(markdown: str, label: str) -> str:
    """The first table row of ``markdown`` whose first cell is ``label``."""
    return next(line for line in markdown.splitlines() if line.startswith(f"| {label} |"))


def copy_conf(tmp_path: Path) -> Path:
    """A copy of ``conf/`` beside nothing else (its scenarios are found from the project root)."""
    conf = tmp_path / "conf"
    shutil.copytree(CONF, conf)
    return conf


# ---------------------------------------------------------------------------------------- the site
@pytest.mark.slow
def test_the_pages_are_in_the_reference_navigation_and_every_block_has_a_generator():
    index = (DOCS / "index.md").read_text()
    toctree = re.search(r"```\{toctree\}\n:caption: Reference\n(.*?)```", index, flags=re.S)[1]
    for page in PAGES:
        assert f"reference/{page}\n" in toctree, page
    assert '"evcd_reference"' in (DOCS / "conf.py").read_text()
    for page in PAGES:
        text = rendered(page)
        assert "{evcd-reference}" not in text, page  # every block was replaced
        # no internal counters of the project's work in a page
        assert not re.search(r"\b(stop|issue|task|step) \d+\b", text, flags=re.I), page
    with pytest.raises(ValueError, match="unknown; the generators"):
        extension().render("```{evcd-reference} nothing\n```\n")


# ---------------------------------------------------------------------------------------- experiments
@pytest.mark.parametrize("experiment", sorted(p.stem for p in (CONF / "experiment").glob("*.yaml")))
def test_the_experiments_page_shows_each_experiment_as_hydra_composes_it(experiment):
    page = rendered("experiments")
    cfg = compose_config("train", f"experiment={experiment}")
    overview = table_row(page, f"[`{experiment}`](#experiment-{experiment})")
    part = section(page, f"## `{experiment}`")
    assert f"| {cfg.evs} |" in overview
    assert f"`{cfg.task}`" in overview and f"`{cfg.env.reward}`" in overview
    # the splits' days as the config lists them, each under its split's column
    days = {"train": cfg.train.days, "tuning": cfg.train.validation.days, "eval": cfg.eval.days}
    row = table_row(part, "background days")
    cells = [c.strip() for c in row.strip("|").split("|")][1:]
    for cell, (split, listed) in zip(cells, days.items(), strict=True):
        shown = {day for run in re.findall(r"\d+(?:-\d+)?", cell.split("(")[0]) for day in _expand(run)}
        assert shown == set(listed), (split, cell)
    # the window, the EVs and the scenario's points of the composed world
    lo, hi = cfg.env.departure_window
    assert f"{int(lo) // 3600:02d}:{int(lo) % 3600 // 60:02d}-{int(hi) // 3600:02d}:" in part
    assert f"| background EVs | {cfg.evs} |" in part
    assert f"{cfg.scenario.charging_points} charging points per station" in part
    assert ("`DNZH` in raw units" if cfg.task == "fleet" else "`DNZ` in raw units") in part


def _expand(text: str) -> Iterator[int]:
    lo, _, hi = text.partition("-")
    yield from range(int(lo), int(hi or lo) + 1)


def test_a_change_in_an_experiment_file_reaches_the_page(tmp_path):
    experiments = extension("experiments")
    conf = copy_conf(tmp_path)
    peak = conf / "experiment" / "peak.yaml"
    peak.write_text(peak.read_text().replace("regime: peak\n", "regime: peak\nevs: 321\n"))
    shutil.copy(conf / "experiment" / "paper.yaml", conf / "experiment" / "copied.yaml")
    page = experiments.markdown(conf)
    assert "| background EVs | 321 |" in section(page, "## `peak`")
    assert "| background EVs | 400 |" in section(page, "## `paper`")
    assert "## `copied`" in page


# ---------------------------------------------------------------------------------------- configuration
def _leaves(node: Any, prefix: str = "") -> Iterator[str]:
    if isinstance(node, dict) and node:
        for key, value in node.items():
            yield from _leaves(value, f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix


@pytest.mark.slow
def test_every_key_train_composes_is_on_the_configuration_page_with_its_default_and_a_meaning():
    configuration = extension("configuration")
    keys = configuration.collect(CONF)
    assert configuration.missing_meanings(keys) == []
    assert all(k.type for k in keys)
    page = rendered("configuration")
    train = section(page, "## Keys of `scripts/train.py`")
    composed = OmegaConf.to_container(compose_config("train"), resolve=False)
    for path in _leaves(composed):
        row = table_row(train, f"`{path}`")
        assert f"`{extension('sources').yaml_text(_get(composed, path))}`" in row, (path, row)
    # a key only another option of a group has, with the option named
    assert "agent=`central`" in table_row(train, "`agent.charge_s`")
    assert "task=`fleet`" in table_row(train, "`fleet.guided_share`")
    # every group and its options
    for folder in (p for p in CONF.iterdir() if p.is_dir() and p.name != "hydra"):
        for option in folder.glob("*.yaml"):
            assert f"| `{folder.name}` | `{option.stem}` |" in page, option
    # evaluate.py's own keys
    evaluate = section(page, "## `scripts/evaluate.py`")
    for key in ("episodes", "bootstrap_resamples"):
        assert f"| `{key}` |" in evaluate


def _get(node: Any, path: str) -> Any:
    for part in path.split("."):
        node = node[part]
    return node


def test_a_key_nobody_explains_is_reported_and_a_comment_explains_it(tmp_path):
    configuration = extension("configuration")
    conf = copy_conf(tmp_path)
    train = conf / "train.yaml"
    train.write_text(train.read_text().replace("seed: 0\n", "seed: 0\nunexplained_key: 3\n"))
    keys = configuration.collect(conf, with_options=False)
    assert configuration.missing_meanings(keys) == ["unexplained_key"]
    commented = tmp_path / "commented"
    shutil.copytree(conf, commented)
    train = commented / "train.yaml"
    train.write_text(train.read_text().replace("unexplained_key: 3\n", "# what it is\nunexplained_key: 3\n"))
    keys = {k.path: k for k in configuration.collect(commented, with_options=False)}
    assert keys["unexplained_key"].meaning == "what it is" and keys["unexplained_key"].type == "int"


# ---------------------------------------------------------------------------------------- metrics
def documented() -> set[str]:
    """The names the metrics page explains."""
    return extension("metrics").documented_names(rendered("metrics"))


def explained(name: str, names: set[str]) -> bool:
    return extension("metrics").explained(name, names)


def field_paths(node: Any, prefix: str = "") -> Iterator[str]:
    """The dotted path of every value of a ``results.json`` (``[]`` for the entries of a list of
    objects; an empty object has none)."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from field_paths(value, f"{prefix}.{key}" if prefix else str(key))
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for item in node:
            yield from field_paths(item, prefix + "[]")
    else:
        yield prefix


def unexplained_fields(results: dict[str, Any], names: set[str], config_keys: set[str]) -> set[str]:
    """The fields of ``results`` the page does not explain. ``config`` is the configuration page's;
    the entries of ``episodes`` are the per-episode files' columns; a baseline's summary has the
    fields of ``summary``; the fleet's paired block has one set of paired fields per measure."""
    out = set()
    for path in set(field_paths(results)):
        if path.startswith("config."):
            ok = path.removeprefix("config.") in config_keys
        elif path.startswith("episodes[]."):
            ok = path.removeprefix("episodes[].") in names
        elif re.match(r"baselines\.[^.]+\.summary\.", path):
            ok = explained("summary." + path.split(".summary.", 1)[1], names)
        elif re.match(r"baselines\.[^.]+\.paired\.[^.]+\.", path):
            rule, measure, field = re.match(r"baselines\.([^.]+)\.paired\.([^.]+)\.(.+)", path).groups()
            ok = explained(f"baselines.{rule}.paired.{measure}", names) and explained(
                f"baselines.{rule}.paired.{field}", names)  # fmt: skip
        else:
            ok = explained(path, names)
        if not ok:
            out.add(path)
    return out


@pytest.fixture(scope="module")
def training_run(request) -> Path:
    """test_train_script.py's reference run directory (made once per test run)."""
    return request.getfixturevalue("uninterrupted")


@pytest.mark.slow
def test_every_tag_and_field_a_training_run_writes_is_explained(training_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    names = documented()
    events = EventAccumulator(str(training_run / "tensorboard"))
    events.Reload()
    tags = set(events.Tags()["scalars"]) | {t.removesuffix("/text_summary") for t in events.Tags()["tensors"]}
    assert {"charts/travel_time", "losses/td_loss", "eval/paired_difference_greedy", "config"} <= tags
    assert sorted(t for t in tags if not explained(t, names)) == []
    results = json.loads((training_run / "results.json").read_text())
    config_keys = {k.path for k in extension("configuration").collect(CONF)}
    assert sorted(unexplained_fields(results, names, config_keys)) == []
    files = [training_run / "train_episodes.csv", training_run / "episodes.csv",
             *training_run.glob("baseline_*_episodes.csv")]  # fmt: skip
    assert len(files) == 4
    for path in files:
        with open(path, newline="") as f:
            header = next(csv.reader(f))
        assert [c for c in header if c not in names] == [], path.name
    # the check can fail: a field, a tag or a column nobody explains
    assert unexplained_fields({**results, "new_field": 1}, names, config_keys) == {"new_field"}
    assert not explained("charts/new_curve", names) and "new_column" not in names


def test_every_tag_the_code_writes_is_explained():
    from evcd.env.fleet.measures import FleetMeasures
    from evcd.env.runners.base import EpisodeRow
    from evcd.env.runners.fleet import FleetEpisode

    names = documented()
    found = set()
    for path in (ROOT / "evcd").rglob("*.py"):
        found |= set(re.findall(r"f?\"((?:charts|losses|eval)/[^\"\s]*)\"", path.read_text()))
    assert "charts/{key}" in found and "losses/policy" in found  # the row's curves, PPO's scalars
    for tag in sorted(found - {"charts/{key}"}):
        assert explained(re.sub(r"\{[^}]+\}", "someone", tag), names), tag
    # charts/{key}: the keys of each task's training row
    row = EpisodeRow(0, 1, 0.0, "e", 0, "1-1", 1, "cs1", 60.0, 0.0, "charging", False, -0.1, 0.1, 0)
    fleet = FleetEpisode(0, 0, _measures(FleetMeasures), {"ev": -0.1}, 3, 1.0)
    for key in [*row.charts(), *fleet.charts()]:
        assert f"charts/{key}" in names, key


def _measures(cls: type) -> Any:
    """A fleet episode's measures with every value finite."""
    return cls(**{f.name: 1 if f.type == "int" else 0.5 for f in dataclasses.fields(cls)})


def test_the_fields_of_runs_not_made_here_are_explained():
    """The fleet's, the validation's, the hindsight bound's and scripts/evaluate.py's blocks, from the
    code that writes them."""
    from evcd.cli.trained_world import trained_world
    from evcd.env.fleet.measures import FleetMeasures
    from evcd.env.runners.base import EpisodeRow
    from evcd.env.runners.fleet import FleetEpisode
    from evcd.loops.fleet import FleetTrainState, paired_fleet, summarize_fleet
    from evcd.loops.hindsight import HindsightBound
    from evcd.loops.validation import ValidationPoint, ValidationRecord

    names = documented()
    episodes = [FleetEpisode(i, i, _measures(FleetMeasures), {"ev": -0.1}, 3, 1.0) for i in range(2)]
    assert [c for c in episodes[0].row() if c not in names] == []
    summary = dataclasses.asdict(summarize_fleet(episodes, np.random.default_rng(0), 10))
    bound = HindsightBound(2)
    row = EpisodeRow(0, 1, 0.0, "e", 0, "1", 1, "cs1", 60.0, 0.0, "charging", False, -0.1, 0.1)
    bound.by_station = [[row], [dataclasses.replace(row, station=0, truncated=True)]]
    record = ValidationRecord([ValidationPoint(2, 10, [60.0, float("nan")])], {"greedy": [50.0, 70.0]})
    cfg = OmegaConf.to_container(compose_config("evaluate"), resolve=True)
    results = {
        "summary": summary,
        "training": FleetTrainState().summary(),
        "validation": record.to_dict(),
        **bound.report(),
        "trained_world": trained_world(cfg, cfg),
        "baselines": {"greedy": {"summary": summary, "paired": paired_fleet(episodes, episodes, 0, 10)}},
    }
    assert sorted(unexplained_fields(results, names, set())) == []


def test_every_field_of_a_generated_table_has_its_docstring():
    metrics = extension("metrics")
    page = (REFERENCE / "metrics.md").read_text()
    classes = re.findall(r"\{evcd-reference\} fields (\S+)", page)
    assert len(classes) == 3
    for dotted in classes:
        assert metrics.undocumented_fields(dotted) == [], dotted
