"""Settings that left evcd, and the last commit of main that has each.

An option stays in evcd where a shipped experiment uses it or a researcher expects it from a library
of its kind; an exploration that did not pay leaves, and its results stay reproducible from the last
commit that has it (``git checkout <commit>``). A removed setting met anywhere (a command-line
override, the config of a run to resume, a checkpoint's saved settings) is refused in one line that
names it and that commit, before any simulation starts; one found at the value that made it do
nothing (its default then) is dropped, so that old runs and checkpoints that never used it still load.

    check_overrides(["learner.rule_prior=true"])     # ValueError: learner.rule_prior=true: ...
    config = drop_removed(saved_config)             # a saved config without its inert removed keys
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple


class Removed(NamedTuple):
    """A setting that left evcd: its value when it did nothing (its default) and the last commit of
    main that has it."""

    inert: Any
    commit: str


#: The last commit of main with the DQN learner's research switches, the rules' switching margin and
#: the validation of the untrained policy (docs/PERTURBED.md and docs/FLEET.md report their results).
RESEARCH_SWITCHES = "c467250"

#: Every removed setting by its dotted key in ``conf/train.yaml``'s layout.
REMOVED: dict[str, Removed] = {
    "learner.in_turn": Removed(False, RESEARCH_SWITCHES),
    "learner.rule_estimate": Removed(False, RESEARCH_SWITCHES),
    "learner.rule_prior": Removed(False, RESEARCH_SWITCHES),
    "learner.rule_prior_bound_s": Removed(None, RESEARCH_SWITCHES),
    "learner.rule_prior_relative": Removed(False, RESEARCH_SWITCHES),
    "learner.switch_margin_s": Removed(0.0, RESEARCH_SWITCHES),
    "learner.lr_end": Removed(None, RESEARCH_SWITCHES),
    "learner.lr_decay_steps": Removed(10_000, RESEARCH_SWITCHES),
    "agent.switch_margin_s": Removed(0.0, RESEARCH_SWITCHES),
    "train.validation.at_start": Removed(False, RESEARCH_SWITCHES),
}


def removed_message(key: str, value: Any) -> str:
    """The one line that refuses ``key=value``."""
    commit = REMOVED[key].commit
    return (f"{key}={value}: this setting left evcd; commit {commit} is the last that has it "
            f"(git checkout {commit} to use it or reproduce its results)")  # fmt: skip


def check_overrides(overrides: Sequence[str]) -> None:
    """Refuse command-line overrides (``key=value``, ``+key=value``, ``~key``) of a removed setting.

    Raises:
        ValueError: one line naming the first such setting and the last commit that has it.
    """
    for override in overrides:
        key, _, value = str(override).lstrip("+~").partition("=")
        if key in REMOVED:
            raise ValueError(removed_message(key, value))


def drop_removed(config: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``config`` (a nested mapping, its keys dotted below ``prefix``) without the removed settings it
    holds at their inert value.

    Raises:
        ValueError: a removed setting at another value (the run or policy used it): one line naming it
            and the last commit that has it.
    """
    out: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if name in REMOVED:
            if value != REMOVED[name].inert:
                raise ValueError(removed_message(name, value))
            continue
        out[key] = drop_removed(value, f"{name}.") if isinstance(value, Mapping) else value
    return out
