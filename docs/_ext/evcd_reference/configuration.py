"""The configuration reference: every config group with its options, and every key that
``scripts/train.py`` composes (and what ``scripts/evaluate.py`` composes differently), with its
default, type and meaning.

Everything is read from the sources a run reads: the configs are composed by Hydra's compose API on
``conf/`` with evcd's structured configs registered (:func:`evcd.experiments.compose.compose`); a
key's type is its field's in the dataclass that checks the block (``DQNConfig``, ``EnvConfig``,
``DemandConfig``, the perturbations' settings, an agent's constructor or config), else the type of
its value; its meaning is the comment above it in ``conf/`` (:func:`sources.read_yaml`), else the
dataclass's ``Attributes:`` / ``Args:`` docstring. A key with neither is reported by
:func:`missing_meanings` (a test fails on it): explain it at its source.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from .sources import YamlFile, attributes, code, first_sentence, plain_roles, read_yaml, table, yaml_text

#: The scripts' primary configs documented here, the first one in full.
PRIMARY = ("train", "evaluate")
#: Blocks whose dataclass docstring explains a key before any YAML comment does (the presets'
#: comments say why a value was chosen, not what the key is).
CODE_FIRST = ("learner",)


@dataclass
class Key:
    """One key of a composed config and what the page says of it."""

    path: str
    values: dict[str, Any] = field(default_factory=dict)  # composition label -> raw value
    resolved: dict[str, Any] = field(default_factory=dict)
    type: str = ""
    meaning: str = ""
    source: str = ""
    experiments: dict[str, Any] = field(default_factory=dict)  # experiment -> its value, where it differs
    only_with: list[str] = field(default_factory=list)  # "agent=central", ... (absent from the default)

    @property
    def block(self) -> str:
        """The top-level block the key belongs to ("" for a top-level scalar; an empty block, such as
        ``perturbations: {}``, is its own)."""
        empty_block = any(isinstance(v, Mapping) for v in self.values.values())
        return self.path.split(".")[0] if "." in self.path or empty_block else ""


# ---------------------------------------------------------------------------------------- composing
_SESSION: list[Path] = []  # the conf folder Hydra is initialised on by :func:`session`, if any


@contextmanager
def session(conf_dir: Path) -> Iterator[None]:
    """Hydra initialised on ``conf_dir`` (with evcd's structured configs registered) for the
    compositions inside: one initialisation for a page's many compositions."""
    from hydra import initialize_config_dir

    from evcd.experiments.schema import register_configs

    conf_dir = Path(conf_dir).resolve()
    if _SESSION and _SESSION[-1] == conf_dir:
        yield
        return
    register_configs(conf_dir)
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        _SESSION.append(conf_dir)
        try:
            yield
        finally:
            _SESSION.pop()


def compose(
    config_name: str, overrides: tuple[str, ...], conf_dir: Path
) -> tuple[DictConfig, dict[str, str]]:
    """The config ``scripts/<config_name>.py <overrides>`` composes (evcd's own composition, with
    the structured configs registered), without its ``hydra`` node, and Hydra's choice per group."""
    from hydra import compose as hydra_compose

    with session(conf_dir):
        cfg = hydra_compose(config_name, overrides=list(overrides), return_hydra_config=True)
    choices = {str(k): str(v) for k, v in cfg.hydra.runtime.choices.items() if v is not None}
    with open_dict(cfg):
        del cfg["hydra"]
    return cfg, choices


def group_options(conf_dir: Path) -> dict[str, list[str]]:
    """Every config group of ``conf_dir`` (a folder of YAML files, or a group evcd's ConfigStore fills)
    and its options as Hydra lists them (files, structured configs and launcher plugins)."""
    from hydra.core.global_hydra import GlobalHydra

    groups = sorted({str(p.parent.relative_to(conf_dir)) for p in Path(conf_dir).rglob("*.yaml")} - {"."})
    with session(conf_dir):
        loader = GlobalHydra.instance().config_loader()
        groups = sorted(set(groups) | {g for g in loader.list_groups("") if g in ("learner", "agent")})
        return {g: sorted(loader.get_group_options(g)) for g in groups}


def flatten(node: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(dotted key, value) of every leaf of a plain mapping; an empty mapping is a leaf."""
    if isinstance(node, Mapping) and node:
        for key, value in node.items():
            yield from flatten(value, f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix, node


def leaves(cfg: DictConfig, resolve: bool) -> dict[str, Any]:
    """The composed config's keys and values (interpolations kept unless ``resolve``)."""
    return dict(flatten(OmegaConf.to_container(cfg, resolve=resolve)))


# ---------------------------------------------------------------------------------------- meanings
@cache
def yaml_files(conf_dir: Path) -> tuple[tuple[str, str, YamlFile], ...]:
    """Every YAML file of ``conf_dir``: (its group, "" for a primary config; the prefix of its keys in
    a composed config; its comments)."""
    out = []
    for path in sorted(Path(conf_dir).rglob("*.yaml")):
        group = str(path.parent.relative_to(conf_dir))
        group = "" if group == "." else group
        info = read_yaml(path)
        prefix = "" if not group or info.package == "_global_" else group.replace("/", ".")
        out.append((group, prefix, info))
    return tuple(out)


def yaml_meaning(path: str, conf_dir: Path, primary: str, choices: Mapping[str, str]) -> tuple[str, str]:
    """The comment explaining ``path`` in ``conf_dir`` and its file: the chosen option's file first,
    then the group's other files, the primary config, the other configs; never an experiment's (its
    comments say why it chose a value, not what the key is)."""
    best: tuple[int, str, str] | None = None
    for group, prefix, info in yaml_files(conf_dir):
        if group.startswith("hydra") or (prefix and not path.startswith(prefix + ".")):
            continue
        text = info.keys.get(path[len(prefix) + 1 :] if prefix else path)
        if group == "" and path in info.groups:  # a key named as its group (``task``): the defaults' comment
            text = info.groups[path]
        if not text:
            continue
        chosen = group and choices.get(group) == info.path.stem
        if group == "experiment":
            continue
        if chosen:
            rank = 0
        elif group and (path.split(".")[0] == group.split("/")[0] or info.package == "_global_"):
            rank = 1
        elif group == "" and info.path.stem == primary:
            rank = 2
        elif group == "":
            rank = 3
        else:
            rank = 4
        candidate = (rank, str(info.path.relative_to(conf_dir.parent)), text)
        if best is None or candidate[:2] < best[:2]:
            best = candidate
    return (best[2], best[1]) if best else ("", "")


def code_source(path: str, choices: Mapping[str, str]) -> tuple[Any, str] | None:
    """The code that checks ``path``'s block and documents its fields: (the class or function, the
    field's name in it), or ``None``."""
    from evcd.agents.dqn import DQNConfig
    from evcd.env.charging_nav import ChargingNavEnv
    from evcd.scenario.demand import DemandConfig
    from evcd.sim.perturbations import Perturbations

    parts = path.split(".")
    if parts[0] == "learner" and len(parts) == 2:
        return DQNConfig, parts[1]
    if parts[0] == "env" and len(parts) == 2:
        return ChargingNavEnv, parts[1]
    if parts[:2] == ["scenario", "demand"] and len(parts) == 3:
        return DemandConfig, parts[2]
    if parts[0] == "perturbations" and len(parts) == 3:
        hints = typing.get_type_hints(Perturbations)
        kind = typing.get_args(hints.get(parts[1], None)) or (hints.get(parts[1]),)
        cls = next((c for c in kind if dataclasses.is_dataclass(c)), None)
        return (cls, parts[2]) if cls is not None else None
    if parts[0] == "agent" and len(parts) == 2:
        return agent_source(choices.get("agent", ""), parts[1])
    return None


def agent_source(name: str, option: str) -> tuple[Any, str] | None:
    """Where the registered agent ``name`` documents ``option``: its constructor's ``Args:`` or the
    dataclass its ``config`` argument takes (e.g. ``PPOConfig``)."""
    from evcd.agents import agent_class, agent_names

    if name not in agent_names():
        return None
    cls = agent_class(name)
    if option in attributes(cls):
        return cls, option
    hints = typing.get_type_hints(cls.__init__, sys.modules[cls.__module__].__dict__)
    for arg in typing.get_args(hints.get("config")) or (hints.get("config"),):
        if dataclasses.is_dataclass(arg) and option in {f.name for f in dataclasses.fields(arg)}:
            return arg, option
    return None


def field_type(owner: Any, name: str) -> str:
    """The declared type of ``owner``'s field or constructor argument ``name`` ("" if none)."""
    if dataclasses.is_dataclass(owner):
        for f in dataclasses.fields(owner):
            if f.name == name:
                return str(f.type)
    try:
        import inspect

        parameter = inspect.signature(owner.__init__).parameters.get(name)
    except (TypeError, ValueError):
        return ""
    if parameter is None or parameter.annotation is inspect.Parameter.empty:
        return ""
    return str(parameter.annotation)


def value_type(values: list[Any]) -> str:
    """The type of a key's values as YAML writes them (``int``, ``list[float]``, ``... | null``)."""

    def one(v: Any) -> str:
        if isinstance(v, bool):
            return "bool"
        if isinstance(v, (int, float, str)):
            return type(v).__name__
        if isinstance(v, (list, tuple)):
            inner = sorted({one(x) for x in v})
            return f"list[{' | '.join(inner)}]" if inner else "list"
        if isinstance(v, Mapping):
            return "mapping"
        return "null"

    kinds = {one(v) for v in values}
    if kinds == {"int", "float"}:
        kinds = {"float"}
    if "list" in kinds and any(k.startswith("list[") for k in kinds):
        kinds.discard("list")  # an empty list beside typed ones
    named = sorted(k for k in kinds if k != "null")
    return " | ".join(named + (["null"] if "null" in kinds else [])) or "null"


# ---------------------------------------------------------------------------------------- the keys
@cache
def collect(conf_dir: Path, primary: str = "train", with_options: bool = True) -> list[Key]:
    """Every key of ``primary``'s composition, and (``with_options``) those its groups' other options add,
    with default, type, meaning and (for ``train``) each experiment's value where it differs."""
    with session(conf_dir):
        return _collect(Path(conf_dir), primary, with_options)


def _collect(conf_dir: Path, primary: str, with_options: bool) -> list[Key]:
    from evcd.experiments.compose import experiment_names

    cfg, choices = compose(primary, (), conf_dir)
    keys: dict[str, Key] = {}
    for path, raw in leaves(cfg, resolve=False).items():
        keys[path] = Key(path, {"default": raw})
    resolved = leaves(cfg, resolve=True)
    for path, key in keys.items():
        key.resolved["default"] = resolved[path]
    option_choices: dict[str, dict[str, str]] = {}
    for group, options in group_options(conf_dir).items():
        if not with_options or group.startswith("hydra") or group not in choices or group == "experiment":
            continue
        for option in options:
            if option == choices[group]:
                continue
            other, other_choices = compose(primary, (f"{group}={option}",), conf_dir)
            for path, raw in leaves(other, resolve=False).items():
                if path in keys and "default" in keys[path].values:
                    continue
                key = keys.setdefault(path, Key(path))
                key.values[f"{group}={option}"] = raw
                key.only_with.append(f"{group}={option}")
                option_choices.setdefault(path, other_choices)
    if primary == "train" and "experiment" in choices:
        plain = leaves(compose(primary, ("~experiment",), conf_dir)[0], resolve=False)
        for name in experiment_names(conf_dir):
            values = leaves(compose(primary, (f"experiment={name}",), conf_dir)[0], resolve=False)
            for path, key in keys.items():
                if path in values and (path not in plain or values[path] != plain[path]):
                    key.experiments[name] = values[path]
        for path, key in keys.items():
            if key.experiments and path in plain:
                key.experiments["(none)"] = plain[path]
    for path, key in keys.items():
        own = option_choices.get(path, choices)
        describe(key, conf_dir, primary, own)
    return list(keys.values())


def describe(key: Key, conf_dir: Path, primary: str, choices: Mapping[str, str]) -> None:
    """Fill ``key``'s meaning (and its source) and type."""
    found = code_source(key.path, choices)
    doc = attributes(found[0]).get(found[1], "") if found else ""
    text, source = yaml_meaning(key.path, conf_dir, primary, choices)
    if doc and (key.block in CODE_FIRST or not text):
        text, source = doc, f"{found[0].__module__}.{found[0].__qualname__}"
    key.meaning, key.source = text, source
    declared = field_type(*found) if found else ""
    values = [*key.resolved.values(), *key.values.values(), *key.experiments.values()]
    key.type = declared or value_type([v for v in values if not is_interpolation(v)])


def is_interpolation(value: Any) -> bool:
    """Whether ``value`` is an unresolved ``${...}``."""
    return isinstance(value, str) and value.startswith("${")


def missing_meanings(keys: list[Key]) -> list[str]:
    """The keys that nothing explains."""
    return [k.path for k in keys if not k.meaning.strip()]


# ---------------------------------------------------------------------------------------- Markdown
def default_cell(key: Key) -> str:
    """The key's default (an interpolation with what it resolves to), or its value per option."""
    if "default" in key.values:
        raw, value = key.values["default"], key.resolved["default"]
        text = code(raw)
        return f"{text} (= {code(value)})" if yaml_text(raw) != yaml_text(value) else text
    by_value: dict[str, list[str]] = {}
    for label, value in key.values.items():
        by_value.setdefault(yaml_text(value), []).append(label)
    return "; ".join(f"`{v}` with {options_text(labels)}" for v, labels in by_value.items())


def options_text(labels: list[str]) -> str:
    """``group=a``, ``group=b`` as "group=`a`, `b`"."""
    groups: dict[str, list[str]] = {}
    for label in labels:
        group, _, option = label.partition("=")
        groups.setdefault(group, []).append(option)
    return "; ".join(f"{g}=" + ", ".join(f"`{o}`" for o in options) for g, options in groups.items())


def experiments_cell(key: Key) -> str:
    """What each experiment sets the key to, where that differs from the composition without one."""
    if not key.experiments:
        return ""
    parts = [f"{name}: {code(v)}" for name, v in key.experiments.items() if name != "(none)"]
    if "(none)" in key.experiments:
        parts.append(f"without: {code(key.experiments['(none)'])}")
    return "; ".join(parts)


BLOCK_TITLES = {"": "Top-level keys"}


def keys_markdown(conf_dir: Path, primary: str = "train", keys: list[Key] | None = None) -> str:
    """One section per block of ``primary``'s composition: key, default, type, meaning (and, for
    ``train``, what the experiments set)."""
    keys = keys if keys is not None else collect(conf_dir, primary)
    blocks: dict[str, list[Key]] = {"": []}
    for key in keys:
        blocks.setdefault(key.block, []).append(key)
    with_experiments = any(k.experiments for k in keys)
    out = []
    for block, members in blocks.items():
        title = BLOCK_TITLES.get(block, f"`{block}`")
        sources = sorted({k.source for k in members if k.source})
        header = ["key", "default", "type", "meaning"]
        header += ["set by the experiments"] if with_experiments else []
        rows = []
        for k in members:
            row = [f"`{k.path}`", default_cell(k), f"`{k.type}`", plain_roles(k.meaning)]
            rows.append(row + ([experiments_cell(k)] if with_experiments else []))
        out += [f"### {title}", "", "Explained in " + ", ".join(f"`{s}`" for s in sources) + ".", "",
                table(header, rows), ""]  # fmt: skip
    return "\n".join(out)


def groups_markdown(conf_dir: Path) -> str:
    """The config groups: each group's default in each primary config and what it selects, then every
    option with the first sentence of its description."""
    from evcd.agents import agent_class, agent_names
    from evcd.agents.dqn import DQNConfig
    from evcd.experiments.schema import LEARNER_DEFAULTS

    conf_dir = Path(conf_dir)
    options = group_options(conf_dir)
    choices = {name: compose(name, (), conf_dir)[1] for name in PRIMARY}
    primaries = {info.path.stem: info for group, _, info in yaml_files(conf_dir) if group == ""}
    rows = []
    for group in options:
        defaults = [f"`{choices[p].get(group)}`" if group in choices[p] else "" for p in PRIMARY]
        what = next((primaries[p].groups[group] for p in PRIMARY if group in primaries[p].groups), "")
        if not what:  # a group another config or an experiment selects
            found = (info.groups[group] for _, _, info in yaml_files(conf_dir) if group in info.groups)
            what = next(found, "")
        rows.append([f"`{group}`", *defaults, what])
    out = [table(["group", *[f"`{p}.py` default" for p in PRIMARY], "what it selects"], rows), ""]
    files = {(group, info.path.stem): info for group, _, info in yaml_files(conf_dir) if group}
    option_rows = []
    for group, names in options.items():
        for name in names:
            info = files.get((group, name))
            if info is not None:
                text, where = first_sentence(info.header), f"`{info.path.relative_to(conf_dir.parent)}`"
            elif group == "learner" and name == LEARNER_DEFAULTS:
                text, where = first_sentence(DQNConfig.__doc__ or ""), "`evcd.agents.dqn.DQNConfig`"
            elif group == "agent" and name in agent_names():
                cls = agent_class(name)
                text, where = first_sentence(cls.__doc__ or ""), f"`{cls.__module__}.{cls.__qualname__}`"
            else:
                text, where = "a Hydra plugin's own option", "Hydra"
            option_rows.append([f"`{group}`", f"`{name}`", text, where])
    out += ["Every option of every group:", "", table(["group", "option", "what it is", "from"], option_rows)]
    return "\n".join(out)


def evaluate_markdown(conf_dir: Path) -> str:
    """The keys ``scripts/evaluate.py`` composes that ``train.py`` has not, or with another default;
    and those it does not have."""
    conf_dir = Path(conf_dir)
    train = {k.path: k for k in collect(conf_dir, "train") if "default" in k.values}
    evaluate = collect(conf_dir, "evaluate", with_options=False)
    differ = [k for k in evaluate if k.path not in train or yaml_text(train[k.path].values["default"])
              != yaml_text(k.values["default"])]  # fmt: skip
    absent = sorted({p.split(".")[0] for p in train} - {k.path.split(".")[0] for k in evaluate})
    rows = [[f"`{k.path}`", default_cell(k),
             default_cell(train[k.path]) if k.path in train else "(not in `train.yaml`)",
             f"`{k.type}`", plain_roles(k.meaning)] for k in differ]  # fmt: skip
    return "\n".join([
        table(["key", "`evaluate.py` default", "`train.py` default", "type", "meaning"], rows), "",
        "`scripts/evaluate.py` has none of these blocks and keys of `train.py`: "
        + ", ".join(f"`{b}`" for b in absent) + ".",
    ])  # fmt: skip
