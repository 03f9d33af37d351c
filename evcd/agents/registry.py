"""The agent registry: a name -> an :class:`~evcd.agents.base.Agent` subclass, for evcd's own agents
and for agents other packages bring.

    from evcd.agents import register_agent
    register_agent("my_ppo", MyPPO)                                  # a class, or "mypkg.agents:MyPPO"
    register_agent("my_ppo_wide", MyPPO, defaults={"hidden": (256, 256)})

A package makes its agents known without anyone importing it by hand through an entry point in the
group ``evcd.agents`` (its ``pyproject.toml``); evcd reads the group at the first lookup of a name:

    [project.entry-points."evcd.agents"]
    my_ppo = "mypkg.agents:MyPPO"         # an Agent subclass, registered under the entry point's name
    my_set = "mypkg.agents:register"      # or a function that calls register_agent itself

``scripts/train.py agent=my_ppo`` and ``scripts/evaluate.py agent=my_ppo`` then find it: its Hydra
block (``agent.*``) is its declared :attr:`~evcd.agents.base.Agent.options` (:mod:`evcd.experiments.schema`),
the tasks it takes are the observation layouts it declares (:attr:`~evcd.agents.base.Agent.obs_blocks`:
3 for the single target, 4 for the fleet), and the loops need of it only the methods of
:class:`~evcd.agents.base.Agent`. evcd registers its own learner PPO through its own entry point, the
way an outside package does.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from evcd.agents.base import Agent

log = logging.getLogger(__name__)

#: The entry-point group other packages register agents in.
ENTRY_POINT_GROUP = "evcd.agents"
#: Task -> the observation layout (blocks) an agent must accept to play it.
TASK_BLOCKS: dict[str, int] = {"single": 3, "fleet": 4}


@dataclass
class AgentEntry:
    """One registered name.

    Attributes:
        name: the registry key (``agent=<name>``).
        target: the agent class, or its import path ``"module:Class"`` (imported on first use, so that
            the rules do not pay for torch).
        defaults: the constructor options the name implies (``dueling_ddqn``: both switches on).
    """

    name: str
    target: str | type[Agent]
    defaults: Mapping[str, Any] = field(default_factory=dict)

    def load(self) -> type[Agent]:
        """The agent class.

        Raises:
            ValueError: the import path does not lead to an :class:`Agent` subclass.
        """
        if isinstance(self.target, str):
            module, _, attr = self.target.partition(":")
            self.target = _agent_subclass(getattr(importlib.import_module(module), attr), self.name)
        return self.target


def _agent_subclass(obj: Any, name: str) -> type[Agent]:
    if not (isinstance(obj, type) and issubclass(obj, Agent)):
        raise ValueError(f"agent {name!r}: {obj!r} is not a subclass of evcd.agents.Agent")
    return obj


_REGISTRY: dict[str, AgentEntry] = {}
_entry_points_read = False


def register_agent(
    name: str,
    agent: str | type[Agent],
    *,
    defaults: Mapping[str, Any] | None = None,
    replace: bool = False,
) -> None:
    """Register ``agent`` (an :class:`Agent` subclass or its import path ``"module:Class"``) as
    ``name``, with the constructor ``defaults`` that name implies.

    Raises:
        ValueError: ``name`` is not a lowercase identifier (it names a Hydra option and run folders),
            is registered already (unless ``replace``), or ``agent`` is not an Agent subclass or path.
    """
    if not (isinstance(name, str) and name.isidentifier() and name == name.lower()) or name == "hindsight":
        raise ValueError(f"agent name {name!r}: must be a lowercase Python identifier other than 'hindsight' "
                         "(the bound's name)")  # fmt: skip
    if isinstance(agent, str):
        if agent.count(":") != 1:
            raise ValueError(f"agent {name!r}: {agent!r} must be an import path 'module:Class'")
    else:
        _agent_subclass(agent, name)
    if name in _REGISTRY and not replace:
        raise ValueError(f"agent {name!r} is registered already (as {_REGISTRY[name].target!r}); pass "
                         "replace=True to replace it")  # fmt: skip
    _REGISTRY[name] = AgentEntry(name, agent, dict(defaults or {}))


def unregister_agent(name: str) -> None:
    """Remove ``name`` from the registry (tests, notebooks); ``KeyError`` if it is not there."""
    del _REGISTRY[name]


def load_entry_points() -> None:
    """Register the agents of the ``evcd.agents`` entry points (once per process). An entry point
    that fails to load is reported and skipped: one broken package does not take evcd's own agents
    down."""
    global _entry_points_read
    if _entry_points_read:
        return
    _entry_points_read = True
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        try:
            obj = ep.load()
        except Exception as exc:
            log.warning("entry point %s = %s (group %s) failed to load: %s", ep.name, ep.value,
                        ENTRY_POINT_GROUP, exc)  # fmt: skip
            continue
        try:
            if isinstance(obj, type):
                register_agent(ep.name, _agent_subclass(obj, ep.name))
            elif callable(obj):
                obj()
            else:
                raise ValueError("neither an Agent subclass nor a function that registers agents")
        except ValueError as exc:
            log.warning("entry point %s = %s (group %s) skipped: %s", ep.name, ep.value, ENTRY_POINT_GROUP,
                        exc)  # fmt: skip


def _entry(name: str) -> AgentEntry:
    load_entry_points()
    if name not in _REGISTRY:
        raise ValueError(f"agent {name!r} is unknown; known agents: {', '.join(agent_names())}")
    return _REGISTRY[name]


def agent_class(name: str) -> type[Agent]:
    """The agent class registered as ``name``.

    Raises:
        ValueError: ``name`` is not registered (the message lists the registered names).
    """
    return _entry(name).load()


def agent_defaults(name: str) -> dict[str, Any]:
    """The constructor arguments the name ``name`` implies (e.g. ``dueling_ddqn``: both switches on)."""
    return dict(_entry(name).defaults)


def agent_names(task: str | None = None) -> tuple[str, ...]:
    """The registered names, in registration order; with ``task`` (``"single"`` or ``"fleet"``), those
    whose class reads that task's observation (:data:`TASK_BLOCKS`; imports every class).

    Raises:
        ValueError: an unknown task.
    """
    load_entry_points()
    if task is None:
        return tuple(_REGISTRY)
    if task not in TASK_BLOCKS:
        raise ValueError(f"task={task!r}: must be one of {', '.join(TASK_BLOCKS)}")
    return tuple(n for n, e in _REGISTRY.items() if TASK_BLOCKS[task] in e.load().obs_blocks)


def check_agent_task(name: str, task: str) -> type[Agent]:
    """The class of ``name`` if it takes ``task``.

    Raises:
        ValueError: an unknown name, or an agent that does not read the task's observation (the
            message lists the agents that do).
    """
    if name not in agent_names():
        raise ValueError(f"agent {name!r} is not an agent of task={task}; the agents of task={task}: "
                         f"{', '.join(agent_names(task))}")  # fmt: skip
    cls = agent_class(name)
    if TASK_BLOCKS[task] not in cls.obs_blocks:
        others = {3: "single", 4: "fleet"}
        takes = ", ".join(f"task={others[b]}" for b in cls.obs_blocks)
        raise ValueError(f"agent {name!r} does not take task={task} (it takes {takes}); the agents of "
                         f"task={task}: {', '.join(agent_names(task))}")  # fmt: skip
    return cls


def check_options(cls: type[Agent], name: str, kwargs: Mapping[str, Any]) -> None:
    """Refuse options ``cls`` does not declare (:meth:`~evcd.agents.base.Agent.option_names`).

    Raises:
        ValueError: naming the unknown options and the ones the agent takes.
    """
    params = cls.option_names()
    unknown = sorted(set(kwargs) - set(params))
    if unknown:
        raise ValueError(f"agent {name!r}: unknown options {unknown}; it takes {params or 'none'}")


for _name, _path, _defaults in (
    ("random", "evcd.agents.heuristics:RandomAgent", {}),
    ("greedy", "evcd.agents.heuristics:GreedyAgent", {}),
    ("queue_aware", "evcd.agents.heuristics:QueueAwareAgent", {}),
    ("queue_forecast", "evcd.agents.heuristics:ForecastQueueAgent", {}),
    ("dqn", "evcd.agents.dqn:DQNAgent", {"double": False, "dueling": False}),
    ("dueling_ddqn", "evcd.agents.dqn:DQNAgent", {"double": True, "dueling": True}),
    ("reservation", "evcd.agents.fleet_rules:ReservationAgent", {}),
    ("central", "evcd.agents.fleet_rules:CentralAgent", {}),
    ("planned", "evcd.agents.planned:PlannedAgent", {}),
):
    register_agent(_name, _path, defaults=_defaults)
