"""What a network reads: an observation in physical units (m, vehicles) scaled to km, tens of
vehicles and multiples of the charging points, whatever units the environment hands out.

    divisors = observation_divisors(points, n_stations, blocks, normalized)   # env units -> physical
    factor = input_factor(input_scale, divisors, normalized)                  # env units -> network
    x = network_input(obs, factor, blocks)

A learner keeps ``input_scale`` (physical -> network) with its networks in a checkpoint, so a loaded
policy sees what it was trained on in any environment; the DQN and PPO learners share this.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from evcd.env.observation import check_layout, unit_divisors


def observation_divisors(
    points: int | Sequence[int] | None, n_stations: int, blocks: int | str, normalized: bool
) -> np.ndarray:
    """What the environment's observation units are worth in physical ones (float64, one per entry of
    a vector of layout ``blocks``: 3, 4 or its letters, :func:`~evcd.env.observation.check_layout`):
    :func:`~evcd.env.observation.unit_divisors` of the stations' ``points``, or ones for
    ``points=None`` (an observation taken as given).

    Raises:
        ValueError: ``normalized`` without ``points``, or ``points`` not an integer >= 1 or one per
            station.
    """
    if points is None:
        if normalized:
            raise ValueError("normalized=True needs the stations' charging points (points=...), to "
                             "read Z in vehicles")  # fmt: skip
        return np.ones(len(check_layout(blocks)) * n_stations)
    pts = np.broadcast_to(np.asarray(points), (n_stations,)) if np.ndim(points) == 0 else np.asarray(points)
    if pts.shape != (n_stations,) or not np.issubdtype(pts.dtype, np.integer) or (pts < 1).any():
        raise ValueError(f"points={points!r}: must be an integer >= 1 or {n_stations} of them")
    return unit_divisors(pts, blocks)


def input_factor(input_scale: np.ndarray, divisors: np.ndarray, normalized: bool) -> np.ndarray:
    """The factor from the environment's observation to the network's input (float32): the physical
    reading (times ``divisors`` where the environment normalises) times ``input_scale``."""
    units = divisors if normalized else np.ones(len(divisors))
    return (np.asarray(input_scale, np.float32).astype(np.float64) * units).astype(np.float32)


def network_input(obs: np.ndarray, factor: np.ndarray, blocks: int | str) -> torch.Tensor:
    """``obs`` (one observation or a batch) times ``factor`` (:func:`input_factor`), as a float32
    tensor.

    Raises:
        ValueError: the last axis is not ``len(factor)`` (``blocks`` x stations).
    """
    x = np.asarray(obs, dtype=np.float32)
    if x.shape[-1:] != (len(factor),):
        raise ValueError(f"observation shape {x.shape}: expected (..., {len(factor)}), {blocks} x m")
    return torch.from_numpy(x * factor)
