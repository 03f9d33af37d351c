"""Any policy on an experiment's evaluation episodes, beside evcd's rules, with evcd's statistics.

    from evcd.experiments import evaluate_policy
    report = evaluate_policy(lambda obs: int(obs[:5].argmin()), experiment="peak", episodes=50, seed=0)
    report.summary["policy"].mean_travel_time, report.summary["queue_aware"].mean_travel_time
    report.paired["queue_aware"]["mean_difference"]   # policy - rule on the same episodes (negative: faster)

The policy is a function of one observation (what ``gymnasium.make("evcd/ChargingNav-v1",
experiment=..., split="eval")`` returns: normalised unless ``normalize_obs=False``) to a station
index: a trained network's greedy action, a stable-baselines3 model's ``predict``, a rule of your
own. It plays the first ``episodes`` evaluation episodes of run ``seed`` in the experiment's
evaluation split, the episodes ``scripts/train.py experiment=<name> seed=<seed>`` evaluates on,
and each rule plays the very same episodes: :func:`evcd.loops.evaluate.evaluate` for every one,
with the same summary (mean, median, bootstrap interval, truncations) and the same paired
comparison (:func:`evcd.loops.stats.paired_difference`: the mean difference on the episodes both
ended charging, its bootstrap interval, faster / equal / slower). Episodes are played one at a time
in the single environment (``gymnasium.make``'s), whose travel times differ from the scripts'
batched engine by a few seconds on average.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evcd.agents import Agent, make_agent_for_env
from evcd.agents.base import EpisodeState
from evcd.experiments.make import make_env
from evcd.loops.evaluate import evaluate
from evcd.loops.seeds import bootstrap_rng
from evcd.loops.stats import EvalResult, paired_difference

#: The name the policy's results go under.
POLICY = "policy"


class PolicyAgent(Agent):
    """A function of one observation to a station, as an evcd dispatcher (it never learns).

    Args:
        policy: ``policy(obs) -> station index``.
        n_stations: the stations of the world it plays in.
    """

    name = POLICY

    def __init__(self, policy: Callable[[np.ndarray], int], n_stations: int) -> None:
        super().__init__(n_stations, np.random.default_rng(0))
        self.policy = policy

    def decide(self, obs: np.ndarray, episodes: Sequence[EpisodeState], explore: bool = False) -> np.ndarray:
        """The policy's station for each of ``k`` episodes (``explore`` is ignored).

        Raises:
            ValueError: the policy returned something that is not a station index.
        """
        rows = np.asarray(obs).reshape(len(episodes), -1)
        out = np.empty(len(episodes), dtype=np.int64)
        for i, row in enumerate(rows):
            action = self.policy(row)
            if not isinstance(action, (int, np.integer)) or not 0 <= int(action) < self.n_stations:
                raise ValueError(f"the policy returned {action!r}: it must return a station index in "
                                 f"0..{self.n_stations - 1}")  # fmt: skip
            out[i] = int(action)
        return out


@dataclass(frozen=True)
class PolicyReport:
    """What :func:`evaluate_policy` measured.

    Attributes:
        results: per dispatcher (``"policy"`` and each rule) its evaluation (rows and summary).
        paired: per rule, the policy minus the rule on the same episodes
            (:func:`evcd.loops.stats.paired_difference`).
    """

    results: Mapping[str, EvalResult]
    paired: Mapping[str, Mapping[str, Any]]

    @property
    def summary(self) -> dict[str, Any]:
        """Per dispatcher its :class:`~evcd.loops.stats.EvalSummary`."""
        return {name: result.summary for name, result in self.results.items()}


def evaluate_policy(
    policy: Callable[[np.ndarray], int],
    experiment: str = "peak",
    episodes: int = 50,
    seed: int = 0,
    rules: Sequence[str] = ("queue_aware", "greedy"),
    overrides: Sequence[str] = (),
    progress: bool = False,
    **env_kwargs: Any,
) -> PolicyReport:
    """Play ``policy`` and ``rules`` on the same evaluation episodes of ``experiment`` (module docstring).

    Args:
        policy: ``policy(obs) -> station index``, ``obs`` as ``gymnasium.make`` gives it.
        experiment: a file of ``conf/experiment/`` (a single-target one).
        episodes: evaluation episodes (>= 1).
        seed: the run seed: which episodes, and the bootstrap.
        rules: evcd's rules to play beside it (registered agent names).
        overrides: Hydra overrides of the experiment (``["evs=300"]``).
        progress: a progress bar per dispatcher.
        **env_kwargs: environment arguments (``normalize_obs=False`` for raw units).

    Raises:
        ValueError: an unknown experiment or rule, a fleet experiment, a bad count or seed, or a
            policy that returns no station index.
    """
    env = make_env(experiment, split="eval", run_seed=seed, overrides=overrides, **env_kwargs)
    try:
        agents: dict[str, Agent] = {POLICY: PolicyAgent(policy, len(env.unwrapped.stations))}
        for rule in rules:
            agents[rule] = make_agent_for_env(rule, env.unwrapped, np.random.default_rng(seed))
        results = {name: evaluate(env, agent, episodes, seed, progress=progress)
                   for name, agent in agents.items()}  # fmt: skip
    finally:
        env.close()
    paired = {rule: paired_difference(results[POLICY].rows, results[rule].rows, bootstrap_rng(seed))
              for rule in rules}  # fmt: skip
    return PolicyReport(results, paired)
