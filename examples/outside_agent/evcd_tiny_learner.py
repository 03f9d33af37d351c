"""A learner written outside evcd, as another package would write one (numpy only, no evcd internals):
the tests install it through an entry point of the group ``evcd.agents`` and train it with
``scripts/train.py``, on the single target and on the fleet (tests/scripts/test_outside_agent.py).

Each station's score is linear in its own block of features (``D`` in km, ``N`` in tens, ``Z`` and,
on the fleet, ``H`` as given) with one weight vector shared by the stations and a bias per station;
it explores epsilon-greedily with the episode's generator and learns by one-step Q-learning.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from evcd.agents import Agent, EpisodeState, Transition, observation_layout

SCALE = {0: 1e-3, 1: 0.1}  # block -> factor (D: m -> km, N: vehicles -> tens); the others as given


class TinyLearner(Agent):
    """One-step linear Q-learning with shared weights per feature block."""

    name = "tiny"
    learns = True
    obs_blocks = (3, 4)
    options: ClassVar[Mapping[str, Any]] = {"lr": 0.05, "epsilon": 0.3, "gamma": 0.9}
    env_options = ("blocks",)

    def __init__(self, n_stations: int, rng: np.random.Generator, lr: float = 0.05, epsilon: float = 0.3,
                 gamma: float = 0.9, blocks: int = 3) -> None:  # fmt: skip
        super().__init__(n_stations, rng)
        if not 0 < lr <= 1:
            raise ValueError(f"lr={lr!r}: must be in (0, 1]")
        self.lr, self.epsilon, self.gamma, self.blocks = float(lr), float(epsilon), float(gamma), int(blocks)
        self.w = rng.normal(0.0, 0.1, self.blocks)
        self.b = np.zeros(n_stations)
        self.steps = self.updates = self.episodes = 0

    @classmethod
    def env_kwargs(cls, env: Any) -> dict[str, Any]:
        return {"blocks": observation_layout(env)}

    def _features(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64).reshape(*np.shape(obs)[:-1], self.blocks, self.n_stations)
        scale = np.array([SCALE.get(k, 1.0) for k in range(self.blocks)])[:, None]
        return x * scale  # (..., blocks, stations)

    def q(self, obs: np.ndarray) -> np.ndarray:
        return np.einsum("...bs,b->...s", self._features(obs), self.w) + self.b

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        greedy = self.q(obs).argmax(axis=-1)
        out = []
        for g, episode in zip(greedy, episodes, strict=True):
            draw, station = episode.rng.random(), int(episode.rng.integers(self.n_stations))
            out.append(station if explore and draw < self.epsilon else int(g))
        return np.array(out, dtype=np.int64)

    def observe(self, transition: Transition, episode: EpisodeState | None = None) -> None:
        obs, a = transition.obs, int(transition.action)
        target = float(transition.reward)
        if not transition.terminated:
            target += self.gamma * float(self.q(transition.next_obs).max())
        error = target - float(self.q(obs)[a])
        self.w += self.lr * error * self._features(obs)[:, a]
        self.b[a] += self.lr * error
        self.steps += 1
        self.updates += 1

    def end_episode(self, episode: EpisodeState | None = None) -> None:
        self.episodes += 1

    def stats(self) -> dict[str, float]:
        return {"transitions": float(self.steps), "gradient_steps": float(self.updates),
                "episodes": float(self.episodes)}  # fmt: skip

    def scalars(self) -> dict[str, float]:
        return {"charts/tiny_weight_norm": float(np.linalg.norm(self.w))}

    def policy_state_dict(self) -> dict[str, Any]:
        return {"format": "tiny/1", "w": self.w.copy(), "b": self.b.copy()}

    def state_dict(self) -> dict[str, Any]:
        return {**self.policy_state_dict(), "counters": [self.steps, self.updates, self.episodes],
                "rng": self.rng.bit_generator.state}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any], policy_only: bool = False) -> None:
        if state.get("format") != "tiny/1":
            raise ValueError(f"not a tiny learner's state: {state.get('format')!r}")
        self.w, self.b = np.array(state["w"], dtype=np.float64), np.array(state["b"], dtype=np.float64)
        if not policy_only:
            self.steps, self.updates, self.episodes = (int(v) for v in state["counters"])
            self.rng.bit_generator.state = state["rng"]
