"""The experiments page: every shipped experiment (``conf/experiment/*.yaml``) split by split, as a run
meets it.

Each experiment is composed as ``scripts/train.py experiment=<name>`` composes it
(:func:`evcd.experiments.compose_experiment`), and each split's world is what the scripts and
``gymnasium.make`` build their environments with (:func:`evcd.experiments.split_kwargs`: days,
departure window, EV count, scenario, reward, observation); nothing is read twice, so a change in a
YAML file changes the page.
"""

from __future__ import annotations

import contextlib
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from .sources import code, read_yaml, table

#: Each split's config keys: its days, its episodes and the rules played on the same episodes.
SPLIT_KEYS = {
    "train": ("train.days", "train.episodes", None),
    "tuning": ("train.validation.days", "train.validation.episodes", "train.validation.rules"),
    "eval": ("eval.days", "eval.episodes", "eval.baselines"),
}
#: What an observation block counts, in the environment's raw units (``normalize_obs=False``).
RAW_UNITS = {"D": "m", "N": "vehicles", "Z": "vehicles", "H": "vehicles", "P": "points", "T": "s",
             "F": "vehicles", "G": "vehicles"}  # fmt: skip
#: Seeds whose evaluation days are listed when each seed has its own (``eval.day_per_seed``).
SHOWN_SEEDS = 3


def clock(seconds: float) -> str:
    """Seconds of day as ``HH:MM``."""
    minutes = round(float(seconds) / 60)
    return f"{minutes // 60:02d}:{minutes % 60:02d}"


def days_list(days: tuple[int, ...] | list[int]) -> str:
    """Demand seeds with runs of consecutive ones as ranges (``0, 3``; ``101-105``)."""
    runs: list[list[int]] = []
    for d in days:
        if runs and d == runs[-1][-1] + 1:
            runs[-1].append(d)
        else:
            runs.append([d])
    return ", ".join(f"{r[0]}-{r[-1]}" if len(r) > 2 else ", ".join(map(str, r)) for r in runs)


def window_text(window: tuple[float, float]) -> str:
    """A departure window as clock times with its seconds."""
    lo, hi = window
    return f"{clock(lo)}-{clock(hi)} (`[{lo:g}, {hi:g}]` s)"


def units_text(layout: str, normalize: bool) -> str:
    """The observation's blocks with their units: raw, or divided by :func:`unit_divisors`."""
    from evcd.env.observation import unit_divisors

    sentinel = 7  # a number of charging points no fixed divisor equals
    divisors = unit_divisors([sentinel], layout)
    raw = ", ".join(f"`{c}` {RAW_UNITS.get(c, '?')}" for c in layout)
    by = ["points" if d == sentinel else f"{d:g}" for d in divisors]
    scaled = ", ".join(f"`{c}` / {d}" for c, d in zip(layout, by, strict=True))
    if normalize:
        return f"`{layout}` normalised: {scaled}"
    return f"`{layout}` in raw units: {raw} (normalised, as `gymnasium.make` gives it: {scaled})"


@dataclass
class Split:
    """One split of an experiment as a run meets it (:func:`evcd.experiments.split_kwargs`)."""

    name: str
    days_key: str
    days: tuple[int, ...]
    days_by_seed: dict[int, tuple[int, ...]]
    episodes: int
    rules: list[str]
    kwargs: dict[str, Any]


@dataclass
class Experiment:
    """A shipped experiment: its file's words, its composed config and its splits."""

    name: str
    description: str
    cfg: DictConfig
    choices: dict[str, str]
    splits: dict[str, Split] = field(default_factory=dict)

    @property
    def task(self) -> str:
        return str(self.cfg.task)


