"""stable-baselines3's PPO in evcd's own world at evcd's speed: trained on the README job's training
days (``experiment=peak``) through the batched engine (the sweep vector environment,
:mod:`evcd.env.sweep`, behind SB3's ``VecEnv``: :mod:`evcd.experiments.sb3`), evaluated on the very
held-out episodes ``scripts/train.py experiment=peak`` evaluates its learners on, in the single
environment, beside evcd's queue_aware rule on the same episodes.

    pip install -e ".[sb3]"
    python examples/sb3_ppo.py --timesteps 12000 --envs 16          # about the README job's budget
    python examples/sb3_ppo.py --timesteps 64 --episodes 2 --override evs=200   # a quick look

Observations come normalised (``D`` km, ``N`` tens, ``Z`` per charging point), what SB3's MLP wants.
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env

import evcd  # noqa: F401  (registers evcd/ChargingNav-v1)
from evcd.experiments import evaluate_policy, make_sweep_env
from evcd.experiments.sb3 import SB3VecEnv

ENV_ID = "evcd/ChargingNav-v1"


def make(split: str, overrides: list[str]) -> gymnasium.Env:
    """The README job's world, ``split``'s days (``overrides``: ``scripts/train.py`` settings)."""
    return gymnasium.make(ENV_ID, experiment="peak", split=split, overrides=overrides)


def evaluate(model: PPO, overrides: list[str], episodes: int, seed: int) -> tuple[float, float]:
    """Mean travel time (s) of the trained policy and of queue_aware on evaluation episodes
    ``0..episodes-1`` of run ``seed`` (the episodes ``scripts/train.py seed=<seed>`` evaluates on)."""

    def act(obs: np.ndarray) -> int:
        return int(model.predict(obs, deterministic=True)[0])

    report = evaluate_policy(act, "peak", episodes, seed, rules=("queue_aware",), overrides=overrides)
    return report.summary["policy"].mean_travel_time, report.summary["queue_aware"].mean_travel_time


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--timesteps", type=int, default=12_000, help="decisions to train on")
    parser.add_argument("--envs", type=int, default=16, help="targets co-simulated per SUMO run")
    parser.add_argument("--episodes", type=int, default=50, help="held-out evaluation episodes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-steps", type=int, default=128, help="PPO's rollout per environment")
    parser.add_argument("--override", action="append", default=[], help="a Hydra override (repeatable)")
    args = parser.parse_args()

    probe = make("train", args.override)
    check_env(probe.unwrapped)  # SB3's own check of the environment
    probe.close()
    vec = SB3VecEnv(make_sweep_env(args.envs, experiment="peak", split="train", overrides=args.override))
    vec.seed(args.seed)
    model = PPO("MlpPolicy", vec, n_steps=args.n_steps, batch_size=min(64, args.n_steps * args.envs),
                seed=args.seed, verbose=0)  # fmt: skip
    model.learn(total_timesteps=args.timesteps)
    vec.close()
    ppo, rule = evaluate(model, args.override, args.episodes, args.seed)
    print(f"trained {model.num_timesteps} decisions")
    print(f"held-out: sb3 PPO {ppo:.1f} s, queue_aware {rule:.1f} s on the same {args.episodes} episodes")


if __name__ == "__main__":
    main()
