"""The seed streams of a run: everything derives from the run seed, never from what ran before.

Through ``numpy.random.SeedSequence`` spawn keys, an episode depends only on ``(seed, stream, i)``:

- evaluation episode ``i``: ``SeedSequence(seed, spawn_key=(0, i))`` gives the ``env.reset`` seed and
  the generator of the agent's episode (see :func:`episode_spec`);
- the bootstrap: ``spawn_key=(1,)``; the agent's own generator (network initialisation, replay
  sampling): ``spawn_key=(2,)``, the baseline rule's ``(2, 1)``; training episodes: ``spawn_key=(3, i)``,
  a stream disjoint from the evaluation episodes'; the periodic validation's episodes:
  ``spawn_key=(4, i)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from evcd.env.runners.base import EpisodeSpec
from evcd.utils.validation import check_int

#: Spawn keys of the seed streams (see the module docstring).
EVAL_STREAM = 0
BOOTSTRAP_STREAM = 1
AGENT_STREAM = 2
TRAIN_STREAM = 3
VALIDATION_STREAM = 4


def episode_spec(seed: int, episode: int, stream: int = EVAL_STREAM) -> EpisodeSpec:
    """Episode ``episode`` of stream ``stream`` of run ``seed`` (its reset seed and agent seed)."""
    env_ss, agent_ss = np.random.SeedSequence(seed, spawn_key=(stream, episode)).spawn(2)
    reset_seed = int(env_ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))  # fits int64
    return EpisodeSpec(int(episode), reset_seed, agent_ss)


def episode_specs(seed: int, indices: Sequence[int] | range, stream: int = EVAL_STREAM) -> list[EpisodeSpec]:
    """:func:`episode_spec` for each index."""
    return [episode_spec(seed, i, stream) for i in indices]


def episode_seed(seed: int, episode: int, stream: int = EVAL_STREAM) -> tuple[int, np.random.Generator]:
    """The ``env.reset`` seed and the agent's generator of episode ``episode`` of run ``seed``."""
    spec = episode_spec(seed, episode, stream)
    return spec.reset_seed, spec.agent_rng()


def bootstrap_rng(seed: int) -> np.random.Generator:
    """The generator of a run's bootstrap."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(BOOTSTRAP_STREAM,)))


def agent_rng(seed: int) -> np.random.Generator:
    """The generator a run builds its agent with (network initialisation, replay sampling)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(AGENT_STREAM,)))


def baseline_rng(seed: int) -> np.random.Generator:
    """The generator a run builds its baseline rule with."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(AGENT_STREAM, 1)))


def days_of_seed(days: Sequence[int], seed: int, count: int = 1) -> tuple[int, ...]:
    """The held-out days of run ``seed`` when each seed of a sweep has its own (``eval.day_per_seed``):
    the ``count`` consecutive days of ``days`` from index ``seed * count`` on, wrapping round (so seeds
    ``0..len(days) // count - 1`` share no day), each at most once.

    The single target takes one day per seed (its episodes spread over the day); the fleet takes one
    per evaluation episode, since a fleet episode is a whole window of its day.
    """
    check_int("count", count, minimum=1)
    if not days:
        raise ValueError("days: at least one day is needed")
    n = len(days)
    block = [days[(seed * count + j) % n] for j in range(min(count, n))]
    return tuple(dict.fromkeys(block))


def check_seed(seed: object) -> int:
    """``seed`` if it is an integer >= 0 (``ValueError`` naming it otherwise)."""
    return check_int("seed", seed, minimum=0)
