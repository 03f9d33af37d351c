"""DQN and Dueling Double DQN: one learner, two switches, read top to bottom.

    agent = DQNAgent(n_stations=5, rng=rng, config=DQNConfig(lr=1e-3), double=True, dueling=True)
    action = agent.act(obs, explore=True)                                   # epsilon-greedy
    agent.observe(Transition(obs, action, reward, next_obs, terminated, truncated))   # learns

1. **Settings**: :class:`DQNConfig`, declared once (Hydra's ``learner`` block is built from it).
2. **Acting**: the policy (:class:`~evcd.agents.q_policy.QPolicy`: the networks and what they read)
   gives each episode's greedy station; while exploring, epsilon-greedy with epsilon linear from
   ``epsilon_start`` to ``epsilon_end`` over ``exploration_steps`` transitions, drawn per slot or once
   per episode (:class:`DQNEpisode`), from the episode's own generator (so an episode does not depend
   on those run before it).
3. **Storing**: each episode keeps an n-step window; a transition is stored once the ``n - 1`` after it
   are known (or its episode ended), its reward the discounted sum of the (up to) ``n`` rewards, its
   next observation the one ``n`` steps on, its bootstrap discounted by ``gamma ** n``. Replay is
   prioritized (:mod:`evcd.agents.replay`): priorities ``(|TD error| + eps) ** alpha``, importance
   weights with ``beta`` annealed linearly to 1; ``alpha = 0`` is uniform replay.
4. **Learning**: every ``train_freq`` transitions after ``learning_starts``, ``gradient_steps`` steps of
   the TD update (:meth:`DQNAgent.learn`): DQN bootstraps from ``max_a Q_target(s', a)``, Double DQN
   from ``Q_target(s', argmax_a Q_online(s', a))``; ``terminated`` (charging started) cuts the
   bootstrap, ``truncated`` does not. The loss (MSE or Huber) is weighted by the importance weights,
   the gradient's norm clipped; the target network follows every ``target_update`` gradient steps
   (a copy, or Polyak averaging with ``tau`` < 1).

No global random state is touched: the networks are initialised from a seed drawn from ``rng``, replay
sampling draws from the agent's own generator, drawn from ``rng`` next. :meth:`DQNAgent.state_dict`
holds everything a resumed run needs.
"""

from __future__ import annotations

