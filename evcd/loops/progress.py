"""A progress bar per run of episodes (tqdm, on stderr)."""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from evcd.env.runners.base import EpisodeRow


class EpisodeProgress:
    """A tqdm bar over episodes showing the running mean travel time (and the truncated count).

    Args:
        total: episodes expected.
        desc: the bar's label.
        enabled: show it (on stderr).
        initial: episodes already done (a resumed run).
        window: the mean covers the latest ``window`` charged episodes (``None``: all).
    """

    def __init__(
        self, total: int, desc: str, enabled: bool = True, initial: int = 0, window: int | None = None
    ) -> None:
        self.bar = tqdm(
            total=total, initial=initial, desc=desc, unit="ep", mininterval=2, disable=not enabled
        )
        self.window = window
        self.travel: list[float] = []
        self.truncated = 0

    def __call__(self, row: EpisodeRow) -> None:
        """Count ``row`` (use the instance as a runner's ``on_episode``)."""
        if row.truncated:
            self.truncated += 1
        else:
            self.travel.append(row.travel_time)
        recent = self.travel[-self.window :] if self.window else self.travel
        self.bar.set_postfix(mean_T=f"{np.mean(recent):.0f}s" if recent else "-", truncated=self.truncated,
                             refresh=False)  # fmt: skip
        self.bar.update(1)

    def close(self) -> None:
        """Close the bar."""
        self.bar.close()
