"""The agent interface shared by the dispatchers: heuristics and learning agents (DQN).

An agent maps the environment's observation ``[D, N, Z]`` (see :mod:`evcd.env.observation`), or the
fleet's ``[D, N, Z, H]`` (:mod:`evcd.env.fleet`), to a station index. It acts in one way,
:meth:`Agent.decide`: the observations of ``k`` episodes due at the same time and each episode's
state (:meth:`Agent.new_episode`: its generator, and what the agent keeps per episode, such as a
station drawn at departure), so that one agent can drive several episodes at once (the batched
engine, or every guided EV of a fleet at one tick) and one network forward pass serves them all. For
one episode at a time, as with a Gymnasium environment:

    agent.begin_episode(rng)              # after env.reset(): a new episode state
    action = agent.act(obs, explore)      # once per decision slot: decide() on that one episode
    agent.observe(Transition(...))        # learning agents only: after every env.step()
    agent.end_episode()                   # learning agents only: after the episode's last step

Every source of randomness is a ``numpy.random.Generator`` handed in (at construction, and per
episode), never the global one, so a run is reproducible from its seed.

What the loops need of an agent is all declared here, with defaults that fit a rule, so that an
agent written outside evcd (registered with :func:`evcd.agents.register_agent` or an entry point)
trains, checkpoints, resumes and is evaluated like evcd's own:

- acting: :meth:`Agent.new_episode`, :meth:`Agent.decide`;
- learning (``learns = True``): :meth:`Agent.observe` on every transition of an episode, then
  :meth:`Agent.end_episode` once it ended (an on-policy learner learns from whole episodes there;
  an episode that ended where its target could no longer be observed gets no last transition);
- checkpoints: :meth:`Agent.state_dict` (everything a resumed run needs) and
  :meth:`Agent.policy_state_dict` (what decides), loaded back exactly by
  :meth:`Agent.load_state_dict`; :meth:`Agent.checkpoint_options` rebuilds an agent that fits a
  saved policy (``scripts/evaluate.py agent.checkpoint=...``);
- logs: :meth:`Agent.stats` (counters for ``results.json``) and :meth:`Agent.scalars` (TensorBoard);
- configuration: :attr:`Agent.options` (its Hydra block ``agent.*``, with defaults),
  :attr:`Agent.env_options` (read off the environment by :meth:`Agent.env_kwargs`), and
  :attr:`Agent.obs_blocks` (the tasks it takes).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np

from evcd.env.observation import BASE_LAYOUTS, check_layout
from evcd.env.transition import Transition
from evcd.utils.validation import check_int

#: The observation layouts, by number of length-``m`` blocks: the single environment's ``[D, N, Z]``
#: (:mod:`evcd.env.observation`) and the fleet's ``[D, N, Z, H]`` (:mod:`evcd.env.fleet`; ``H``: the
#: other guided EVs heading to each station). The observation options (``EnvConfig.observe``) add
#: blocks after these: an agent reads such a vector by its layout letters (:attr:`Agent.layout`).
OBSERVATION_LAYOUTS: dict[int, str] = {3: "[D, N, Z]", 4: "[D, N, Z, H]"}


def check_blocks(blocks: Any, name: str = "blocks") -> int:
    """``blocks`` if it is 3 (``[D, N, Z]``) or 4 (``[D, N, Z, H]``); else ``ValueError`` naming it."""
    if isinstance(blocks, bool) or blocks not in OBSERVATION_LAYOUTS:
        raise ValueError(f"{name}={blocks!r}: must be 3 ([D, N, Z]) or 4 ([D, N, Z, H])")
    return int(blocks)


def layout_option(obs_blocks: Any) -> str:
    """A learner's ``obs_blocks`` option as a layout: 3 (``"DNZ"``), 4 (``"DNZH"``) or block letters
    with the observation options' (e.g. ``"DNZP"``).

    Raises:
        ValueError: naming the value and what is allowed.
    """
    try:
        return check_layout(obs_blocks)
    except ValueError:
        raise ValueError(
            f"obs_blocks={obs_blocks!r}: must be 3 ([D, N, Z]), 4 ([D, N, Z, H]) or a layout's letters "
            "(e.g. 'DNZP', 'DNZHPT': evcd.env.observation.check_layout)"
        ) from None


def split_observation(obs: np.ndarray, n_stations: int, blocks: int | str = 3) -> tuple[np.ndarray, ...]:
    """The length-``n_stations`` parts of an observation vector (or, for a batch ``(k, size)``, of
    each row: arrays ``(k, m)``), in the order of ``blocks``: 3 (``D, N, Z``, the single
    environment), 4 (``D, N, Z, H``, the fleet) or a layout's letters (e.g. ``"DNZP"``,
    :func:`evcd.env.observation.check_layout`).

    Raises:
        ValueError: ``obs`` is not ``(size,)`` or ``(k, size)`` for the layout, or the layout is not one.
    """
    try:
        layout = check_layout(blocks)
    except ValueError:
        raise ValueError(
            f"blocks={blocks!r}: must be 3 ([D, N, Z]), 4 ([D, N, Z, H]) or a layout's letters (e.g. 'DNZP')"
        ) from None
    vec = np.asarray(obs)
    size = len(layout) * n_stations
    if vec.ndim not in (1, 2) or vec.shape[-1] != size:
        named = OBSERVATION_LAYOUTS.get(len(layout)) if layout in BASE_LAYOUTS else f"[{', '.join(layout)}]"
        raise ValueError(
            f"observation of shape {vec.shape}: expected ({size},) = {named} for {n_stations} stations "
            "(or a batch of them)"
        )
    m = n_stations
    return tuple(vec[..., b * m : (b + 1) * m] for b in range(len(layout)))


def observation_blocks(obs: np.ndarray, n_stations: int, accepted: Sequence[int] = (3, 4)) -> int:
    """The number of blocks of ``obs`` (one vector or a batch ``(k, size)``), read off its size: 3 for
    ``[D, N, Z]`` (``3 * n_stations``), 4 for ``[D, N, Z, H]`` (``4 * n_stations``).

    Args:
        obs: an observation or a batch of them.
        n_stations: number of stations ``m``.
        accepted: the block counts allowed (a subset of 3 and 4).

    Raises:
        ValueError: ``obs`` has none of the accepted shapes (the message names them).
    """
    vec = np.asarray(obs)
    accepted = tuple(check_blocks(b) for b in accepted)
    if vec.ndim in (1, 2):
        for blocks in accepted:
            if vec.shape[-1] == blocks * n_stations:
                return blocks
    expected = " or ".join(f"({b * n_stations},) = {OBSERVATION_LAYOUTS[b]}" for b in accepted)
    raise ValueError(
        f"observation of shape {vec.shape}: expected {expected} for {n_stations} stations "
        "(or a batch of them)"
    )


def observation_units(env: Any) -> dict[str, Any]:
    """What an agent needs to read the observations of ``env`` (a :class:`~evcd.env.ChargingNavEnv`,
    wrapped or not) in physical units: each station's charging points and whether the environment
    normalises (:func:`evcd.env.observation.unit_divisors`)."""
    base = env.unwrapped
    return {"points": [st.points for st in base.stations], "normalized": bool(base.config.normalize_obs)}


def observation_layout(env: Any) -> int:
    """The number of length-``m`` blocks of ``env``'s observations: 3 (``[D, N, Z]``), 4 for the fleet's
    ``[D, N, Z, H]``, plus one per observation option (:func:`observation_letters` names them)."""
    return len(observation_letters(env))


def observation_letters(env: Any) -> str:
    """The layout of ``env``'s observations (block letters: ``"DNZ"``, the fleet's ``"DNZH"``, with the
    observation options' blocks after them, e.g. ``"DNZPTF"``): the environment's ``layout``, else read
    off the observation space's size (3 or 4 blocks; ``"DNZ"`` for an object without a space)."""
    layout = getattr(getattr(env, "unwrapped", env), "layout", None)
    if isinstance(layout, str):
        return check_layout(layout)
    space = getattr(env, "observation_space", None)
    if space is None:
        return "DNZ"
    if callable(space):  # PettingZoo: one space per agent, the same for all
        space = space(next(iter(env.possible_agents), None))
    return check_layout(int(space.shape[0]) // len(env.unwrapped.stations))


@dataclass
class EpisodeState:
    """What an agent keeps about one episode: by default only the episode's generator. Agents that
    keep more (a station drawn at departure, an exploration draw) subclass it."""

    rng: np.random.Generator


class Agent(ABC):
    """A dispatcher: picks the station the target drives to, once per decision slot.

    Args:
        n_stations: number of stations ``m`` (the action space is ``Discrete(m)``).
        rng: the agent's random generator (derive it from the run seed); episodes begun without a
            generator of their own draw from it.

    Subclasses set :attr:`name` (the registry key, see :func:`evcd.agents.make_agent`) and implement
    :meth:`decide`; learning agents also override :meth:`observe` (and :meth:`end_episode`) and the
    checkpoint methods. Agents that read the fleet's observation set :attr:`obs_blocks`; agents with
    options declare them in :attr:`options`.
    """

    name: ClassVar[str]
    #: Whether the agent learns from :meth:`observe` (the trainer runs a training phase for it).
    learns: ClassVar[bool] = False
    #: The observation layouts :meth:`decide` accepts, as block counts (:data:`OBSERVATION_LAYOUTS`):
    #: 3, the single environment's ``[D, N, Z]`` (``task=single``); 4, the fleet's ``[D, N, Z, H]``
    #: (``task=fleet``). Which one a call holds is read off its size (:meth:`blocks_of`).
    obs_blocks: ClassVar[tuple[int, ...]] = (3,)
    #: The options a user sets, beyond ``n_stations`` and ``rng``, with their defaults: the agent's
    #: Hydra block ``agent.*`` (where ``conf/agent`` has no file of its name, evcd makes the block
    #: from this) and what :func:`~evcd.agents.make_agent` accepts (:meth:`option_names`).
    options: ClassVar[Mapping[str, Any]] = {}
    #: The constructor arguments :meth:`env_kwargs` reads off an environment (accepted as options too).
    env_options: ClassVar[tuple[str, ...]] = ()
    #: Whether the constructor takes ``config``, the run's ``learner`` block
    #: (:class:`~evcd.agents.dqn.DQNConfig`: the DQN learners' hyperparameters).
    learner_block: ClassVar[bool] = False

    def __init__(self, n_stations: int, rng: np.random.Generator) -> None:
        self.n_stations = check_int("n_stations", n_stations, minimum=1)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng={rng!r}: must be a numpy.random.Generator (derive it from the run seed)")
        self.rng = rng
        #: the layout of the observations it decides on (block letters, e.g. ``"DNZP"``); set from the
        #: environment by :meth:`from_env`; ``None``: read off each observation's size (3 or 4 blocks)
        self.layout: str | None = None
        self.episode = self.new_episode(rng)  # the episode act() decides for

    # ------------------------------------------------------------------ construction
    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """Constructor arguments this agent reads off an environment (beyond ``n_stations``).

        Agents whose behaviour depends on the environment's settings (charging points, observation
        scaling) override this; :func:`evcd.agents.make_agent_for_env` uses it.
        """
        del env
        return {}

    @classmethod
    def option_names(cls) -> list[str]:
        """The options the constructor takes beyond ``n_stations`` and ``rng``, as declared:
        :attr:`options`, :attr:`env_options`, and ``config`` where it takes the ``learner`` block."""
        names = [*cls.options, *(n for n in cls.env_options if n not in cls.options)]
        return [*names, "config"] if cls.learner_block else names

    @classmethod
    def from_env(cls, env: Any, rng: np.random.Generator, **kwargs: Any) -> Self:
        """This agent for ``env`` (its number of stations and :meth:`env_kwargs`), plus ``kwargs``.

        ``env`` is a Gymnasium environment or a PettingZoo one (the fleet: ``action_space(agent)``, the
        same ``Discrete(m)`` for every agent, asked for its first possible agent, or ``None``).
        """
        space = env.action_space
        if callable(space):  # PettingZoo: one space per agent
            space = space(next(iter(env.possible_agents), None))
        agent = cls(int(space.n), rng, **{**cls.env_kwargs(env), **kwargs})
        agent.layout = observation_letters(env)
        return agent

    # ------------------------------------------------------------------ acting
    def blocks_of(self, obs: np.ndarray) -> int:
        """The base layout of ``obs`` (one observation or a batch): 3 (``[D, N, Z]``) or 4 (``[D, N, Z,
        H]``), one of :attr:`obs_blocks`; with :attr:`layout` set, ``obs`` must have its size.

        Raises:
            ValueError: ``obs`` has none of the accepted shapes (the message names them).
        """
        if self.layout is None:
            return observation_blocks(obs, self.n_stations, self.obs_blocks)
        self.parts(obs)  # its size
        blocks = 4 if "H" in self.layout else 3
        if blocks not in self.obs_blocks:
            raise ValueError(
                f"observations of layout {self.layout!r}: {self.name} reads {self.obs_blocks} blocks"
            )
        return blocks

    def parts(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """The blocks of ``obs`` (one observation or a batch) by letter, in the environment's units
        (:attr:`layout`, or the base layout its size says)."""
        layout = self.layout or BASE_LAYOUTS[observation_blocks(obs, self.n_stations, self.obs_blocks) - 3]
        return dict(zip(layout, split_observation(obs, self.n_stations, layout), strict=True))

    def new_episode(self, rng: np.random.Generator) -> EpisodeState:
        """The state of a new episode drawing from ``rng`` (the episode's own generator, so that an
        episode does not depend on the ones played before it)."""
        return EpisodeState(rng)

    @abstractmethod
    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The stations for ``k`` episodes due at the same time.

        Args:
            obs: their observations, shape ``(k, 3m)`` (``[D, N, Z]``) or, for agents whose
                :attr:`obs_blocks` has 4, ``(k, 4m)`` (``[D, N, Z, H]``, the guided EVs of a fleet
                deciding at one tick, in the env's agent order); with the observation options'
                blocks after them where the environment has them (:attr:`layout`).
            episodes: each episode's state (from :meth:`new_episode`), updated in place.
            explore: whether a learning agent may explore (training); rules ignore it.

        Returns:
            ``k`` station indices (int64).
        """

    def begin_episode(self, rng: np.random.Generator | None = None) -> EpisodeState:
        """Start an episode for :meth:`act` (call after every ``env.reset()``), drawing from ``rng``
        (default: the agent's own generator)."""
        self.episode = self.new_episode(self.rng if rng is None else rng)
        return self.episode

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """The station to drive to in the current episode (:meth:`begin_episode`): :meth:`decide` on
        that one episode."""
        return int(self.decide(np.asarray(obs)[None], [self.episode], explore)[0])

    # ------------------------------------------------------------------ learning
    def observe(self, transition: Transition, episode: EpisodeState | None = None) -> None:  # noqa: B027
        """Learning hook, called after every step of ``episode`` (default: the current one) while
        training; the rules ignore it."""

    def end_episode(self, episode: EpisodeState | None = None) -> None:  # noqa: B027
        """Learning hook, called once ``episode`` (default: the current one) ended, after its last
        :meth:`observe`, while training: an on-policy learner completes its rollout here. An episode
        whose target could no longer be observed (it vanished or teleported, was never inserted, or
        SUMO failed: :data:`evcd.env.episode_rules.UNOBSERVED`) ends without a last transition, so
        the transitions observed hold only true next observations. The rules ignore it."""

    def stats(self) -> dict[str, float]:
        """Learning statistics for ``results.json`` and logs (cumulative counters such as
        ``transitions`` and ``gradient_steps``, and current schedules); none here."""
        return {}

    def scalars(self) -> dict[str, float]:
        """TensorBoard scalars by tag (e.g. ``losses/policy``), logged after every training episode
        beside the trainer's own; none here."""
        return {}

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Everything that determines the agent's future (a snapshot: later decisions or learning
        do not change it); a rule's is its generator."""
        return {"format": f"evcd.agent/{self.name}", "rng": self.rng.bit_generator.state}

    def policy_state_dict(self) -> dict[str, Any]:
        """The part of :meth:`state_dict` that decides (a learner's networks, without its optimiser or
        replay), read by ``load_state_dict(..., policy_only=True)``; a rule's has nothing to load."""
        return {"format": f"evcd.agent/{self.name}"}

    def load_state_dict(self, state: Mapping[str, Any], policy_only: bool = False) -> None:
        """Restore :meth:`state_dict` (``policy_only``: just :meth:`policy_state_dict`'s part).

        Raises:
            CheckpointError: ``state`` is not this agent's.
        """
        from evcd.utils.checkpoint import CheckpointError  # torch: only where checkpoints are loaded

        expected = f"evcd.agent/{self.name}"
        if not isinstance(state, Mapping) or state.get("format") != expected:
            found = state.get("format") if isinstance(state, Mapping) else type(state).__name__
            raise CheckpointError(f"the checkpoint holds {found!r}, not a {self.name!r} agent ({expected!r})")
        if not policy_only:
            self.rng.bit_generator.state = state["rng"]

    @classmethod
    def checkpoint_options(cls, policy: Mapping[str, Any]) -> dict[str, Any]:
        """The constructor options a saved :meth:`policy_state_dict` implies (its network's sizes),
        so that an agent built with them loads it; none here.

        Raises:
            CheckpointError: ``policy`` is not a policy of this class.
        """
        del policy
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_stations={self.n_stations})"