import copy
import logging
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812  (torch's convention)

from evcd.agents.base import (
    Agent,
    EpisodeState,
    Transition,
    layout_option,
    observation_letters,
    observation_units,
)
from evcd.agents.networks import NETWORKS, check_hidden
from evcd.agents.q_policy import QPolicy, policy_settings
from evcd.agents.replay import PrioritizedReplayBuffer
from evcd.utils.checkpoint import CheckpointError, load_checkpoint, to_numpy
from evcd.utils.validation import check_bool, check_choice, check_int, check_real, with_overrides

log = logging.getLogger(__name__)

LOSSES = ("mse", "huber")
EXPLORATIONS = ("slot", "episode")


@dataclass(frozen=True)
class DQNConfig:
    """A DQN learner's hyperparameters; validated on creation (``ValueError`` naming the value).

    Attributes:
        hidden: hidden layer sizes of the network's trunk.
        network: ``"mlp"`` (the paper's: one MLP reads the whole observation) or ``"station"`` (one
            trunk shared by the stations scores each from its own features and its index,
            :class:`~evcd.agents.networks.StationQNetwork`).
        lr: Adam learning rate.
        batch_size: transitions per gradient step.
        buffer_size: replay capacity (transitions).
        gamma: discount per decision slot.
        n_step: rewards summed per stored transition (n-step returns; 1: one-step Q-learning).
        learning_starts: transitions stored before the first gradient step.
        train_freq: a round of learning every this many transitions.
        gradient_steps: gradient steps per round.
        target_update: gradient steps between target-network updates.
        tau: target update ``target <- tau * online + (1 - tau) * target``; 1 is a hard copy.
        epsilon_start: exploration rate at the first transition ...
        epsilon_end: ... moving linearly to this ...
        exploration_steps: ... over this many transitions.
        exploration: ``"slot"`` (an epsilon-greedy draw at every decision, the textbook form) or
            ``"episode"`` (one draw per episode: with probability epsilon the whole episode drives to
            one random station, like the Random baseline, instead of zig-zagging).
        alpha: priority exponent of the prioritized replay (0: uniform replay).
        beta_start: importance-sampling exponent at the first transition, annealed linearly to 1 ...
        beta_steps: ... over this many transitions.
        priority_eps: added to ``|TD error|`` so that no priority is zero.
        loss: ``"mse"`` (the paper's) or ``"huber"``; both weighted by the importance weights.
        max_grad_norm: clip the gradient's global norm to this (``None``: no clipping).
        reward_scale: rewards are multiplied by this before learning (the paper's reward reaches
            tens; a scale keeps the regression targets near 1).
    """

    hidden: tuple[int, ...] = (512, 256)
    network: str = "mlp"
    lr: float = 1e-3
    batch_size: int = 32
    buffer_size: int = 10_000
    gamma: float = 0.99
    n_step: int = 1
    learning_starts: int = 100
    train_freq: int = 1
    gradient_steps: int = 1
    target_update: int = 8000
    tau: float = 1.0
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    exploration_steps: int = 1000
    exploration: str = "slot"
    alpha: float = 0.6
    beta_start: float = 0.4
    beta_steps: int = 1000
    priority_eps: float = 1e-6
    loss: str = "mse"
    max_grad_norm: float | None = 10.0
    reward_scale: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", check_hidden(self.hidden))
        for key in ("batch_size", "buffer_size", "train_freq", "gradient_steps", "target_update", "n_step"):
            check_int(key, getattr(self, key), minimum=1)
        for key in ("learning_starts", "exploration_steps", "beta_steps"):
            check_int(key, getattr(self, key), minimum=0)
        if self.buffer_size < self.batch_size:
            raise ValueError(f"buffer_size={self.buffer_size} < batch_size={self.batch_size}: the buffer "
                             "must hold at least one batch")  # fmt: skip
        for key in ("lr", "reward_scale", "priority_eps"):
            check_real(key, getattr(self, key), low=0.0, low_open=True)
        for key in ("gamma", "epsilon_start", "epsilon_end", "alpha", "beta_start"):
            check_real(key, getattr(self, key), low=0.0, high=1.0)
        check_real("tau", self.tau, low=0.0, high=1.0, low_open=True)
        check_choice("network", self.network, NETWORKS)
        check_choice("exploration", self.exploration, EXPLORATIONS)
        check_choice("loss", self.loss, LOSSES)
        if self.max_grad_norm is not None:
            check_real("max_grad_norm", self.max_grad_norm, low=0.0, low_open=True)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """The hyperparameters' names."""
        return tuple(f.name for f in fields(cls))


def linear_schedule(start: float, end: float, steps: int, t: int) -> float:
    """``start`` moving linearly to ``end`` over ``steps`` steps, then ``end`` (``steps = 0``: ``end``)."""
    if steps <= 0 or t >= steps:
        return float(end)
    return float(start + (end - start) * t / steps)


@dataclass
class DQNEpisode(EpisodeState):
    """What a DQN learner keeps per episode: its exploration draw under ``exploration="episode"``
    (made at its first decision while exploring: ``random_station`` is where the whole episode then
    drives, ``None`` to follow the network) and its n-step window of transitions not stored yet."""

    drawn: bool = False
    random_station: int | None = None
    pending: deque[Transition] = field(default_factory=deque)

    def choose(self, greedy: int, epsilon: float, n_stations: int, exploration: str) -> int:
        """The action of an exploring agent given the greedy one: epsilon-greedy per slot
        (``"slot"``), or one draw at the episode's first decision (``"episode"``)."""
        rng = self.rng
        if exploration == "episode":
            if not self.drawn:  # the episode's first decision: explore it or not
                draw, station = rng.random(), int(rng.integers(n_stations))
                self.drawn = True
                self.random_station = station if draw < epsilon else None
            return greedy if self.random_station is None else self.random_station
        draw, station = rng.random(), int(rng.integers(n_stations))
        return station if draw < epsilon else greedy

    def windows(self, transition: Transition, n_step: int) -> list[tuple[Transition, ...]]:
        """Add ``transition`` to the n-step window; return the windows to store now (each stores its
        first transition with the rewards of the whole window): the full one, and once the episode
        ended every one left."""
        if n_step == 1:
            return [(transition,)]
        self.pending.append(transition)
        out = []
        if len(self.pending) == n_step:
            out.append(tuple(self.pending))
            self.pending.popleft()
        if transition.terminated or transition.truncated:  # the episode ended: store what is left
            out += self.flush()
        return out

    def flush(self) -> list[tuple[Transition, ...]]:
        """The windows still pending (each stored bootstrapping from its last true observation)."""
        out = []
        while self.pending:
            out.append(tuple(self.pending))
            self.pending.popleft()
        return out


#: the learner's counters a checkpoint keeps, and their types
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
    """

    learns = True
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {"double": False, "dueling": False, "checkpoint": None}
    env_options = ("points", "normalized", "obs_blocks")
    learner_block = True

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
        **hyperparameters: Any,
    ) -> None:
        super().__init__(n_stations, rng)
        self.config = c = with_overrides("DQNAgent", DQNConfig, config, hyperparameters)
        self.double = check_bool("double", double)
        self.dueling = check_bool("dueling", dueling)
        self.layout = layout_option(obs_blocks)
        normalized = check_bool("normalized", normalized)
        seed = int(rng.integers(2**63 - 1))
        self.policy = QPolicy(self.n_stations, self.layout, c.hidden, c.network, self.dueling, points,
                              normalized, seed)  # fmt: skip
        self.optimizer = torch.optim.Adam(self.policy.online.parameters(), lr=c.lr)
        self.replay = PrioritizedReplayBuffer(c.buffer_size, self.policy.inputs.size, c.alpha, c.priority_eps)
        self.learn_rng = np.random.default_rng(rng.integers(2**63 - 1))
        self.steps = 0  # transitions observed
        self.gradient_steps = 0
        self.target_updates = 0
        self.loss_total = 0.0  # sum of the losses of every gradient step (for logs)
        self.q_total = 0.0  # sum of the batches' mean Q(s, a)
        if checkpoint is not None:
            self.load(checkpoint)

    @property
    def name(self) -> str:  # type: ignore[override]  (derived from the switches)
        """``dqn``, ``ddqn``, ``dueling_dqn`` or ``dueling_ddqn``."""
        return ("dueling_" if self.dueling else "") + ("ddqn" if self.double else "dqn")

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The env's charging points, whether it normalises, and its observation's blocks."""
        return {**observation_units(env), "obs_blocks": observation_letters(env)}

    @classmethod
    def option_names(cls) -> list[str]:
        """The declared options (:attr:`options`, :attr:`env_options`, ``config``) and every
        hyperparameter of :class:`DQNConfig` (given as keywords, they replace fields of ``config``)."""
        return [*super().option_names(), *DQNConfig.field_names()]

    @classmethod
    def checkpoint_options(cls, policy: Mapping[str, Any]) -> dict[str, Any]:
        """The network settings (``hidden``, ``network``, ``double``, ``dueling``) of a saved policy.

        Raises:
            CheckpointError: ``policy`` is not a DQN agent's, or used a setting that left evcd.
        """
        return policy_settings(policy)

    def __repr__(self) -> str:
        c = self.config
        return (f"DQNAgent({self.name}, {c.network} {list(c.hidden)}, lr={c.lr:g}, batch={c.batch_size}, "
                f"buffer={c.buffer_size}, alpha={c.alpha:g}, target_update={c.target_update})")  # fmt: skip

    # ------------------------------------------------------------------ schedules
    @property
    def epsilon(self) -> float:
        """The exploration rate now (a function of the transitions observed)."""
        c = self.config
        return linear_schedule(c.epsilon_start, c.epsilon_end, c.exploration_steps, self.steps)

    @property
    def beta(self) -> float:
        """The importance-sampling exponent now."""
        return min(1.0, linear_schedule(self.config.beta_start, 1.0, self.config.beta_steps, self.steps))

    # ------------------------------------------------------------------ acting
    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """The online network's Q-values for one observation ``(size,)`` or a batch ``(k, size)``."""
        return self.policy.q_values(obs)

    def new_episode(self, rng: np.random.Generator) -> DQNEpisode:
        """An episode whose exploration draws come from ``rng``."""
        return DQNEpisode(rng)

    def decide(self, obs: np.ndarray, episodes: Sequence[DQNEpisode], explore: bool = False) -> np.ndarray:
        """``argmax Q`` of each observation (one forward pass), epsilon-greedy per episode if ``explore``."""
        greedy = self.policy.greedy(obs)
        if not explore:
            return greedy.astype(np.int64)
        c, eps = self.config, self.epsilon
        return np.array([episode.choose(int(g), eps, self.n_stations, c.exploration)
                         for g, episode in zip(greedy, episodes, strict=True)], dtype=np.int64)  # fmt: skip

    # ------------------------------------------------------------------ storing
    def observe(self, transition: Transition, episode: DQNEpisode | None = None) -> None:
        """Store the transition of ``episode`` (default: the current one) through its n-step window;
        every ``train_freq`` transitions after ``learning_starts``, learn."""
        c = self.config
        ep = self.episode if episode is None else episode
        for window in ep.windows(transition, c.n_step):
            self._store(window)
        self.steps += 1
        if self.steps >= max(c.learning_starts, 1) and self.steps % c.train_freq == 0 and len(self.replay):
            for _ in range(c.gradient_steps):
                self.learn()

    def end_episode(self, episode: DQNEpisode | None = None) -> None:  # type: ignore[override]
        """``episode`` ended. After a last transition nothing is left to store; an episode that ended
        without one (its target could no longer be observed) stores its pending n-step windows, each
        bootstrapping from the last true observation."""
        for window in (self.episode if episode is None else episode).flush():
            self._store(window)

    def _store(self, window: Sequence[Transition]) -> None:
        """Store the first transition of ``window`` with the rewards of the whole window."""
        gamma, first, last = self.config.gamma, window[0], window[-1]
        reward = sum(gamma**k * float(t.reward) for k, t in enumerate(window)) * self.config.reward_scale
        self.replay.add(first.obs, int(first.action), reward, last.next_obs, bool(last.terminated),
                        bool(last.truncated), discount=gamma ** len(window))  # fmt: skip

    # ------------------------------------------------------------------ learning
    def td_targets(
        self, rewards: torch.Tensor, next_obs: torch.Tensor, terminated: torch.Tensor, discounts: torch.Tensor
    ) -> torch.Tensor:
        """``r + discount * (1 - terminated) * Q_target(s', a*)`` (``discount``: ``gamma ** n`` for a
        transition of ``n`` rewards): ``a*`` from the online network if ``double``, else from the
        target network itself (the max)."""
        with torch.no_grad():
            next_target = self.policy.target(next_obs)
            if self.double:
                best = self.policy.online(next_obs).argmax(dim=1, keepdim=True)
                next_value = next_target.gather(1, best).squeeze(1)
            else:
                next_value = next_target.max(dim=1).values
            return rewards + discounts * (1.0 - terminated) * next_value

    def learn(self) -> float:
        """One gradient step on a prioritized batch; returns the loss."""
        c, policy = self.config, self.policy
        batch = self.replay.sample(c.batch_size, self.learn_rng, self.beta)
        obs, next_obs = policy.inputs(batch.obs), policy.inputs(batch.next_obs)
        actions = torch.from_numpy(batch.actions.astype(np.int64))
        rewards = torch.from_numpy(batch.rewards.astype(np.float32))
        terminated = torch.from_numpy(batch.terminated.astype(np.float32))
        weights = torch.from_numpy(batch.weights.astype(np.float32))
        discounts = torch.from_numpy(batch.discounts.astype(np.float32))
        target = self.td_targets(rewards, next_obs, terminated, discounts)
        q = policy.online(obs).gather(1, actions[:, None]).squeeze(1)
        per_sample = (F.mse_loss if c.loss == "mse" else F.smooth_l1_loss)(q, target, reduction="none")
        loss = (weights * per_sample).mean()
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if c.max_grad_norm is not None:
            nn.utils.clip_grad_norm_(policy.online.parameters(), c.max_grad_norm)
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
        self.policy.update_target(self.config.tau)
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
            "lr": self.config.lr,
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
        """The part of :meth:`state_dict` that decides (:meth:`QPolicy.state_dict
        <evcd.agents.q_policy.QPolicy.state_dict>`), read by ``load_state_dict(..., policy_only=True)``."""
        return self.policy.state_dict(self._settings())

    def _settings(self) -> dict[str, Any]:
        """The hyperparameters and switches as a checkpoint keeps them."""
        return {**asdict(self.config), "hidden": list(self.config.hidden), "double": self.double,
                "dueling": self.dueling}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any], policy_only: bool = False) -> None:  # type: ignore[override]
        """Restore :meth:`state_dict` (``policy_only``: just the networks and their input scale).

        Raises:
            CheckpointError: the state is not a DQN agent's, or was made for another observation
                size, number of stations or network (the message names it).
        """
        if self.policy.load_state_dict(state, self._settings()):
            log.info("the checkpoint's network reads observations at its own scale (trained with other "
                     "charging points or without scaling); using it")  # fmt: skip
        if policy_only:
            return
        try:
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
