"""The agent registry and the protocol's defaults: entry points of other packages, declared options,
the rules' checkpoints (pure: no SUMO)."""

from __future__ import annotations

import inspect
import logging
from importlib.metadata import EntryPoint

import numpy as np
import pytest

from evcd.agents import (
    Agent,
    agent_class,
    agent_names,
    make_agent,
    register_agent,
    registry,
    unregister_agent,
)
from evcd.agents.heuristics import GreedyAgent, QueueAwareAgent
from evcd.utils.checkpoint import CheckpointError


class Stub(GreedyAgent):
    """A rule of another package (greedy under another name)."""

    name = "stub"


def register_stub_set() -> None:
    """What an entry point naming a function does: register agents itself."""
    register_agent("stub_from_function", Stub, defaults={})


@pytest.fixture
def fresh_entry_points(monkeypatch):
    """The registry as a process sees it before its first lookup, with ``points`` as the entry points."""
    before = dict(registry._REGISTRY)
    monkeypatch.setattr(registry, "_entry_points_read", False)

    def use(points: list[EntryPoint]) -> None:
        monkeypatch.setattr(registry, "entry_points", lambda group: [p for p in points if p.group == group])

    yield use
    registry._REGISTRY.clear()
    registry._REGISTRY.update(before)


def test_entry_points_register_classes_and_call_functions_and_skip_what_is_broken(fresh_entry_points, caplog):
    group = registry.ENTRY_POINT_GROUP
    fresh_entry_points([
        EntryPoint("stub", f"{__name__}:Stub", group),
        EntryPoint("more", f"{__name__}:register_stub_set", group),
        EntryPoint("broken", "a_package_that_is_not_installed:Agent", group),
        EntryPoint("not_agent", "collections:OrderedDict", group),
        EntryPoint("greedy", f"{__name__}:Stub", group),  # a name evcd has: refused, evcd's kept
        EntryPoint("elsewhere", f"{__name__}:Stub", "another.group"),
    ])  # fmt: skip
    with caplog.at_level(logging.WARNING, logger="evcd.agents.registry"):
        names = agent_names()
    assert agent_class("stub") is Stub and agent_class("stub_from_function") is Stub
    assert {"broken", "not_agent", "elsewhere"}.isdisjoint(names) and agent_class("greedy") is GreedyAgent
    assert "broken" in caplog.text and "a_package_that_is_not_installed" in caplog.text
    assert "not_agent" in caplog.text and "registered already" in caplog.text
    assert make_agent("stub", 3, np.random.default_rng(0)).decide(np.zeros((1, 9)), [None]).shape == (1,)
    agent_names()  # read once per process: no second warning
    assert caplog.text.count("failed to load") == 1


def test_every_agent_declares_the_options_its_constructor_takes():
    """The declared options (the Hydra block and the registry's check) are the constructor's named
    parameters, so a declaration cannot drift from the code."""
    for name in agent_names():
        cls = agent_class(name)
        params = [p for p in inspect.signature(cls.__init__).parameters.values()][3:]
        named = {p.name for p in params if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}
        if any(p.kind is p.VAR_KEYWORD for p in params):  # passes options on to its parent
            named |= set(agent_class(name).__mro__[1].option_names())
        declared = set(cls.option_names())
        assert named <= declared, (name, named - declared)
        assert set(cls.options) <= declared


@pytest.mark.parametrize("name", ["random", "greedy", "queue_aware", "reservation", "central"])
def test_a_rule_checkpoints_its_generator(name):
    rule = make_agent(name, 3, np.random.default_rng(5))
    state = rule.state_dict()
    first = rule.rng.random()
    other = make_agent(name, 3, np.random.default_rng(9))
    other.load_state_dict(state)
    assert other.rng.random() == first
    other.load_state_dict(rule.policy_state_dict(), policy_only=True)  # nothing to load: accepted
    assert type(rule).checkpoint_options(rule.policy_state_dict()) == {}
    with pytest.raises(CheckpointError, match="not a 'greedy' agent"):
        make_agent("greedy", 3, np.random.default_rng(0)).load_state_dict({"format": "evcd.dqn/1"})


def test_the_tasks_an_agent_takes_are_the_layouts_it_declares():
    assert set(agent_names("fleet")) - set(agent_names("single")) == {"reservation", "central", "planned"}
    assert {"ppo", "dqn", "dueling_ddqn", "greedy"} <= set(agent_names("single")) & set(agent_names("fleet"))
    with pytest.raises(ValueError, match="task='bus'"):
        agent_names("bus")
    with pytest.raises(ValueError, match=r"'central' does not take task=single \(it takes task=fleet\)"):
        registry.check_agent_task("central", "single")


def test_registering_and_unregistering(monkeypatch):
    register_agent("queue_aware_slow", QueueAwareAgent, defaults={"speed_mps": 5.0})
    try:
        assert make_agent("queue_aware_slow", 3, np.random.default_rng(0)).speed_mps == 5.0
        register_agent("queue_aware_slow", "evcd.agents.heuristics:QueueAwareAgent", replace=True)
        assert make_agent("queue_aware_slow", 3, np.random.default_rng(0)).speed_mps == 10.0
    finally:
        unregister_agent("queue_aware_slow")
    with pytest.raises(ValueError, match="'queue_aware_slow' is unknown"):
        agent_class("queue_aware_slow")
    register_agent("lazy_missing", "no_such_module_anywhere:Agent")
    try:
        with pytest.raises(ModuleNotFoundError):
            agent_class("lazy_missing")
    finally:
        unregister_agent("lazy_missing")
    assert issubclass(agent_class("ppo"), Agent)
