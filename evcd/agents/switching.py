"""A margin against changing an EV's station: keep the station it was sent to unless another one is
estimated to start its charge more than ``margin_s`` seconds sooner.

    keep_station(seconds, current=2, margin_s=60.0)   # -> 2 unless another is > 60 s sooner

A centre that re-decides its EVs at every tick flips an EV between two stations it estimates close,
and each flip is a detour. The fleet rules (:mod:`evcd.agents.fleet_rules`) rank stations by their
estimated seconds; a learner ranks them by Q-value, which under the ``"time"`` reward is a discounted
return of seconds (:func:`evcd.agents.rule_prior.time_return`) and reads back as seconds with
:func:`return_seconds`, so both take their margin in seconds (``switch_margin_s``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from evcd.agents.in_turn import counted_at


def keep_station(seconds: np.ndarray, current: int, margin_s: float, best: int | None = None) -> int:
    """The station to send an EV to: ``best`` (default: the smallest of ``seconds``, ties to the lowest
    index), unless ``current`` (>= 0; -1: none) is estimated within ``margin_s`` seconds of it. A margin of
    0 never keeps (the plain choice); an estimate that is not finite never keeps either."""
    best = int(np.argmin(seconds)) if best is None else int(best)
    if margin_s > 0 and current >= 0 and float(seconds[current]) - float(seconds[best]) <= margin_s:
        return int(current)
    return best


def return_seconds(q: np.ndarray, slot_s: float, gamma: float, reward_scale: float) -> np.ndarray:
    """The seconds to the start of charging whose discounted ``"time"`` return is ``q`` (the inverse of
    :func:`~evcd.agents.rule_prior.time_return`, in numpy): decreasing in ``q``; a return at or below
    the limit of an endless wait (``-slot_s / 3600 x reward_scale / (1 - gamma)``) reads as ``inf``, one
    above 0 as negative seconds. Hours away at ``gamma`` 0.9 the return is within float precision of
    that limit, so the reading there is coarse (as the learner's Q-values themselves are)."""
    q = np.asarray(q, dtype=np.float64)
    per_slot = -slot_s / 3600.0 * reward_scale
    if gamma >= 1.0:
        return q / per_slot * slot_s
    left = 1.0 - q * (1.0 - gamma) / per_slot  # gamma ** slots
    with np.errstate(divide="ignore", invalid="ignore"):
        slots = np.where(left > 0.0, np.log(np.maximum(left, 1e-300)) / np.log(gamma), np.inf)
    return slots * slot_s


def learner_keep(
    margin_s: float, decision_interval: float | None, reward: object, gamma: float, reward_scale: float
) -> Callable[[np.ndarray, int], int] | None:
    """``keep(q, current)`` -> a learner's greedy station given its Q-values ``q`` (``(m,)``) and the
    station the EV is counted at (-1: none): ``current`` stays unless the argmax, read as seconds
    (:func:`return_seconds` with the learner's ``gamma`` and ``reward_scale``), is more than
    ``margin_s`` sooner. ``None`` for a margin of 0 (the argmax).

    Raises:
        ValueError: a margin with another reward than ``"time"`` (its return is not a time), or without
            the environment's ``decision_interval``.
    """
    if not margin_s > 0:
        return None
    if reward != "time":
        raise ValueError(f"switch_margin_s={margin_s!r} with reward={reward!r}: the margin reads Q-values as "
                         "seconds, the return of the 'time' reward (env.reward=time, as in experiment=peak "
                         "and the fleet); set switch_margin_s=0 for another reward")  # fmt: skip
    if decision_interval is None:
        raise ValueError(f"switch_margin_s={margin_s!r} needs the environment's decision_interval (s per "
                         "slot): build the agent for its environment (make_agent_for_env)")  # fmt: skip
    slot_s = float(decision_interval)

    def keep(q: np.ndarray, current: int) -> int:
        seconds = return_seconds(q, slot_s, gamma, reward_scale)
        return keep_station(seconds, current, margin_s, best=int(np.argmax(q)))

    return keep


def greedy_stations(
    q: np.ndarray, d: np.ndarray, episodes: Sequence[Any], keep: Callable[[np.ndarray, int], int] | None
) -> np.ndarray:
    """The greedy station of each row of Q-values ``q`` (``(k, m)``): the argmax, or with ``keep``
    (:func:`learner_keep`) the station each EV is counted at (:func:`~evcd.agents.in_turn.counted_at`
    from its distances ``d`` and its episode's ``station``) kept within the margin."""
    if keep is None:
        return np.asarray(q).argmax(axis=-1)
    current = counted_at(d, episodes)
    return np.array([keep(row, int(c)) for row, c in zip(q, current, strict=True)], dtype=np.int64)
