"""evcd's experiments as data a Python user can load: the worlds of ``conf/experiment/`` per split.

- :mod:`evcd.experiments.make`: :func:`make_env` (what ``gymnasium.make("evcd/ChargingNav-v1",
  experiment=..., split=...)`` makes), :func:`parallel_env` and :func:`env` (the fleet's
  PettingZoo environment, parallel and AEC, by PettingZoo's factory names);
- :func:`make_sweep_env`: the batched engine as a Gymnasium vector environment in an experiment's
  world (:mod:`evcd.env.sweep`); :mod:`evcd.experiments.sb3` puts it behind stable-baselines3's
  ``VecEnv`` (the optional extra ``.[sb3]``);
- :mod:`evcd.experiments.worlds`: a composed experiment -> each split's environment arguments and
  days (what ``scripts/train.py`` builds its environments with);
- :mod:`evcd.experiments.compose`: an experiment composed as the script composes it;
- :mod:`evcd.experiments.schema`: the structured configs Hydra composes against;
- :func:`evaluate_policy`: any policy on an experiment's evaluation episodes beside evcd's rules, with
  evcd's statistics (:mod:`evcd.experiments.policy_eval`; imported on first use: it needs torch,
  which ``gymnasium.make`` does not).
"""

from evcd.experiments.compose import CONF_DIR, compose_experiment, experiment_names
from evcd.experiments.make import env, make_env, make_sweep_env, make_vector_env, parallel_env
from evcd.experiments.worlds import SPLITS, split_days, split_kwargs

__all__ = [
    "CONF_DIR",
    "SPLITS",
    "PolicyReport",
    "compose_experiment",
    "env",
    "evaluate_policy",
    "experiment_names",
    "make_env",
    "make_sweep_env",
    "make_vector_env",
    "parallel_env",
    "split_days",
    "split_kwargs",
]


def __getattr__(name: str) -> object:
    """``evaluate_policy`` and ``PolicyReport``, imported on first use (they pull in the loops and torch)."""
    if name in ("evaluate_policy", "PolicyReport"):
        from evcd.experiments import policy_eval

        return getattr(policy_eval, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