def file_words(path: Path) -> str:
    """An experiment file's header comment as Markdown: its sentences as paragraphs, its commands
    (``python scripts/...`` and their continuation lines) as code blocks, in the file's order."""
    parts: list[tuple[str, list[str]]] = []
    for line in read_yaml(path).header_lines:
        stripped = line.strip()
        command = stripped.startswith("python ")
        continued = bool(parts) and parts[-1][0] == "code" and parts[-1][1][-1].rstrip().endswith("\\")
        kind = "code" if command or continued else "text"
        if not parts or parts[-1][0] != kind:
            parts.append((kind, []))
        parts[-1][1].append(line.rstrip())
    out = []
    for kind, lines in parts:
        if kind == "code":
            out.append("```bash\n" + textwrap.dedent("\n".join(lines)) + "\n```")
        else:
            out.append(" ".join(x.strip() for x in lines if x.strip()))
    return "\n\n".join(out)


def load(name: str, conf_dir: Path, seed: int = 0) -> Experiment:
    """Compose experiment ``name`` and build each split's world for run ``seed``."""
    from evcd.experiments import SPLITS, compose_experiment, split_days, split_kwargs

    from .configuration import compose

    conf_dir = Path(conf_dir)
    cfg = compose_experiment(name, conf_dir=conf_dir)
    choices = compose("train", (f"experiment={name}",), conf_dir)[1]
    exp = Experiment(name, file_words(conf_dir / "experiment" / f"{name}.yaml"), cfg, choices)
    for split in SPLITS:
        days_key, episodes_key, rules_key = SPLIT_KEYS[split]
        by_seed = {}
        if split == "eval" and bool(cfg.eval.day_per_seed):
            by_seed = {s: split_days(cfg, split, s) for s in range(SHOWN_SEEDS)}
        rules = list(OmegaConf.select(cfg, rules_key) or []) if rules_key else []
        exp.splits[split] = Split(split, days_key, tuple(OmegaConf.select(cfg, days_key)), by_seed,
                                  int(OmegaConf.select(cfg, episodes_key)), rules,
                                  split_kwargs(cfg, split, seed))  # fmt: skip
    return exp


def load_all(conf_dir: Path) -> list[Experiment]:
    """Every experiment of ``conf_dir``, in name order."""
    from evcd.experiments import experiment_names

    return [load(name, Path(conf_dir)) for name in experiment_names(conf_dir)]


def layout(split: Split, task: str) -> str:
    """The split's observation layout (the base and the observation options' blocks)."""
    from evcd.env.observation import layout_of

    return layout_of("DNZH" if task == "fleet" else "DNZ", split.kwargs.get("observe") or ())


def scenario_text(split: Split, conf_dir: Path) -> str:
    """The scenario folder (relative to the project) and its charging points per station."""
    path = Path(split.kwargs["scenario"])
    with contextlib.suppress(ValueError):  # outside the project: the whole path
        path = path.relative_to(Path(conf_dir).resolve().parent)
    return f"`{path}`, {split.kwargs['charging_points']} charging points per station"


def days_text(split: Split) -> str:
    """The split's days as its config key gives them (and each run seed's, where seeds differ)."""
    text = f"{days_list(split.days)} (`{split.days_key}`)"
    if split.days_by_seed:
        seeds = "; ".join(f"seed {s}: {days_list(d)}" for s, d in split.days_by_seed.items())
        text += f"; each run seed its own (`eval.day_per_seed`): {seeds}; ..."
    return text


def perturbations_text(value: Any) -> str:
    """The day's perturbations (``none``: every day calm)."""
    if value is None:
        return "none (every day calm)"
    from dataclasses import fields

    kinds = [f.name for f in fields(value) if getattr(value, f.name) is not None]
    return ", ".join(kinds) or "none (every day calm)"


