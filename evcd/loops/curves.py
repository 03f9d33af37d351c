"""The learning curve of a training run (``learning_curve.png``): travel time and station switches per
training episode, with their rolling means."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from evcd.loops.validation import ValidationRecord
from evcd.utils.atomic import atomic_write_png


def rolling_mean(values: Sequence[float], window: int) -> np.ndarray:
    """Mean of each value and the ``window - 1`` before it (fewer at the start)."""
    x = np.asarray(values, dtype=np.float64)
    if x.size == 0:
        return x
    c = np.cumsum(np.insert(x, 0, 0.0))
    idx = np.arange(1, x.size + 1)
    lo = np.maximum(0, idx - window)
    return (c[idx] - c[lo]) / (idx - lo)


def plot_learning_curve(
    runs: Mapping[str, Sequence[Any]],
    path: str | Path,
    window: int = 50,
    references: Mapping[str, float] | None = None,
    title: str = "",
    validation: ValidationRecord | None = None,
    travel_label: str = "travel time to charge start",
    switches_label: str = "switches per episode",
) -> Path:
    """Save a PNG of travel time per training episode (top), the periodic held-out validation if
    there is one (middle), and station switches (bottom).

    Args:
        runs: label -> the run's training rows (:class:`~evcd.env.runners.base.EpisodeRow`) in the order
            they were played (the x axis is that order: the batched engine finishes episodes in
            another order than their indices).
        path: PNG to write (atomically).
        window: episodes in the rolling mean drawn over the per-episode points.
        references: label -> a travel time drawn as a horizontal line (e.g. a rule's mean).
        title: figure title.
        validation: the run's validations (:mod:`evcd.loops.validation`): the policy's mean travel
            time on the same held-out episodes after each block of training, beside the rules'.
        travel_label, switches_label: what a row's ``travel_time`` and ``switches`` are (the fleet's
            rows hold its guided EVs' means).
    """
    validated = validation is not None and bool(validation.points)
    from matplotlib import colormaps  # matplotlib where a figure is drawn: not in every script's start
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 9.5 if validated else 7))
    if validated:
        ax_t, ax_v, ax_s = fig.subplots(3, 1, sharex=True, height_ratios=[3, 2, 1.2])
        _plot_validation(ax_v, validation)  # type: ignore[arg-type]
    else:
        ax_t, ax_s = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.2])
    colors = colormaps["tab10"](np.arange(max(1, len(runs))) % 10)
    for (label, rows), c in zip(runs.items(), colors, strict=False):
        ep = np.arange(len(rows))  # the order played, not the episode index
        travel = np.array([r.travel_time for r in rows], dtype=np.float64)
        ok = np.array([not r.truncated for r in rows], dtype=bool)
        ax_t.scatter(ep[ok], travel[ok], s=6, color=c, alpha=0.25, linewidths=0)
        if (~ok).any():
            ax_t.scatter(ep[~ok], travel[~ok], s=18, marker="x", color=c, label=f"{label}: truncated")
        ax_t.plot(ep[ok], rolling_mean(travel[ok], window), color=c, lw=2,
                  label=f"{label}: mean of the last {window}")  # fmt: skip
        switches = np.array([r.switches for r in rows], dtype=np.float64)
        ax_s.plot(ep, rolling_mean(switches, window), color=c, lw=1.5, label=label)
    for (label, value), ls in zip((references or {}).items(), ("--", ":", "-.", "--"), strict=False):
        ax_t.axhline(value, color="k", ls=ls, lw=1, label=label)
    ax_t.set_yscale("log")
    ax_t.set_ylabel(f"{travel_label} (s, log)")
    ax_t.grid(alpha=0.3, which="both")
    ax_t.legend(fontsize=8, loc="upper right")
    ax_s.set_ylabel(f"{switches_label}\n(mean of the last {window})")
    ax_s.set_xlabel("training episodes played")
    ax_s.grid(alpha=0.3)
    if title:
        ax_t.set_title(title)
    fig.tight_layout()
    return atomic_write_png(fig, path)


def _plot_validation(ax: Any, validation: ValidationRecord) -> None:
    """The validation curve: the policy's mean after each block of training, the rules as lines."""
    points = validation.points
    x = [p.episodes_done for p in points]
    n = len(points[0].travel_times)
    ax.plot(x, [p.mean for p in points], marker="o", color="C3", lw=2, label="policy, no exploration")
    for (name, mean), ls in zip(validation.to_dict()["rule_means"].items(), ("--", ":", "-."), strict=False):
        if mean is not None:
            ax.axhline(mean, color="k", ls=ls, lw=1.2, label=f"{name}: {mean:.0f} s")
    ax.set_ylabel(f"mean travel time (s)\non {n} held-out episodes")
    ax.set_title("held-out validation: the same episodes after every block of training", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
