"""What a network reads: an observation in physical units (m, vehicles) scaled to km, tens of
vehicles and multiples of the charging points, whatever units the environment hands out.

    inputs = InputScale(points, n_stations, "DNZ", normalized)    # km, tens of vehicles, points
    x = inputs(obs)                                               # env units -> the network's input

A learner keeps ``inputs.scale`` (physical -> network) with its networks in a checkpoint and restores it
with :meth:`InputScale.set`, so a loaded policy sees what it was trained on in any environment; the DQN
and PPO learners share this.
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


class InputScale:
    """An environment's observations -> a network's input: the physical reading (m, vehicles) times
    ``scale``, which is km, tens of vehicles and multiples of the charging points for ``points``, or
    ones for ``points=None`` (an observation taken as given).

    Args:
        points: the stations' charging points (one number for all), or ``None``.
        n_stations: stations ``m``.
        layout: the observation's blocks (3, 4 or letters, :func:`~evcd.env.observation.check_layout`).
        normalized: whether the environment normalises its observations (needs ``points``).

    Raises:
        ValueError: see :func:`observation_divisors`.
    """

    def __init__(
        self, points: int | Sequence[int] | None, n_stations: int, layout: int | str, normalized: bool
    ) -> None:
        self.layout = check_layout(layout)
        self.normalized = bool(normalized)
        self.divisors = observation_divisors(points, n_stations, self.layout, self.normalized)
        self.size = len(self.divisors)
        self.set(np.ones(self.size) if points is None else 1.0 / self.divisors)

    def set(self, scale: np.ndarray) -> None:
        """Take ``scale`` (physical -> network, e.g. a checkpoint's) and derive the factor applied to
        observations."""
        self.scale = np.asarray(scale, np.float32)
        self._factor = input_factor(self.scale, self.divisors, self.normalized)

    def __call__(self, obs: np.ndarray) -> torch.Tensor:
        """The network's input for one observation or a batch (float32).

        Raises:
            ValueError: the last axis is not the layout's size.
        """
        return network_input(obs, self._factor, len(self.layout))
