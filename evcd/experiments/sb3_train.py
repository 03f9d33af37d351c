"""stable-baselines3's algorithms trained in an evcd world, and their policies as evcd dispatchers, so
that they are evaluated by evcd's own evaluation beside its learners and rules.

    env = ChargingNavEnv(**split_kwargs(cfg, "train", seed), normalize_obs=True)
    model, report = train_sb3(SB3Settings("ppo", envs=16, timesteps=12_000), env, seed=0)
    policy = SB3Policy.from_env(eval_env, model, label="sb3_ppo")   # an evcd Agent, decides in batch
    evaluate(runner, policy, episodes=50, seed=0)

Training goes through the batched engine as a Gymnasium vector environment
(:class:`~evcd.env.sweep.SweepVectorEnv`: ``envs`` targets on one decision clock per SUMO run of a
training day) behind SB3's ``VecEnv`` (:class:`~evcd.experiments.sb3.SB3VecEnv`); the budget is in
decisions (SB3's ``total_timesteps``: its schedules, e.g. DQN's exploration, are fractions of it).
``scripts/train_sb3.py`` is the command line. Needs the optional extra ``pip install -e ".[sb3]"``.
"""

from __future__ import annotations

import inspect
import io
import logging
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize
from tqdm.auto import tqdm

from evcd.agents.base import Agent, EpisodeState, observation_letters, observation_units
from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.observation import unit_divisors
from evcd.env.sweep import SweepVectorEnv
from evcd.experiments.sb3 import SB3VecEnv
from evcd.utils.atomic import atomic_write_bytes
from evcd.utils.checkpoint import state_sha256
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

#: The algorithms, by the name ``sb3.algo`` takes.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "dqn": DQN}


@dataclass(frozen=True)
class SB3Settings:
    """What to train: ``algo`` (:data:`ALGORITHMS`), ``envs`` targets co-simulated per sweep (SB3's
    ``n_envs``), ``timesteps`` decisions in all, ``params``, the algorithm's own constructor
    arguments (``learning_rate``, ``n_steps``, ...; names checked here, values by SB3), and
    ``normalize_reward``: whether the algorithm learns from rewards scaled by SB3's ``VecNormalize``
    (a running estimate of the return's spread; evcd's ``time`` reward is minus hours per minute-long
    slot, about -0.017, which the defaults of SB3's learning rates were not tuned for). The
    evaluation and every reported number use the world's own travel times."""

    algo: str
    envs: int
    timesteps: int
    params: Mapping[str, Any] = field(default_factory=dict)
    normalize_reward: bool = False

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"sb3.algo={self.algo!r}: must be one of {', '.join(ALGORITHMS)}")
        check_int("sb3.envs", self.envs, minimum=1)
        check_int("sb3.timesteps", self.timesteps, minimum=1)
        reserved = sorted({"env", "seed", "device", "tensorboard_log", "policy"} & set(self.params))
        if reserved:
            raise ValueError(
                f"sb3.params.{reserved[0]}: evcd sets it (the run's world, seed and CPU); "
                "set the algorithm's other arguments there"
            )
        known = set(inspect.signature(ALGORITHMS[self.algo].__init__).parameters) - {"self", "env", "policy"}
        unknown = sorted(set(self.params) - known)
        if unknown:
            raise ValueError(
                f"sb3.params.{unknown[0]}: not an argument of stable-baselines3's "
                f"{ALGORITHMS[self.algo].__name__}; its arguments: {', '.join(sorted(known))}"
            )

    @property
    def label(self) -> str:
        """The dispatcher's name in results and tables: ``sb3_<algo>``."""
        return f"sb3_{self.algo}"


def make_model(settings: SB3Settings, venv: Any, seed: int, tensorboard_dir: Path | None = None) -> Any:
    """The SB3 model of ``settings`` on ``venv`` (an MLP policy, CPU), seeded by ``seed``.

    Raises:
        ValueError: an argument in ``settings.params`` the algorithm does not take, or a bad value.
    """
    cls = ALGORITHMS[settings.algo]
    try:
        return cls(
            "MlpPolicy",
            venv,
            seed=seed,
            device="cpu",
            verbose=0,
            tensorboard_log=None if tensorboard_dir is None else str(tensorboard_dir),
            **dict(settings.params),
        )
    except (TypeError, AssertionError) as exc:  # SB3 reports bad arguments this way
        raise ValueError(f"sb3.params for {settings.algo}: {exc}") from exc


class TrainingProgress(BaseCallback):
    """Counts the episodes SB3 plays (and their travel times), shows a progress bar over decisions,
    and logs the running mean travel time to TensorBoard (``evcd/travel_time``)."""

    def __init__(self, total: int, desc: str, enabled: bool = True, window: int = 100) -> None:
        super().__init__()
        self.total, self.desc, self.enabled, self.window = total, desc, enabled, window
        self.episodes = 0
        self.truncated = 0
        self.travel: list[float] = []
        self._bar: Any = None

    def _on_training_start(self) -> None:
        self._bar = tqdm(
            total=self.total, desc=self.desc, unit="step", mininterval=2, disable=not self.enabled
        )

    def _on_step(self) -> bool:
        dones, infos = self.locals["dones"], self.locals["infos"]
        for i in np.flatnonzero(dones):
            self.episodes += 1
            if infos[i].get("reason") == "charging":
                self.travel.append(float(infos[i]["travel_time"]))
            else:
                self.truncated += 1
        if self.travel:
            recent = float(np.mean(self.travel[-self.window :]))
            self.logger.record("evcd/travel_time", recent)
            self._bar.set_postfix(mean_T=f"{recent:.0f}s", episodes=self.episodes, refresh=False)
        self._bar.update(len(dones))
        return True

    def _on_training_end(self) -> None:
        self._bar.close()


