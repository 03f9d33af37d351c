"""DQN and Dueling Double DQN: one agent class, two switches.

    agent = DQNAgent(n_stations=5, rng=rng, double=True, dueling=True)      # Dueling DDQN
    action = agent.act(obs, explore=True)                                   # epsilon-greedy
    agent.observe(Transition(obs, action, reward, next_obs, terminated, truncated))   # learns

- ``dueling`` picks the network (:mod:`evcd.agents.networks`); ``double`` the target: DQN bootstraps
  from ``max_a Q_target(s', a)``, Double DQN from ``Q_target(s', argmax_a Q_online(s', a))``.
- Replay is prioritized (:mod:`evcd.agents.replay`): priorities ``(|TD error| + eps) ** alpha``,
  importance weights with ``beta`` annealed linearly to 1; ``alpha = 0`` is uniform replay.
- ``terminated`` (the target started charging) cuts the bootstrap; ``truncated`` does not.
- Exploration is epsilon-greedy, epsilon linear from ``epsilon_start`` to ``epsilon_end`` over
  ``exploration_steps`` transitions. ``exploration="slot"`` (the textbook form) draws at every
  decision slot, so an exploring target zig-zags between stations; ``"episode"`` draws once per
  episode, at its first decision: with probability epsilon the whole episode drives to one random
  station (the Random baseline's behaviour), otherwise it follows the network. Exploration draws
  come from the generator handed to :meth:`begin_episode` (the episode's own, so an episode does not
  depend on those run before it); replay sampling from the agent's own generator, drawn from ``rng``
  at construction.
- The network sees ``obs * obs_scale``: the environment's raw ``[D, N, Z]`` (metres, vehicles) is
  scaled to km, tens of vehicles and multiples of the charging points (:meth:`env_kwargs` reads the
  scale off the environment), or left alone if the environment already normalises.

No global random state is touched: the networks are initialised inside ``torch.random.fork_rng``
from a seed drawn from ``rng``. :meth:`state_dict` holds everything a resumed run needs.
"""

from __future__ import annotations

