"""A plain Gymnasium loop in evcd's own world: the README job's (``experiment=peak``), its training
days, with a rule written here (the station with the fewest vehicles per charging point, ties to the
nearest), then the same rule on the held-out days: on ``eval`` the very episodes ``scripts/train.py
experiment=peak seed=0`` evaluates on (their reset seeds: :func:`evcd.loops.seeds.episode_spec`).

    python examples/gymnasium_loop.py --episodes 20
    python examples/gymnasium_loop.py --episodes 2 --override evs=200   # any scripts/train.py setting

Observations come normalised (``D`` km, ``N`` tens of vehicles, ``Z`` vehicles per charging point),
so ``Z`` compares stations of different sizes directly.
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np

import evcd  # noqa: F401  (registers evcd/ChargingNav-v1)
from evcd.loops.seeds import episode_spec

#: The run seed whose evaluation episodes are played (``scripts/train.py seed=0``'s, on ``eval``).
RUN_SEED = 0


def fewest_per_point(obs: np.ndarray, stations: int) -> int:
    """The station with the fewest vehicles per charging point (``Z``), ties to the nearest (``D``)."""
    d, z = obs[:stations], obs[2 * stations : 3 * stations]
    return int(np.lexsort((d, z))[0])


def play(split: str, episodes: int, overrides: list[str]) -> float:
    """Mean travel time (s) of the rule over ``episodes`` episodes of ``split``."""
    env = gymnasium.make("evcd/ChargingNav-v1", experiment="peak", split=split, overrides=overrides)
    stations = int(env.action_space.n)
    times = []
    try:
        for i in range(episodes):
            seed = episode_spec(RUN_SEED, i).reset_seed  # evcd's evaluation episode i of run seed 0
            obs, info = env.reset(seed=seed)
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(fewest_per_point(obs, stations))
                done = terminated or truncated
            if terminated:
                times.append(info["travel_time"])
            print(f"{split} episode {i}: {info['reason']} after {info['travel_time']:.0f} s")
    finally:
        env.close()
    return float(np.mean(times)) if times else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--override", action="append", default=[], help="a Hydra override (repeatable)")
    args = parser.parse_args()
    for split in ("train", "eval"):
        print(f"{split}: mean travel time {play(split, args.episodes, args.override):.1f} s")


if __name__ == "__main__":
    main()