def rows(exp: Experiment, conf_dir: Path) -> list[list[str]]:
    """The split table of ``exp``: one row per property, one column per split."""
    from evcd.sim.perturbations import Perturbations

    splits = list(exp.splits.values())

    def row(label: str, values: list[str]) -> list[str]:
        return [label, *values]

    out = [
        row("background days", [days_text(s) for s in splits]),
        row("episodes", [f"{s.episodes:,}" for s in splits]),
        row("departure window", [window_text(s.kwargs["departure_window"]) for s in splits]),
        row("background EVs", [str(s.kwargs.get("evs", "the route file's")) for s in splits]),
        row("scenario", [scenario_text(s, conf_dir) for s in splits]),
        row("reward", [code(s.kwargs["reward"]) for s in splits]),
        row(
            "observation", [units_text(layout(s, exp.task), bool(s.kwargs["normalize_obs"])) for s in splits]
        ),
        row("truncated after", [f"{s.kwargs['max_travel_time']:g} s" for s in splits]),
        row(
            "perturbations",
            [perturbations_text(Perturbations.from_value(s.kwargs.get("perturbations"))) for s in splits],
        ),
        row("rules on the same episodes", [", ".join(f"`{r}`" for r in s.rules) or "none" for s in splits]),
    ]
    if exp.task == "fleet":
        out.append(row("guided share", [code(s.kwargs.get("guided_share")) for s in splits]))
    return out


def make_call(exp: Experiment) -> str:
    """How a Python user builds the experiment's world for a split."""
    import evcd

    if exp.task == "fleet":
        return f'`evcd.experiments.parallel_env(experiment="{exp.name}", split=...)`'
    return f'`gymnasium.make("{evcd.ENV_ID}", experiment="{exp.name}", split=...)`'


def overview(experiments: list[Experiment]) -> str:
    """One row per experiment: what sets it apart."""
    out = []
    for e in experiments:
        train, ev = e.splits["train"], e.splits["eval"]
        out.append([f"[`{e.name}`](#experiment-{e.name})", f"`{e.task}`", f"`{e.choices.get('scenario')}`",
                    str(train.kwargs.get("evs")), "-".join(map(clock, train.kwargs["departure_window"])),
                    code(train.kwargs["reward"]), f"{train.episodes:,}",
                    days_list(ev.days)])  # fmt: skip
    header = ["experiment", "task", "scenario", "EVs", "training departures", "reward", "training episodes",
              "evaluation days"]  # fmt: skip
    return table(header, out)


def experiment_markdown(exp: Experiment, conf_dir: Path) -> str:
    """One experiment's section."""
    cfg = exp.cfg
    every = int(cfg.train.validation.every)
    validation = (f"every {every:,} training episodes" if every else "none during training (the tuning days "
                  "serve the runs that chose the settings)")  # fmt: skip
    facts = [
        ["task", f"`{exp.task}`; in Python: {make_call(exp)}"],
        ["regime (`results.json`)", code(cfg.regime)],
        ["learner preset", f"`learner={exp.choices.get('learner')}` (the `learner` block)"],
        ["default agent", f"`{cfg.agent.name}`"],
        ["checkpoints", f"every {int(cfg.train.checkpoint_every):,} training episodes"],
        ["periodic validation", validation],
        ["calibration days (`days.calibration`)", code(list(cfg.days.calibration))],
        ["sweep launcher", f"`hydra/launcher={exp.choices.get('hydra/launcher')}`"],
    ]
    split_rows, same = [], []
    for label, *values in rows(exp, conf_dir):
        if len(set(values)) == 1:
            same.append([label, values[0]])
        else:
            split_rows.append([label, *values])
    out = [f"(experiment-{exp.name})=", f"## `{exp.name}`", "", exp.description, "",
           f"What differs between the splits (`{'`, `'.join(exp.splits)}`):", "",
           table(["", *[f"`{s}`" for s in exp.splits]], split_rows), "",
           "The same in every split, and the run:", "", table(["", "value"], same + facts), ""]  # fmt: skip
    return "\n".join(out)


def markdown(conf_dir: Path) -> str:
    """The generated part of the experiments page."""
    experiments = load_all(conf_dir)
    parts = [overview(experiments), ""]
    parts += [experiment_markdown(e, conf_dir) for e in experiments]
    return "\n".join(parts)
