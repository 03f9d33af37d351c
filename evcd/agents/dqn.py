"""DQN and Dueling Double DQN: one agent class, two switches.

    agent = DQNAgent(n_stations=5, rng=rng, config=DQNConfig(lr=1e-3), double=True, dueling=True)
    action = agent.act(obs, explore=True)                                   # epsilon-greedy
    agent.observe(Transition(obs, action, reward, next_obs, terminated, truncated))   # learns

- The hyperparameters are one :class:`~evcd.agents.dqn_config.DQNConfig` (the agent takes it whole).
- ``dueling`` picks the network (:mod:`evcd.agents.networks`); ``double`` the target: DQN bootstraps
  from ``max_a Q_target(s', a)``, Double DQN from ``Q_target(s', argmax_a Q_online(s', a))``.
- Replay is prioritized (:mod:`evcd.agents.replay`): priorities ``(|TD error| + eps) ** alpha``,
  importance weights with ``beta`` annealed linearly to 1; ``alpha = 0`` is uniform replay.
- ``terminated`` (the target started charging) cuts the bootstrap; ``truncated`` does not.
- Exploration is epsilon-greedy, epsilon linear from ``epsilon_start`` to ``epsilon_end`` over
  ``exploration_steps`` transitions, per slot or per episode (:class:`DQNEpisode`); its draws come
  from the episode's generator (so an episode does not depend on those run before it), replay
  sampling from the agent's own generator, drawn from ``rng`` at construction.
- On the fleet (``[D, N, Z, H]``), ``in_turn`` decides the EVs of one tick one after the other, each
  seeing the stations chosen before it (:mod:`evcd.agents.in_turn`).
- The network's input is the observation in physical units (m, vehicles) times :attr:`input_scale`:
  km, tens of vehicles and multiples of the charging points for an agent made for an environment
  (``points``), whether that environment normalises its observations or not (``normalized``); a
  checkpoint keeps the scale, so a loaded policy always sees what it was trained on. With
  ``rule_estimate`` the network also reads the rule's estimated seconds to each station's start of
  charging, computed from the observation (:mod:`evcd.agents.rule_input`); with ``rule_prior`` the
  Q-value is that estimate as a return plus the network's output, zero at first (:mod:`evcd.agents.
  rule_prior`).

No global random state is touched: the networks are initialised inside ``torch.random.fork_rng``
from a seed drawn from ``rng``. :meth:`DQNAgent.state_dict` holds everything a resumed run needs.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812  (torch's convention)

from evcd.agents.base import (
    Agent,
    Transition,
    layout_option,
    observation_letters,
    observation_units,
)
from evcd.agents.dqn_config import DQNConfig, linear_schedule
from evcd.agents.dqn_episode import DQNEpisode
from evcd.agents.dqn_state import CHECKED_SETTINGS, STATE_FORMAT, check_policy_state, policy_settings
from evcd.agents.in_turn import hold, learner_tick
from evcd.agents.inputs import input_factor, network_input, observation_divisors
from evcd.agents.networks import make_q_network
from evcd.agents.replay import PrioritizedReplayBuffer
from evcd.agents.rule_input import RuleEstimate
from evcd.agents.rule_prior import prior_network
from evcd.agents.switching import greedy_stations, learner_keep
from evcd.utils.checkpoint import CheckpointError, load_checkpoint, to_numpy
from evcd.utils.validation import check_bool, with_overrides

log = logging.getLogger(__name__)
#: the agent's counters a checkpoint keeps, and their types
_COUNTERS = {"steps": int, "gradient_steps": int, "target_updates": int, "loss_total": float,
             "q_total": float}  # fmt: skip


class DQNAgent(Agent):
    """Deep Q-learning dispatcher: DQN, Double DQN, Dueling DQN or Dueling Double DQN.

    Args:
        n_stations: number of stations (actions).
        rng: seeds the networks' initialisation and the agent's replay-sampling generator.
        config: the hyperparameters (default: :class:`DQNConfig`'s); ``hyperparameters`` given as
            keywords replace fields of it (``DQNAgent(5, rng, lr=1e-3)``).
        double: bootstrap with the Double DQN target.
        dueling: use the dueling network.
        points: each station's charging points (one number for all): the network then sees ``D`` in
            km, ``N`` in tens of vehicles and ``Z`` in multiples of the points. ``None``: it sees the
            observation as given (for environments whose observations are already scaled).
        normalized: whether the environment normalises its observations (``normalize_obs``); the
            network's input is the same either way (needs ``points``).
        obs_blocks: 3 for ``[D, N, Z]``, 4 for the fleet's ``[D, N, Z, H]`` (one network for all its EVs),
            or a layout's letters with the observation options' blocks (e.g. ``"DNZP"``).
        checkpoint: load this checkpoint's policy (a training checkpoint or run directory) after building.
        decision_interval, reward: the environment's slot (s) and reward name, for ``rule_prior``.
    """

    learns = True
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {"double": False, "dueling": False, "checkpoint": None}
    env_options = ("points", "normalized", "obs_blocks", "decision_interval", "reward")
    learner_block = True
    decision_options = ("switch_margin_s",)

    def __init__(
        self,
        n_stations: int,
        rng: np.random.Generator,
        config: DQNConfig | None = None,
        *,
        double: bool = False,
        dueling: bool = False,
        points: int | Sequence[int] | None = None,
        normalized: bool = False,
        obs_blocks: int | str = 3,
        checkpoint: str | Path | None = None,
        decision_interval: float | None = None,
        reward: object = None,
        **hyperparameters: Any,
    ) -> None:
        super().__init__(n_stations, rng)
        self.config = with_overrides("DQNAgent", DQNConfig, config, hyperparameters)
        self.double = check_bool("double", double)
        self.dueling = check_bool("dueling", dueling)
        self.layout = layout_option(obs_blocks)
        self.blocks = len(self.layout)
        self.obs_dim = self.blocks * self.n_stations
        if self.config.in_turn and "H" not in self.layout:
            raise ValueError(f"in_turn=True with observations {self.layout} ({self.blocks} blocks): in_turn "
                             "is the fleet's (task=fleet, [D, N, Z, H]: the EVs of one tick decide one after "
                             "the other); the single environment has one EV (in_turn=false)")  # fmt: skip
        self.normalized = check_bool("normalized", normalized)
        self._divisors = observation_divisors(points, self.n_stations, self.layout, self.normalized)
        m = self.n_stations
        #: one vehicle in the observation's Z and H units (in_turn's corrections)
        self._vehicle = 1.0 / self._divisors[2 * m : 3 * m] if self.normalized else np.ones(m)
        #: physical observation (m, vehicles) -> network input; saved with the networks
        self.input_scale = np.ones(self.obs_dim, np.float32) if points is None else 1.0 / self._divisors
        self._set_input_scale(self.input_scale)
        cfg = self.config
        #: the rule's estimate read beside the observation (rule_estimate), else None
        reads = cfg.rule_estimate or cfg.rule_prior
        self._estimate = RuleEstimate(m, self.layout, points, self.normalized) if reads else None
        net_dim = self.obs_dim + (m if cfg.rule_estimate else 0)
        init_seed = int(rng.integers(2**63 - 1))
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(init_seed)
            self.online = make_q_network(net_dim, self.n_stations, cfg.hidden, self.dueling, cfg.network)
        if cfg.rule_prior:  # the network becomes the correction to the rule's return
            self.online = prior_network(self.online, m, cfg, decision_interval, reward)
        #: keep(q, current) -> the greedy station within switch_margin_s (None: no margin, the argmax)
        self._keep = learner_keep(cfg.switch_margin_s, decision_interval, reward, cfg.gamma, cfg.reward_scale)
        self.target = copy.deepcopy(self.online).requires_grad_(False)
        self.optimizer = torch.optim.Adam(self.online.parameters(), lr=cfg.lr)
        self.replay = PrioritizedReplayBuffer(cfg.buffer_size, self.obs_dim, cfg.alpha, cfg.priority_eps)
        self.learn_rng = np.random.default_rng(rng.integers(2**63 - 1))
        self.steps = 0  # transitions observed
        self.gradient_steps = 0
        self.target_updates = 0
        self.loss_total = 0.0  # sum of the losses of every gradient step (for logs)
        self.q_total = 0.0  # sum of the batches' mean Q(s, a)
        if checkpoint is not None:
            self.load(checkpoint)

    # ------------------------------------------------------------------ construction helpers
    @property
    def name(self) -> str:  # type: ignore[override]  (derived from the switches)
        """``dqn``, ``ddqn``, ``dueling_dqn`` or ``dueling_ddqn``."""
        return ("dueling_" if self.dueling else "") + ("ddqn" if self.double else "dqn")

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The env's charging points, whether it normalises, its observation's blocks, slot and reward
        (``None`` where its config has none: ``rule_prior`` then refuses)."""
        get = lambda key: getattr(env.unwrapped.config, key, None)  # noqa: E731
        return {**observation_units(env), "obs_blocks": observation_letters(env),
                "decision_interval": get("decision_interval"), "reward": get("reward")}  # fmt: skip

    @classmethod
    def option_names(cls) -> list[str]:
        """The declared options (:attr:`options`, :attr:`env_options`, ``config``) and every
        hyperparameter of :class:`DQNConfig` (given as keywords, they replace fields of ``config``)."""
        return [*super().option_names(), *DQNConfig.field_names()]

    @classmethod
    def checkpoint_options(cls, policy: Mapping[str, Any]) -> dict[str, Any]:
        """The network settings (``hidden``, ``network``, ``double``, ``dueling``, ``rule_estimate``) of a
        saved policy and how it decides a fleet tick (``in_turn``).

        Raises:
            CheckpointError: ``policy`` is not a DQN agent's.
        """
        return policy_settings(policy)

    def _set_input_scale(self, scale: np.ndarray) -> None:
        """Take ``scale`` (physical -> network) and derive the factor applied to observations."""
        self.input_scale = np.asarray(scale, np.float32)
        self._obs_to_input = input_factor(self.input_scale, self._divisors, self.normalized)

    def __repr__(self) -> str:
        c = self.config
        switches = ("in_turn", "rule_estimate", "rule_prior")
        turn = "".join(f", {n.replace('_', ' ')}" for n in switches if getattr(c, n))
        turn += f" within {c.rule_prior_bound_s:g} s" if c.rule_prior_bound_s is not None else ""
        turn += " relative" if c.rule_prior_relative else ""
        turn += f", switch margin {c.switch_margin_s:g} s" if c.switch_margin_s > 0 else ""
        return (f"DQNAgent({self.name}, {c.network} {list(c.hidden)}, lr={c.lr:g}, batch={c.batch_size}, "
                f"buffer={c.buffer_size}, alpha={c.alpha:g}, "
                f"target_update={c.target_update}{turn})")  # fmt: skip

    # ------------------------------------------------------------------ acting
    @property
    def epsilon(self) -> float:
        """The exploration rate now (a function of the transitions observed)."""
        c = self.config
        return linear_schedule(c.epsilon_start, c.epsilon_end, c.exploration_steps, self.steps)

    @property
    def beta(self) -> float:
        """The importance-sampling exponent now."""
        return min(1.0, linear_schedule(self.config.beta_start, 1.0, self.config.beta_steps, self.steps))

    @property
    def learning_rate(self) -> float:
        """The learning rate of the next gradient step (``lr``, or its schedule to ``lr_end``)."""
        c = self.config
        return (
            c.lr
            if c.lr_end is None
            else linear_schedule(c.lr, c.lr_end, c.lr_decay_steps, self.gradient_steps)
        )

    def _input(self, obs: np.ndarray) -> torch.Tensor:
        x = network_input(obs, self._obs_to_input, self.blocks)
        return x if self._estimate is None else torch.cat([x, torch.from_numpy(self._estimate(obs))], -1)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """The online network's Q-values for one observation ``(m,)`` or a batch ``(k, m)``."""
        with torch.no_grad():
            return self.online(self._input(obs)).numpy()

    def new_episode(self, rng: np.random.Generator) -> DQNEpisode:
        """An episode whose exploration draws come from ``rng``."""
        return DQNEpisode(rng)

    def decide(self, obs: np.ndarray, episodes: Sequence[DQNEpisode], explore: bool = False) -> np.ndarray:
        """``argmax Q`` of each observation (one forward pass), epsilon-greedy per episode if ``explore``;
        with ``in_turn``, the rows one after the other (:func:`~evcd.agents.in_turn.learner_tick`)."""
        keep = self._keep  # with switch_margin_s: an EV keeps its station within the margin
        if self.config.in_turn:  # the fleet's EVs of one tick one after the other
            choose = lambda j, greedy: self._choose(greedy, episodes[j], explore)  # noqa: E731
            return learner_tick(obs, episodes, self._vehicle, self.q_values, choose, self._push, self.layout,
                                keep)  # fmt: skip
        greedy = greedy_stations(self.q_values(obs), np.asarray(obs)[:, : self.n_stations], episodes, keep)
        pairs = zip(greedy, episodes, strict=True)
        return np.array([self._choose(int(g), episode, explore) for g, episode in pairs], dtype=np.int64)

    def _choose(self, greedy: int, episode: DQNEpisode, explore: bool) -> int:
        """The action given the greedy one (the exploration draws, from the episode's generator), kept as
        the episode's station (where ``switch_margin_s`` and ``in_turn`` count it)."""
        if explore:
            greedy = episode.choose(greedy, self.epsilon, self.n_stations, self.config.exploration)
        episode.station = int(greedy)
        return episode.station

    # ------------------------------------------------------------------ learning
    def observe(self, transition: Transition, episode: DQNEpisode | None = None) -> None:
        """Store the transition of ``episode`` (default: the current one); every ``train_freq``
        transitions after ``learning_starts``, learn.

        With ``n_step`` > 1 a transition is stored once the ``n - 1`` after it are known (or its
        episode ended): its reward becomes the discounted sum of the (up to) ``n`` rewards, its
        next observation the one ``n`` steps on, and its bootstrap is discounted by ``gamma ** n``.
        With ``in_turn`` the transition's observation is the one the EV decided on, and its next
        observation the one it decides on at its next tick (:func:`~evcd.agents.in_turn.hold`).
        """
        c = self.config
        ep = self.episode if episode is None else episode
        if c.in_turn and ep.seen is not None:  # decided in turn: learn from what it decided on
            hold(transition, ep, self._push)
        else:
            self._push(transition, ep)
        self.steps += 1
        if self.steps >= max(c.learning_starts, 1) and self.steps % c.train_freq == 0 and len(self.replay):
            for _ in range(c.gradient_steps):
                self.learn()

    def end_episode(self, episode: DQNEpisode | None = None) -> None:  # type: ignore[override]
        """``episode`` ended. After a last transition nothing is left to store; an episode that ended
        without one (its target could no longer be observed) stores what it holds: with ``in_turn``
        its transition waiting for a next decision (with the next observation it had), and its
        pending n-step windows, each bootstrapping from the last true observation."""
        ep = self.episode if episode is None else episode
        if ep.held is not None:
            held, ep.held = ep.held, None
            self._push(held, ep)
        for window in ep.flush():
            self._store(window)

    def _push(self, transition: Transition, episode: DQNEpisode) -> None:
        """Into the replay, through ``episode``'s n-step window."""
        for window in episode.windows(transition, self.config.n_step):
            self._store(window)

    def _store(self, window: Sequence[Transition]) -> None:
        """Store the first transition of ``window`` with the rewards of the whole window."""
        gamma, first, last = self.config.gamma, window[0], window[-1]
        reward = sum(gamma**k * float(t.reward) for k, t in enumerate(window)) * self.config.reward_scale
        self.replay.add(first.obs, int(first.action), reward, last.next_obs, bool(last.terminated),
                        bool(last.truncated), discount=gamma ** len(window))  # fmt: skip

    def td_targets(
        self, rewards: torch.Tensor, next_obs: torch.Tensor, terminated: torch.Tensor, discounts: torch.Tensor
    ) -> torch.Tensor:
        """``r + discount * (1 - terminated) * Q_target(s', a*)`` (``discount``: ``gamma ** n`` for a
        transition of ``n`` rewards): ``a*`` from the online network if ``double``, else from the
        target network itself (the max)."""
        with torch.no_grad():
            next_target = self.target(next_obs)
            if self.double:
                best = self.online(next_obs).argmax(dim=1, keepdim=True)
                next_value = next_target.gather(1, best).squeeze(1)
            else:
                next_value = next_target.max(dim=1).values
            return rewards + discounts * (1.0 - terminated) * next_value

    def learn(self) -> float:
        """One gradient step on a prioritized batch; returns the loss."""
        c = self.config
        batch = self.replay.sample(c.batch_size, self.learn_rng, self.beta)
        obs = self._input(batch.obs)
        next_obs = self._input(batch.next_obs)
        actions = torch.from_numpy(batch.actions.astype(np.int64))
        rewards = torch.from_numpy(batch.rewards.astype(np.float32))
        terminated = torch.from_numpy(batch.terminated.astype(np.float32))
        weights = torch.from_numpy(batch.weights.astype(np.float32))
        discounts = torch.from_numpy(batch.discounts.astype(np.float32))
        target = self.td_targets(rewards, next_obs, terminated, discounts)
        q = self.online(obs).gather(1, actions[:, None]).squeeze(1)
        per_sample = (F.mse_loss if c.loss == "mse" else F.smooth_l1_loss)(q, target, reduction="none")
        loss = (weights * per_sample).mean()
        self.optimizer.zero_grad(set_to_none=True)
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate
        loss.backward()
        if c.max_grad_norm is not None:
            nn.utils.clip_grad_norm_(self.online.parameters(), c.max_grad_norm)
        self.optimizer.step()
        td = (q - target).detach().numpy().astype(np.float64)
        if not np.isfinite(td).all():
            raise FloatingPointError(
                f"non-finite TD errors after {self.gradient_steps} gradient steps (lr={c.lr:g}): the "
                "network diverged; lower lr or set reward_scale / max_grad_norm"
            )
        self.replay.update_priorities(batch.indices, td)
        self.gradient_steps += 1
        if self.gradient_steps % c.target_update == 0:
            self.update_target()
        value = float(loss.item())
        self.loss_total += value
        self.q_total += float(q.detach().mean().item())
        return value

    def update_target(self) -> None:
        """``target <- tau * online + (1 - tau) * target`` (a copy when ``tau = 1``)."""
        tau = self.config.tau
        with torch.no_grad():
            for t, o in zip(self.target.parameters(), self.online.parameters(), strict=True):
                t.copy_(o) if tau >= 1.0 else t.lerp_(o, tau)
        self.target_updates += 1

    def stats(self) -> dict[str, float]:
        """Counters (transitions, gradient steps, target updates, loss and Q sums) and schedules."""
        return {
            "transitions": float(self.steps),
            "gradient_steps": float(self.gradient_steps),
            "target_updates": float(self.target_updates),
            "loss_total": self.loss_total,
            "q_total": self.q_total,
            "epsilon": self.epsilon,
            "beta": self.beta,
            "lr": self.learning_rate,
        }

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        """Everything that determines the agent's future: networks, optimizer, replay, counters, its
        generators, the input scale and the hyperparameters (checked on load). A snapshot: later
        training does not change it (torch's own ``state_dict`` returns the live tensors)."""
        return {
            **self.policy_state_dict(),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "replay": self.replay.state_dict(),
            "counters": {key: getattr(self, key) for key in _COUNTERS},
            "rng": self.rng.bit_generator.state,
            "learn_rng": self.learn_rng.bit_generator.state,
        }

    def policy_state_dict(self) -> dict[str, Any]:
        """The part of :meth:`state_dict` that ``load_state_dict(..., policy_only=True)`` reads: the
        networks, their input scale and the settings it checks (no optimizer, no replay)."""
        return {
            "format": STATE_FORMAT,
            "n_stations": self.n_stations,
            "config": self._saved_config(),
            "input_scale": torch.from_numpy(self.input_scale.copy()),
            "online": copy.deepcopy(self.online.state_dict()),
            "target": copy.deepcopy(self.target.state_dict()),
        }

    def _saved_config(self) -> dict[str, Any]:
        """The hyperparameters and switches as a checkpoint keeps them."""
        return {**asdict(self.config), "hidden": list(self.config.hidden), "double": self.double,
                "dueling": self.dueling}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any], policy_only: bool = False) -> None:  # type: ignore[override]
        """Restore :meth:`state_dict` (``policy_only``: just the networks and their input scale).

        The checkpoint's input scale replaces this agent's: the network keeps seeing what it was
        trained on, whatever this environment's observation units.

        Raises:
            CheckpointError: the state is not a DQN agent's, or was made for another observation
                size, number of stations, network or switch setting (the message names it).
        """
        mine = {key: self._saved_config()[key] for key in CHECKED_SETTINGS}
        scale = check_policy_state(
            state, self.input_scale, mine, f"layout {self.layout}: {self.blocks} x {self.n_stations} stations"
        )
        if not np.array_equal(scale, self.input_scale):
            log.info("the checkpoint's network reads observations at its own scale (trained with other "
                     "charging points or without scaling); using it")  # fmt: skip
        self._set_input_scale(scale)
        try:
            self.online.load_state_dict(state["online"])
            self.target.load_state_dict(state["target"])
            if policy_only:
                return
            # a copy: torch's Optimizer.load_state_dict keeps the given tensors (Adam's moments), which
            # the caller's state (or another agent loaded from it) would then share with this agent
            self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))
            self.replay.load_state_dict(to_numpy(state["replay"]))
        except (RuntimeError, KeyError, ValueError) as exc:
            raise CheckpointError(f"the checkpoint does not fit this agent: {exc}") from exc
        for key, kind in _COUNTERS.items():
            setattr(self, key, kind(state["counters"][key]))
        self.rng.bit_generator.state = state["rng"]
        self.learn_rng.bit_generator.state = state["learn_rng"]

    def load(self, path: str | Path) -> None:
        """Load the policy (networks) from a checkpoint written by the trainer (or a run directory)."""
        state = load_checkpoint(path)
        self.load_state_dict(state.get("agent", state), policy_only=True)
        log.info("loaded %s policy from %s", self.name, path)
