"""One environment step as a learning agent sees it (what runners hand to ``agent.observe``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Transition(NamedTuple):
    """One environment step, as a learning agent sees it.

    ``terminated`` and ``truncated`` are kept apart: a time-limit end (truncation) still bootstraps
    from ``next_obs``, a charge start (termination) does not.
    """

    obs: np.ndarray
    action: int
    reward: float
    next_obs: np.ndarray
    terminated: bool
    truncated: bool