@dataclass(frozen=True)
class TrainingReport:
    """What a training run did, for ``results.json`` (``training``)."""

    algo: str
    timesteps: int
    episodes: int
    truncated: int
    mean_travel_time: float
    wall_s: float
    sweeps: int
    gradient_steps: int
    policy_sha256: str

    def to_dict(self) -> dict[str, Any]:
        """Plain values, with ``transitions`` and ``transitions_per_second`` under evcd's names."""
        out = dict(self.__dict__)
        out["transitions"] = self.timesteps
        out["transitions_per_second"] = self.timesteps / self.wall_s if self.wall_s > 0 else math.nan
        return out


def train_sb3(
    settings: SB3Settings,
    env: ChargingNavEnv,
    seed: int,
    tensorboard_dir: Path | None = None,
    progress: bool = True,
) -> tuple[Any, TrainingReport]:
    """Train ``settings``' algorithm for ``settings.timesteps`` decisions on ``env``'s days and window
    through the sweep vector environment of ``settings.envs`` targets; closes the sweep (and ``env``).

    Args:
        env: the training world (its days and window), normalised observations (what an MLP wants).
        seed: seeds SB3 (torch, numpy, its sampling) and the sweeps (days, origins, departures).

    Raises:
        ValueError: ``env`` does not normalise observations, or a bad SB3 argument.
    """
    if not env.config.normalize_obs:
        raise ValueError("train_sb3 needs normalize_obs=True (SB3's MLP is meant for inputs near 1)")
    sweep = SweepVectorEnv(env, settings.envs)
    venv: Any = SB3VecEnv(sweep)
    if settings.normalize_reward:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=settings.params.get("gamma", 0.99))
    try:
        model = make_model(settings, venv, seed, tensorboard_dir)
        callback = TrainingProgress(settings.timesteps, f"train {settings.label}", progress)
        start = time.perf_counter()
        model.learn(total_timesteps=settings.timesteps, callback=callback, tb_log_name=settings.label)
        wall = time.perf_counter() - start
        sweeps = int(sweep.sweeps)
    finally:
        venv.close()
    report = TrainingReport(
        algo=settings.algo,
        timesteps=int(model.num_timesteps),
        episodes=callback.episodes,
        truncated=callback.truncated,
        mean_travel_time=float(np.mean(callback.travel)) if callback.travel else math.nan,
        wall_s=wall,
        sweeps=sweeps,
        gradient_steps=gradient_steps(model),
        policy_sha256=state_sha256(model.policy.state_dict()),
    )
    return model, report


def gradient_steps(model: Any) -> int:
    """The optimiser steps ``model`` took: SB3's DQN counts them (``_n_updates``); its PPO counts
    epochs, each of ``ceil(rollout / batch_size)`` minibatch steps."""
    updates = int(getattr(model, "_n_updates", 0))
    if isinstance(model, PPO):
        return updates * math.ceil(model.n_steps * model.n_envs / model.batch_size)
    return updates


def save_model(model: Any, path: str | Path) -> Path:
    """Write ``model`` (SB3's zip) to ``path`` atomically; refuse to overwrite.

    Raises:
        FileExistsError: ``path`` exists.
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists: nothing is overwritten")
    buf = io.BytesIO()
    model.save(buf)
    return atomic_write_bytes(path, buf.getvalue())


class SB3Policy(Agent):
    """A trained SB3 model as an evcd dispatcher (:class:`~evcd.agents.Agent`): decides a batch of
    episodes with ``model.predict(..., deterministic=True)`` on the observations normalised as in
    training (:func:`~evcd.env.observation.unit_divisors`), whatever the playing environment's units.
    It does not learn (evcd's trainer only evaluates it).

    Args:
        model: the trained SB3 model (its observations the normalised ``[D, N, Z]`` and the observation
            options' blocks, ``layout``).
        n_stations: the stations of the world it plays in.
        points: each station's charging points (the normalisation of ``Z``).
        normalized: whether the playing environment already normalises its observations.
        label: its name in results (``sb3_ppo``, ``sb3_dqn``).
        layout: the observations' layout (:func:`evcd.env.observation.check_layout`).
    """

    name = "sb3"

    def __init__(
        self,
        model: Any,
        n_stations: int,
        points: Sequence[int],
        normalized: bool,
        label: str,
        rng: np.random.Generator | None = None,
        layout: str = "DNZ",
    ) -> None:
        super().__init__(n_stations, np.random.default_rng(0) if rng is None else rng)
        self.model = model
        self.name = label  # type: ignore[misc]  (an instance's name: the SB3 algorithm it runs)
        self.layout = layout
        self._divisors = None if normalized else unit_divisors(points, layout)

    @classmethod
    def for_env(cls, env: Any, model: Any, label: str) -> SB3Policy:
        """This policy for playing in ``env`` (its stations and observation units)."""
        units = observation_units(env)
        layout = observation_letters(env)
        return cls(model, len(units["points"]), units["points"], units["normalized"], label, layout=layout)

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The model's deterministic stations for ``k`` episodes (``explore`` is ignored)."""
        self.blocks_of(obs)
        x = np.asarray(obs, dtype=np.float64).reshape(len(episodes), -1)
        if self._divisors is not None:
            x = x / self._divisors
        actions, _ = self.model.predict(x.astype(np.float32), deterministic=True)
        return np.asarray(actions, dtype=np.int64).reshape(len(episodes))

    def policy_state_dict(self) -> dict[str, Any]:
        """The SB3 policy's tensors."""
        return {"format": f"evcd.agent/{self.name}", "policy": self.model.policy.state_dict()}
