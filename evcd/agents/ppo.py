"""PPO: an on-policy actor-critic learner (clipped objective, GAE, value and entropy terms).

    agent = PPOAgent(n_stations=5, rng=rng, lr=3e-4, rollout_steps=512)
    python scripts/train.py agent=ppo                   # the README regime, batched engine
    python scripts/train.py experiment=fleet agent=ppo  # the fleet: one policy for every guided EV

evcd registers it through its own entry point (``pyproject.toml``, group ``evcd.agents``), the way a
package outside evcd adds an agent, and it uses only the agent protocol of :mod:`evcd.agents.base`:

- :meth:`PPOAgent.decide` samples each episode's station from the policy (its draws from the
  episode's own generator) while exploring, and takes the most probable one otherwise; while
  exploring, each episode's state (:class:`PPOEpisode`) keeps the observation, action, log-probability
  and value estimate of every decision;
- :meth:`PPOAgent.observe` adds each transition's reward; :meth:`PPOAgent.end_episode` turns the
  finished episode into advantages and returns (:func:`~evcd.agents.ppo_loss.gae`, bootstrapping from
  the value of the last true observation unless it terminated) and adds it to the rollout; once the
  rollout holds ``rollout_steps`` transitions, ``epochs`` passes of minibatch gradient steps on the
  clipped loss (:func:`~evcd.agents.ppo_loss.ppo_loss`) follow, and the rollout starts again.

With the batched engine, episodes in flight when an update happens finish under the new policy:
their earlier actions keep the log-probabilities they were drawn with, so the ratio of the next
update measures the change from the policy that acted (as it must); such episodes are at most a
batch of the engine. The network's input is scaled as the DQN learners' is (:mod:`evcd.agents.inputs`).
Every draw is from a generator derived from the run seed (the networks' initialisation in
``torch.random.fork_rng``), and :meth:`PPOAgent.state_dict` holds the rollout, so a resumed run ends
with the weights of an uninterrupted one.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from evcd.agents.base import (
    Agent,
    EpisodeState,
    Transition,
    layout_option,
    observation_letters,
    observation_units,
)
from evcd.agents.inputs import InputScale
from evcd.agents.networks import make_q_network
from evcd.agents.ppo_config import PPOConfig
from evcd.agents.ppo_loss import gae, ppo_loss
from evcd.utils.checkpoint import CheckpointError, to_numpy
from evcd.utils.validation import check_bool, with_overrides

#: The ``format`` of a PPO agent's state.
STATE_FORMAT = "evcd.ppo/1"
#: The rollout's columns (one row per transition).
_COLUMNS = ("obs", "actions", "logp", "advantages", "returns")


@dataclass
class PPOEpisode(EpisodeState):
    """What PPO keeps of an episode while exploring: per decision the observation, the action, its
    log-probability and the value estimate; per transition the (scaled) reward, and the last
    transition's end and next observation."""

    obs: list[np.ndarray] = field(default_factory=list)
    actions: list[int] = field(default_factory=list)
    logp: list[float] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    terminated: bool = False
    last_next_obs: np.ndarray | None = None


