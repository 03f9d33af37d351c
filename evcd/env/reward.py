"""Reward shapes: what one decision slot is worth.

The default, ``"paper"``, is the paper's: 0 at every slot, and ``7200 / T_travel`` when the target
starts charging, ``T_travel`` being the seconds from its departure to the start of charging (queueing
included). A custom reward is any callable taking a :class:`Slot` and returning a float.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

#: Numerator of the paper's reward (s): a two-hour trip is worth 1.
PAPER_SCALE_S = 7200.0


@dataclass(frozen=True)
class Slot:
    """What happened in one decision slot.

    Attributes:
        duration: simulated seconds the slot lasted (shorter than the interval if it ended early).
        elapsed: seconds from the target's departure to the end of the slot.
        started_charging: the target got a charging point in this slot (the episode terminates).
        truncated: the episode ended without charging (teleport, vanished, stuck, time cap, error).
        travel_time: ``T_travel`` (s) when ``started_charging``, else ``None``.
    """

    duration: float
    elapsed: float
    started_charging: bool
    truncated: bool
    travel_time: float | None = None


RewardFn = Callable[[Slot], float]


def paper_reward(slot: Slot) -> float:
    """``7200 / T_travel`` at the start of charging, 0 otherwise (truncation included)."""
    if slot.started_charging and slot.travel_time is not None:
        return PAPER_SCALE_S / max(slot.travel_time, 1e-9)
    return 0.0


def time_reward(slot: Slot) -> float:
    """Minus the slot's duration in hours: the episode's return is ``-T_travel / 3600``."""
    return -slot.duration / 3600.0


REWARDS: dict[str, RewardFn] = {"paper": paper_reward, "time": time_reward}


def reward_fn(reward: str | RewardFn) -> RewardFn:
    """The reward function for a name in :data:`REWARDS` or a callable."""
    if callable(reward):
        return reward
    try:
        return REWARDS[reward]
    except KeyError:
        raise ValueError(f"reward={reward!r}: must be one of {sorted(REWARDS)} or a callable") from None