import copy
import logging
import math
import numbers
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812  (torch's convention)

from evcd.agents.base import Agent, Transition
from evcd.agents.networks import check_hidden, make_q_network
from evcd.agents.replay import PrioritizedReplayBuffer
from evcd.checkpoint import CheckpointError, load_checkpoint, to_numpy
from evcd.env.observation import D_SCALE_M, N_SCALE

log = logging.getLogger(__name__)

LOSSES = ("mse", "huber")
EXPLORATIONS = ("slot", "episode")
_UNDRAWN = -1  # episode exploration: not decided yet (None: follow the network; >= 0: that station)
STATE_FORMAT = "evcd.agents.dqn/1"


@dataclass(frozen=True)
class DQNConfig:
    """The agent's hyperparameters (see :class:`DQNAgent` for their meaning); validated on creation."""

    double: bool = False
    dueling: bool = False
    hidden: tuple[int, ...] = (512, 256)
    lr: float = 1e-3
    batch_size: int = 32
    buffer_size: int = 10_000
    gamma: float = 0.99
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
        for key in ("double", "dueling"):
            if not isinstance(getattr(self, key), bool | np.bool_):
                raise ValueError(f"{key}={getattr(self, key)!r}: must be true or false")
        for key in ("batch_size", "buffer_size", "train_freq", "gradient_steps", "target_update"):
            _integer(key, getattr(self, key), 1)
        for key in ("learning_starts", "exploration_steps", "beta_steps"):
            _integer(key, getattr(self, key), 0)
        if self.buffer_size < self.batch_size:
            raise ValueError(f"buffer_size={self.buffer_size} < batch_size={self.batch_size}: the buffer "
                             "must hold at least one batch")  # fmt: skip
        _real("lr", self.lr, low=0.0, low_open=True)
        _real("reward_scale", self.reward_scale, low=0.0, low_open=True)
        _real("priority_eps", self.priority_eps, low=0.0, low_open=True)
        for key in ("gamma", "epsilon_start", "epsilon_end", "alpha", "beta_start"):
            _real(key, getattr(self, key), low=0.0, high=1.0)
        _real("tau", self.tau, low=0.0, high=1.0, low_open=True)
        if self.exploration not in EXPLORATIONS:
            raise ValueError(f"exploration={self.exploration!r}: must be one of {EXPLORATIONS}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss={self.loss!r}: must be one of {LOSSES}")
        if self.max_grad_norm is not None:
            _real("max_grad_norm", self.max_grad_norm, low=0.0, low_open=True)


def _integer(key: str, value: Any, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{key}={value!r}: must be an integer >= {minimum}")


def _real(key: str, value: Any, low: float, high: float = math.inf, low_open: bool = False) -> None:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bounds = f"{'(' if low_open else '['}{low:g}, {high:g}]" if math.isfinite(high) else (
            f"> {low:g}" if low_open else f">= {low:g}")  # fmt: skip
        raise ValueError(f"{key}={value!r}: must be a finite number in {bounds}")


def linear_schedule(start: float, end: float, steps: int, t: int) -> float:
    """``start`` moving linearly to ``end`` over ``steps`` steps, then ``end`` (``steps = 0``: ``end``)."""
    if steps <= 0 or t >= steps:
        return float(end)
    return float(start + (end - start) * t / steps)


def observation_scale(stations: Sequence[Any], normalized: bool) -> np.ndarray:
    """The factor that brings the environment's ``[D, N, Z]`` to km, tens of vehicles and multiples
    of the charging points (ones if the environment normalises already)."""
    m = len(stations)
    if normalized:
        return np.ones(3 * m, dtype=np.float32)
    points = np.array([st.points for st in stations], dtype=np.float64)
    return np.concatenate([np.full(m, 1 / D_SCALE_M), np.full(m, 1 / N_SCALE), 1 / points]).astype(np.float32)


class DQNAgent(Agent):
    """Deep Q-learning dispatcher: DQN, Double DQN, Dueling DQN or Dueling Double DQN.

    Args:
        n_stations: number of stations (actions).
        rng: seeds the networks' initialisation and the agent's replay-sampling generator.
        double: bootstrap with the Double DQN target.
        dueling: use the dueling network.
        hidden: hidden layer sizes of the MLP trunk.
        lr: Adam learning rate.
        batch_size: transitions per gradient step.
        buffer_size: replay capacity (transitions).
        gamma: discount per decision slot.
        learning_starts: transitions stored before the first gradient step.
        train_freq: a round of learning every this many transitions.
        gradient_steps: gradient steps per round.
        target_update: gradient steps between target-network updates.
        tau: target update ``target <- tau * online + (1 - tau) * target``; 1 is a hard copy.
        epsilon_start, epsilon_end, exploration_steps: the epsilon-greedy schedule (transitions).
        exploration: ``"slot"`` (a draw per decision) or ``"episode"`` (a draw per episode; see the
            module docstring).
        alpha: priority exponent (0: uniform replay).
        beta_start, beta_steps: importance-sampling exponent, annealed linearly to 1 (transitions).
        priority_eps: added to ``|TD error|`` so that no priority is zero.
        loss: ``"mse"`` (the paper's) or ``"huber"``; both weighted by the importance weights.
        max_grad_norm: clip the gradient's global norm to this (``None``: no clipping).
        reward_scale: rewards are multiplied by this before learning (the paper's reward reaches
            tens; a scale keeps the regression targets near 1).
        obs_scale: per-feature factor applied to observations (default: none); see
            :func:`observation_scale`, which :meth:`env_kwargs` uses.
        checkpoint: load this checkpoint (a training checkpoint or run directory) after building.
    """

    learns = True

    def __init__(
        self,
        n_stations: int,
        rng: np.random.Generator,
        double: bool = False,
        dueling: bool = False,
        hidden: Sequence[int] = (512, 256),
        lr: float = 1e-3,
        batch_size: int = 32,
        buffer_size: int = 10_000,
        gamma: float = 0.99,
        learning_starts: int = 100,
        train_freq: int = 1,
        gradient_steps: int = 1,
        target_update: int = 8000,
        tau: float = 1.0,
        epsilon_start: float = 1.0,
        epsilon_end: float = 0.1,
        exploration_steps: int = 1000,
        exploration: str = "slot",
        alpha: float = 0.6,
        beta_start: float = 0.4,
        beta_steps: int = 1000,
        priority_eps: float = 1e-6,
        loss: str = "mse",
        max_grad_norm: float | None = 10.0,
        reward_scale: float = 1.0,
        obs_scale: Sequence[float] | np.ndarray | None = None,
        checkpoint: str | Path | None = None,
    ) -> None:
        super().__init__(n_stations, rng)
        self.config = DQNConfig(
            double=double, dueling=dueling, hidden=tuple(hidden) if isinstance(hidden, Sequence) else hidden,
            lr=lr, batch_size=batch_size, buffer_size=buffer_size, gamma=gamma,
            learning_starts=learning_starts, train_freq=train_freq, gradient_steps=gradient_steps,
            target_update=target_update, tau=tau, epsilon_start=epsilon_start, epsilon_end=epsilon_end,
            exploration_steps=exploration_steps, exploration=exploration, alpha=alpha,
            beta_start=beta_start, beta_steps=beta_steps,
            priority_eps=priority_eps, loss=loss, max_grad_norm=max_grad_norm, reward_scale=reward_scale,
        )  # fmt: skip
        obs_dim = 3 * self.n_stations
        scale = np.ones(obs_dim, np.float32) if obs_scale is None else np.asarray(obs_scale, np.float32)
        if scale.shape != (obs_dim,) or not (np.isfinite(scale).all() and (scale > 0).all()):
            raise ValueError(f"obs_scale: need {obs_dim} finite factors > 0 (3 x stations), got {scale!r}")
        self.obs_dim = obs_dim
        self.obs_scale = scale
        cfg = self.config
        init_seed = int(rng.integers(2**63 - 1))
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(init_seed)
            self.online = make_q_network(obs_dim, self.n_stations, cfg.hidden, cfg.dueling)
        self.target = copy.deepcopy(self.online).requires_grad_(False)
        self.optimizer = torch.optim.Adam(self.online.parameters(), lr=cfg.lr)
        self.replay = PrioritizedReplayBuffer(cfg.buffer_size, obs_dim, alpha=cfg.alpha, eps=cfg.priority_eps)
        self.learn_rng = np.random.default_rng(rng.integers(2**63 - 1))
        self.steps = 0  # transitions observed
        self.gradient_steps = 0
        self.target_updates = 0
        self._episode_station: int | None = _UNDRAWN
        self.loss_total = 0.0  # sum of the losses of every gradient step (for logs)
        self.q_total = 0.0  # sum of the batches' mean Q(s, a)
        if checkpoint is not None:
            self.load(checkpoint)

    # ------------------------------------------------------------------ construction helpers
    @property
    def name(self) -> str:  # type: ignore[override]  (derived from the switches)
        """``dqn``, ``ddqn``, ``dueling_dqn`` or ``dueling_ddqn``."""
        return ("dueling_" if self.config.dueling else "") + ("ddqn" if self.config.double else "dqn")

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The observation scale for ``env`` (its stations' charging points, its normalisation)."""
        base = env.unwrapped
        return {"obs_scale": observation_scale(base.stations, base.config.normalize_obs).tolist()}

    def __repr__(self) -> str:
        c = self.config
        return (f"DQNAgent({self.name}, hidden={list(c.hidden)}, lr={c.lr:g}, batch={c.batch_size}, "
                f"buffer={c.buffer_size}, alpha={c.alpha:g}, target_update={c.target_update})")  # fmt: skip

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

    def _input(self, obs: np.ndarray) -> torch.Tensor:
        x = np.asarray(obs, dtype=np.float32)
        if x.shape[-1:] != (self.obs_dim,):
            raise ValueError(f"observation of shape {x.shape}: expected (..., {self.obs_dim}) = [D, N, Z]")
        return torch.from_numpy(x * self.obs_scale)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """The online network's Q-values for one observation ``(m,)`` or a batch ``(k, m)``."""
        with torch.no_grad():
            return self.online(self._input(obs)).numpy()

    def begin_episode(self, rng: np.random.Generator | None = None) -> None:
        """Start an episode: exploration draws come from ``rng`` (the episode's) from now on."""
        super().begin_episode(rng)
        self._episode_station = _UNDRAWN

    def act(self, obs: np.ndarray, explore: bool = False) -> int:
        """Epsilon-greedy if ``explore`` (draws from the episode's generator), else ``argmax Q``."""
        if explore and self.config.exploration == "episode" and self._episode_station not in (_UNDRAWN, None):
            return int(self._episode_station)  # exploring this episode: no forward pass needed
        return self._choose(int(self.q_values(np.asarray(obs)[None, :])[0].argmax()), explore)

    def _choose(self, greedy: int, explore: bool) -> int:
        """The action given the greedy one: the exploration draws of :meth:`act`."""
        if not explore:
            return greedy
        if self.config.exploration == "episode":
            if self._episode_station == _UNDRAWN:  # the episode's first decision: explore it or not
                draw, station = self.rng.random(), int(self.rng.integers(self.n_stations))
                self._episode_station = station if draw < self.epsilon else None
            return greedy if self._episode_station is None else int(self._episode_station)
        draw, station = self.rng.random(), int(self.rng.integers(self.n_stations))
        return station if draw < self.epsilon else greedy

    def act_batch(self, obs: np.ndarray, explore: bool = False) -> np.ndarray:
        """:meth:`act` for a batch of observations ``(k, 3m)`` in one forward pass (slot exploration;
        episode exploration keeps a choice per episode, so it goes through :meth:`act`)."""
        greedy = self.q_values(obs).argmax(axis=-1)
        if not explore:
            return greedy
        if self.config.exploration == "episode":
            raise ValueError("exploration='episode' decides per episode: call act() for each target")
        return np.array([self._choose(int(g), True) for g in greedy], dtype=np.int64)

    def episode_state(self) -> Any:
        """The episode's generator and its exploration draw (episode exploration)."""
        return (self.rng, self._episode_station)

    def set_episode_state(self, state: Any) -> None:
        """Restore :meth:`episode_state`."""
        self.rng, self._episode_station = state

    def act_episodes(
        self, obs: np.ndarray, states: Sequence[Any], explore: bool = False
    ) -> tuple[np.ndarray, list[Any]]:
        """:meth:`act` for ``k`` targets of different episodes with one forward pass (see
        :meth:`evcd.agents.base.Agent.act_episodes`)."""
        greedy = self.q_values(obs).argmax(axis=-1)
        actions, out = [], []
        for g, state in zip(greedy, states, strict=True):
            self.set_episode_state(state)
            actions.append(self._choose(int(g), explore))
            out.append(self.episode_state())
        return np.array(actions, dtype=np.int64), out

    # ------------------------------------------------------------------ learning
    def observe(self, transition: Transition) -> None:
        """Store the transition; every ``train_freq`` transitions after ``learning_starts``, learn."""
        t = transition
        self.replay.add(t.obs, int(t.action), float(t.reward) * self.config.reward_scale, t.next_obs,
                        bool(t.terminated), bool(t.truncated))  # fmt: skip
        self.steps += 1
        c = self.config
        if self.steps >= max(c.learning_starts, 1) and self.steps % c.train_freq == 0:
            for _ in range(c.gradient_steps):
                self.learn()

    def td_targets(
        self, rewards: torch.Tensor, next_obs: torch.Tensor, terminated: torch.Tensor
    ) -> torch.Tensor:
        """``r + gamma * (1 - terminated) * Q_target(s', a*)``: ``a*`` from the online network if
        ``double``, else from the target network itself (the max)."""
        with torch.no_grad():
            next_target = self.target(next_obs)
            if self.config.double:
                best = self.online(next_obs).argmax(dim=1, keepdim=True)
                next_value = next_target.gather(1, best).squeeze(1)
            else:
                next_value = next_target.max(dim=1).values
            return rewards + self.config.gamma * (1.0 - terminated) * next_value

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
        target = self.td_targets(rewards, next_obs, terminated)
        q = self.online(obs).gather(1, actions[:, None]).squeeze(1)
        if c.loss == "mse":
            per_sample = F.mse_loss(q, target, reduction="none")
        else:
            per_sample = F.smooth_l1_loss(q, target, reduction="none")
        loss = (weights * per_sample).mean()
        self.optimizer.zero_grad(set_to_none=True)
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
                if tau >= 1.0:
                    t.copy_(o)
                else:
                    t.lerp_(o, tau)
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
        }

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        """Everything that determines the agent's future: networks, optimizer, replay, counters,
        generators (numpy and torch), and the hyperparameters (checked on load). A snapshot: later
        training does not change it (torch's own ``state_dict`` returns the live tensors)."""
        config = asdict(self.config)
        config["hidden"] = list(config["hidden"])
        return {
            "format": STATE_FORMAT,
            "n_stations": self.n_stations,
            "config": config,
            "obs_scale": torch.from_numpy(self.obs_scale.copy()),
            "online": copy.deepcopy(self.online.state_dict()),
            "target": copy.deepcopy(self.target.state_dict()),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "replay": self.replay.state_dict(),
            "counters": {
                "steps": self.steps,
                "gradient_steps": self.gradient_steps,
                "target_updates": self.target_updates,
                "loss_total": self.loss_total,
                "q_total": self.q_total,
            },
            "rng": self.rng.bit_generator.state,
            "learn_rng": self.learn_rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, state: dict[str, Any], policy_only: bool = False) -> None:
        """Restore :meth:`state_dict` (``policy_only``: just the online and target networks).

        Raises:
            CheckpointError: the state is not a DQN agent's, or was made for another observation
                size, number of stations, network or switch setting (the message names it).
        """
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        if found != STATE_FORMAT:
            raise CheckpointError(f"not a DQN agent state (format {found!r}, expected {STATE_FORMAT!r})")
        saved = state["config"]
        scale = np.asarray(to_numpy(state["obs_scale"]), np.float32)
        if scale.shape != self.obs_scale.shape:
            raise CheckpointError(
                f"the checkpoint was made for observations of size {scale.shape[0]}; this "
                f"environment's are {self.obs_dim} (3 x {self.n_stations} stations)"
            )
        mine = asdict(self.config)
        for key in ("hidden", "dueling", "double"):
            if list(np.atleast_1d(saved[key])) != list(np.atleast_1d(mine[key])):
                raise CheckpointError(f"the checkpoint's agent has {key}={saved[key]!r}; this one has "
                                      f"{key}={mine[key]!r} (use the same agent settings)")  # fmt: skip
        if not np.allclose(scale, self.obs_scale):
            log.warning("the checkpoint's observation scale differs from this environment's; using the "
                        "checkpoint's (the network was trained on it)")  # fmt: skip
            self.obs_scale = scale
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
        counters = state["counters"]
        self.steps = int(counters["steps"])
        self.gradient_steps = int(counters["gradient_steps"])
        self.target_updates = int(counters["target_updates"])
        self.loss_total = float(counters["loss_total"])
        self.q_total = float(counters["q_total"])
        self.rng.bit_generator.state = state["rng"]
        self.learn_rng.bit_generator.state = state["learn_rng"]
        torch.set_rng_state(state["torch_rng"])

    def load(self, path: str | Path) -> None:
        """Load the policy (networks) from a checkpoint written by the trainer (or a run directory)."""
        state = load_checkpoint(path)
        self.load_state_dict(state.get("agent", state), policy_only=True)
        log.info("loaded %s policy from %s", self.name, path)


def checkpoint_agent_config(path: str | Path) -> dict[str, Any]:
    """The network settings (``hidden``, ``double``, ``dueling``) of the agent saved in a checkpoint,
    so that a policy can be rebuilt to load it.

    Raises:
        CheckpointError: the file is not a DQN checkpoint (or is damaged).
    """
    state = load_checkpoint(path)
    agent = state.get("agent", state)
    if not isinstance(agent, dict) or agent.get("format") != STATE_FORMAT:
        raise CheckpointError(f"checkpoint {str(path)!r} does not hold a DQN agent")
    saved = agent["config"]
    return {
        "hidden": tuple(saved["hidden"]),
        "double": bool(saved["double"]),
        "dueling": bool(saved["dueling"]),
    }