class PPOAgent(Agent):
    """The PPO dispatcher (see the module docstring).

    Args:
        n_stations: number of stations (actions).
        rng: seeds the networks' initialisation and the minibatch shuffling.
        config: the hyperparameters (default :class:`PPOConfig`'s); ``hyperparameters`` given as
            keywords replace fields of it.
        points, normalized: the environment's charging points and whether it normalises (the
            network then reads km, tens of vehicles, multiples of the points; read off the env).
        obs_blocks: 3 for ``[D, N, Z]``, 4 for the fleet's ``[D, N, Z, H]``, or a layout's letters with
            the observation options' blocks (e.g. ``"DNZP"``).
        checkpoint: unused here (``scripts/evaluate.py`` loads a policy through the protocol); kept so
            that the agent's Hydra block can carry ``agent.checkpoint``.
    """

    name = "ppo"
    learns = True
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {**asdict(PPOConfig()), "checkpoint": None}
    env_options = ("points", "normalized", "obs_blocks")

    def __init__(
        self,
        n_stations: int,
        rng: np.random.Generator,
        config: PPOConfig | None = None,
        *,
        points: int | Sequence[int] | None = None,
        normalized: bool = False,
        obs_blocks: int | str = 3,
        checkpoint: Any = None,
        **hyperparameters: Any,
    ) -> None:
        super().__init__(n_stations, rng)
        del checkpoint
        self.config = with_overrides("PPOAgent", PPOConfig, config, hyperparameters)
        self.layout = layout_option(obs_blocks)
        self.inputs = InputScale(points, self.n_stations, self.layout, check_bool("normalized", normalized))
        self.obs_dim = self.inputs.size
        c = self.config
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(rng.integers(2**63 - 1)))
            self.actor = make_q_network(self.obs_dim, self.n_stations, c.hidden, False, c.network)
            self.critic = make_q_network(self.obs_dim, 1, c.hidden, False, "mlp")
        self.optimizer = torch.optim.Adam([*self.actor.parameters(), *self.critic.parameters()], lr=c.lr)
        self.learn_rng = np.random.default_rng(rng.integers(2**63 - 1))
        self.rollout: dict[str, list[Any]] = {k: [] for k in _COLUMNS}
        self.steps = 0  # transitions observed
        self.episodes = 0  # episodes ended while learning
        self.updates = 0
        self.gradient_steps = 0
        self.last: dict[str, float] = {}  # the last update's means (losses, KL, clipped share)

    # ------------------------------------------------------------------ construction
    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        """The env's charging points, whether it normalises, and its observation's blocks (3 or 4)."""
        return {**observation_units(env), "obs_blocks": observation_letters(env)}

    @classmethod
    def option_names(cls) -> list[str]:
        """The declared options and ``config``."""
        return [*super().option_names(), "config"]

    @classmethod
    def checkpoint_options(cls, policy: Mapping[str, Any]) -> dict[str, Any]:
        """The network settings (``hidden``, ``network``) of a saved PPO policy.

        Raises:
            CheckpointError: ``policy`` is not a PPO agent's.
        """
        if not isinstance(policy, Mapping) or policy.get("format") != STATE_FORMAT:
            raise CheckpointError("the checkpoint does not hold a PPO agent")
        return {"hidden": tuple(policy["config"]["hidden"]), "network": str(policy["config"]["network"])}

    def __repr__(self) -> str:
        c = self.config
        return (f"PPOAgent({c.network} {list(c.hidden)}, lr={c.lr:g}, rollout={c.rollout_steps}, "
                f"epochs={c.epochs}, minibatch={c.minibatch_size}, clip={c.clip:g})")  # fmt: skip

    # ------------------------------------------------------------------ acting
    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        """The policy's station probabilities for one observation or a batch."""
        with torch.no_grad():
            return torch.softmax(self.actor(self.inputs(obs)), dim=-1).double().numpy()

    def new_episode(self, rng: np.random.Generator) -> PPOEpisode:
        """An episode whose draws come from ``rng``."""
        return PPOEpisode(rng)

    def decide(self, obs: np.ndarray, episodes: Sequence[PPOEpisode], explore: bool = False) -> np.ndarray:
        """The most probable station of each episode, or while exploring one drawn from the policy
        (each episode's draw from its own generator, its decision kept for learning)."""
        batch = np.asarray(obs, dtype=np.float32)
        if batch.ndim != 2 or len(batch) != len(episodes):
            raise ValueError(
                f"observations of shape {batch.shape} for {len(episodes)} episodes: one row each"
            )
        with torch.no_grad():
            x = self.inputs(batch)
            logits = self.actor(x)
            logp_all = torch.log_softmax(logits, dim=-1).double().numpy()
            values = self.critic(x).squeeze(-1).double().numpy() if explore else None
        if not explore:
            return logp_all.argmax(axis=-1).astype(np.int64)
        actions = np.empty(len(episodes), dtype=np.int64)
        for j, episode in enumerate(episodes):
            cdf = np.cumsum(np.exp(logp_all[j]))
            a = min(
                int(np.searchsorted(cdf, episode.rng.random() * cdf[-1], side="right")), self.n_stations - 1
            )
            actions[j] = a
            episode.obs.append(batch[j].copy())
            episode.actions.append(a)
            episode.logp.append(float(logp_all[j, a]))
            episode.values.append(float(values[j]))  # type: ignore[index]
        return actions

    # ------------------------------------------------------------------ learning
    def observe(self, transition: Transition, episode: PPOEpisode | None = None) -> None:  # type: ignore[override]
        """Keep the transition's reward (scaled) and, for the episode's end, its next observation."""
        ep = self.episode if episode is None else episode
        ep.rewards.append(float(transition.reward) * self.config.reward_scale)
        ep.terminated = bool(transition.terminated)
        ep.last_next_obs = np.asarray(transition.next_obs, dtype=np.float32)
        self.steps += 1

    def end_episode(self, episode: PPOEpisode | None = None) -> None:  # type: ignore[override]
        """Add the finished episode's transitions (advantages and returns) to the rollout; update once
        the rollout is full. A decision without a transition (the target could no longer be
        observed after it) is dropped; the episode bootstraps from its last true observation."""
        ep = self.episode if episode is None else episode
        n = len(ep.rewards)
        if n:
            c = self.config
            bootstrap = 0.0
            if not ep.terminated:
                with torch.no_grad():
                    bootstrap = float(self.critic(self.inputs(ep.last_next_obs[None])).squeeze())  # type: ignore[index]
            advantages, returns = gae(np.array(ep.rewards), np.array(ep.values[:n]), bootstrap, c.gamma,
                                      c.gae_lambda)  # fmt: skip
            self.rollout["obs"] += ep.obs[:n]
            self.rollout["actions"] += ep.actions[:n]
            self.rollout["logp"] += ep.logp[:n]
            self.rollout["advantages"] += advantages.tolist()
            self.rollout["returns"] += returns.tolist()
        self.episodes += 1
        ep.obs, ep.actions, ep.logp, ep.values, ep.rewards = [], [], [], [], []
        if len(self.rollout["actions"]) >= self.config.rollout_steps:
            self.update()

    def update(self) -> dict[str, float]:
        """``epochs`` passes of minibatch gradient steps on the rollout, which is then emptied;
        returns the means of the losses, the KL estimate and the clipped share."""
        c = self.config
        obs = self.inputs(np.stack(self.rollout["obs"]))
        actions = torch.tensor(self.rollout["actions"], dtype=torch.int64)
        old_logp = torch.tensor(self.rollout["logp"], dtype=torch.float32)
        advantages = torch.tensor(self.rollout["advantages"], dtype=torch.float32)
        returns = torch.tensor(self.rollout["returns"], dtype=torch.float32)
        n = len(actions)
        sums: dict[str, float] = {}
        steps = 0
        params = [*self.actor.parameters(), *self.critic.parameters()]
        for _ in range(c.epochs):
            order = torch.from_numpy(self.learn_rng.permutation(n))
            for start in range(0, n, c.minibatch_size):
                idx = order[start : start + c.minibatch_size]
                adv = advantages[idx]
                if c.normalize_advantages and len(idx) > 1:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                dist = torch.distributions.Categorical(logits=self.actor(obs[idx]))
                values = self.critic(obs[idx]).squeeze(-1)
                terms = ppo_loss(dist.log_prob(actions[idx]), old_logp[idx], adv, values, returns[idx],
                                 dist.entropy(), clip=c.clip, value_coef=c.value_coef,
                                 entropy_coef=c.entropy_coef)  # fmt: skip
                self.optimizer.zero_grad(set_to_none=True)
                terms.total.backward()
                nn.utils.clip_grad_norm_(params, c.max_grad_norm)
                if not torch.isfinite(terms.total):
                    raise FloatingPointError(f"non-finite PPO loss after {self.gradient_steps} gradient "
                                             f"steps (lr={c.lr:g}): lower lr or reward_scale")  # fmt: skip
                self.optimizer.step()
                for key in ("policy", "value", "entropy", "approx_kl", "clip_fraction"):
                    sums[key] = sums.get(key, 0.0) + getattr(terms, key)
                steps += 1
        self.gradient_steps += steps
        self.updates += 1
        self.rollout = {k: [] for k in _COLUMNS}
        self.last = {k: v / steps for k, v in sums.items()}
        return dict(self.last)

    def stats(self) -> dict[str, float]:
        """Counters: transitions, episodes, updates, gradient steps; the rollout's fill."""
        return {
            "transitions": float(self.steps),
            "episodes": float(self.episodes),
            "updates": float(self.updates),
            "gradient_steps": float(self.gradient_steps),
            "rollout": float(len(self.rollout["actions"])),
        }

    def scalars(self) -> dict[str, float]:
        """The last update's means: ``losses/policy``, ``losses/value``, ``losses/entropy``,
        ``charts/approx_kl``, ``charts/clip_fraction``."""
        tags = {"policy": "losses/policy", "value": "losses/value", "entropy": "losses/entropy",
                "approx_kl": "charts/approx_kl", "clip_fraction": "charts/clip_fraction"}  # fmt: skip
        return {tags[k]: v for k, v in self.last.items()}

    # ------------------------------------------------------------------ state
    def policy_state_dict(self) -> dict[str, Any]:
        """The networks, their input scale and the settings a loaded policy is checked against."""
        config = asdict(self.config)
        config["hidden"] = list(config["hidden"])
        return {
            "format": STATE_FORMAT,
            "n_stations": self.n_stations,
            "obs_dim": self.obs_dim,
            "config": config,
            "input_scale": torch.from_numpy(self.inputs.scale.copy()),
            "actor": copy.deepcopy(self.actor.state_dict()),
            "critic": copy.deepcopy(self.critic.state_dict()),
        }

    def state_dict(self) -> dict[str, Any]:
        """Everything a resumed run needs: :meth:`policy_state_dict`, the optimiser, the rollout
        gathered so far, the counters and both generators (a snapshot)."""
        rollout = {k: np.asarray(v, dtype=np.float32 if k != "actions" else np.int64) for k, v in
                   self.rollout.items() if k != "obs"}  # fmt: skip
        rollout["obs"] = np.asarray(self.rollout["obs"], np.float32).reshape(-1, self.obs_dim)
        return {
            **self.policy_state_dict(),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "rollout": rollout,
            "counters": {
                "steps": self.steps,
                "episodes": self.episodes,
                "updates": self.updates,
                "gradient_steps": self.gradient_steps,
                "last": dict(self.last),
            },
            "rng": self.rng.bit_generator.state,
            "learn_rng": self.learn_rng.bit_generator.state,
        }

    def load_state_dict(self, state: Mapping[str, Any], policy_only: bool = False) -> None:
        """Restore :meth:`state_dict` (``policy_only``: the networks and their input scale).

        Raises:
            CheckpointError: not a PPO agent's state, or made for another observation size or network.
        """
        if not isinstance(state, Mapping) or state.get("format") != STATE_FORMAT:
            found = state.get("format") if isinstance(state, Mapping) else type(state).__name__
            raise CheckpointError(f"the checkpoint holds {found!r}, not a PPO agent ({STATE_FORMAT!r})")
        saved = state["config"]
        mine = {"hidden": list(self.config.hidden), "network": self.config.network}
        theirs = {"hidden": list(saved["hidden"]), "network": saved["network"]}
        if (state["n_stations"], state["obs_dim"], theirs) != (self.n_stations, self.obs_dim, mine):
            raise CheckpointError(f"the checkpoint's PPO policy ({state['n_stations']} stations, "
                                  f"observation {state['obs_dim']}, {theirs}) does not fit this agent "
                                  f"({self.n_stations}, {self.obs_dim} = layout {self.layout}, {mine}; the "
                                  "observation options, env.observe, add blocks)")  # fmt: skip
        try:
            self.actor.load_state_dict(state["actor"])
            self.critic.load_state_dict(state["critic"])
        except (RuntimeError, KeyError) as exc:
            raise CheckpointError(f"the checkpoint does not fit this agent: {exc}") from exc
        self.inputs.set(to_numpy(state["input_scale"]))
        if policy_only:
            return
        self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))
        rollout = to_numpy(state["rollout"])
        self.rollout = {k: [row.copy() for row in rollout[k]] if k == "obs" else rollout[k].tolist()
                        for k in _COLUMNS}  # fmt: skip
        counters = state["counters"]
        self.steps, self.episodes = int(counters["steps"]), int(counters["episodes"])
        self.updates, self.gradient_steps = int(counters["updates"]), int(counters["gradient_steps"])
        self.last = {k: float(v) for k, v in counters["last"].items()}
        self.rng.bit_generator.state = state["rng"]
        self.learn_rng.bit_generator.state = state["learn_rng"]
