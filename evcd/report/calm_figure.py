"""What a perturbed world costs each dispatcher, as a figure: each row of a comparison
(:mod:`evcd.report.compare`) minus the same dispatcher calm, paired by episode.

One panel per dispatcher, one bar per perturbed world: the mean over seeds of each seed's paired
difference, its 95% t interval across seeds, and each seed's difference as a dot. The panels share no
axis: a rule that drives into outages may lose minutes where another loses seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from evcd.report.paired import PairedStat
from evcd.utils.atomic import atomic_write_png

#: (world, dispatcher, that row minus the same dispatcher calm)
CalmRow = tuple[str, str, PairedStat]


def plot_against_calm(rows: Sequence[CalmRow], path: str | Path) -> Path:
    """Save the figure of ``rows`` (each perturbed row minus the same dispatcher calm) to ``path``.

    Args:
        rows: (world, dispatcher, paired difference); the panels follow the dispatchers' first
            appearance, the bars the worlds'.
        path: PNG to write (atomically).

    Raises:
        ValueError: no row.
    """
    if not rows:
        raise ValueError("plot_against_calm: no row to draw (no perturbed row has a calm counterpart)")
    agents = list(dict.fromkeys(agent for _, agent, _ in rows))
    worlds = list(dict.fromkeys(world for world, _, _ in rows))
    # the words every world shares ("fleet", "sees PTG") go to the axis label, the rest name the bars
    common = [w for w in worlds[0].split() if all(w in x.split() for x in worlds)] if len(worlds) > 1 else []
    labels = [" ".join(w for w in world.split() if w not in common) or world for world in worlds]
    fig = Figure(figsize=(4.6 * len(agents) + 1.6, 0.55 * len(worlds) + 1.9))
    axes = fig.subplots(1, len(agents), squeeze=False)[0]
    for ax, agent in zip(axes, agents, strict=True):
        mine = {world: p for world, a, p in rows if a == agent}
        y = np.arange(len(worlds))[::-1]
        for yi, world in zip(y, worlds, strict=True):
            p = mine.get(world)
            if p is None:
                continue
            s = p.stat
            clear = s.n > 1 and (s.low > 0 or s.high < 0)  # the interval leaves out 0
            color = ("tab:red" if s.mean > 0 else "tab:blue") if clear else "0.7"
            ax.barh(yi, s.mean, 0.6, color=color)
            if s.n > 1:
                ax.errorbar(s.mean, yi, xerr=[[s.mean - s.low], [s.high - s.mean]], fmt="none", ecolor="0.15",
                            capsize=3, elinewidth=1.2)  # fmt: skip
            seeds = list(p.per_seed.values())
            ax.scatter(seeds, np.full(len(seeds), yi) + np.linspace(-0.18, 0.18, len(seeds)), s=12,
                       color="0.1", zorder=5)  # fmt: skip
        ax.axvline(0.0, color="0.2", lw=0.8)
        ax.set_yticks(y, labels if ax is axes[0] else [""] * len(worlds))
        if ax is axes[0] and common:
            ax.set_ylabel(f"{' '.join(common)}, perturbed with")
        ax.set_xlabel("minus the same dispatcher calm (s)")
        ax.set_title(agent)
        ax.grid(axis="x", alpha=0.3)
        ax.set_axisbelow(True)
    title = ("Perturbed minus calm, paired by episode: mean over seeds, 95% t interval across seeds, "
               "each seed a dot (red / blue: slower / faster, interval clear of 0)")  # fmt: skip
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return atomic_write_png(fig, path)
