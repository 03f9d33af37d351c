"""Figures a person looks at: the scenario map, the station queues over a day, learning curves."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import sumolib
from matplotlib import colormaps
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from evcd.atomic import atomic_write_bytes
from evcd.scenario.stations_file import Station


def plot_scenario_day(
    net: sumolib.net.Net,
    stations: Sequence[Station],
    times_s: np.ndarray,
    waiting: Mapping[str, np.ndarray],
    charging: Mapping[str, np.ndarray],
    path: str | Path,
    title: str = "",
) -> Path:
    """Save a PNG: the road network with the stations (left) and each station's queue over the day (right).

    Args:
        net: the network.
        stations: the stations, in the order their colours are assigned.
        times_s: sample times (s of day).
        waiting: station id -> number of EVs waiting at each sample.
        charging: station id -> number of EVs charging at each sample.
        path: PNG to write (atomically).
        title: figure title.
    """
    # the object-oriented API: no pyplot, no global backend state
    m = len(stations)
    fig = Figure(figsize=(15, max(6.5, 1.3 * m + 1)))
    grid = fig.add_gridspec(m, 2, width_ratios=[1.1, 1])
    ax_map = fig.add_subplot(grid[:, 0])
    segs, widths = [], []
    for edge in net.getEdges(withInternal=False):
        segs.append(edge.getShape())
        widths.append(0.4 + 0.5 * edge.getLaneNumber())
    ax_map.add_collection(LineCollection(segs, linewidths=widths, colors="0.55"))
    colors = colormaps["tab10"](np.arange(m) % 10)
    for st, c in zip(stations, colors, strict=True):
        x, y = sumolib.geomhelper.positionAtShapeOffset(net.getLane(st.lane).getShape(), st.mid_pos)
        ax_map.plot(x, y, marker="*", markersize=22, color=c, markeredgecolor="k", zorder=5)
        ax_map.annotate(f"{st.id}: {st.name}", (x, y), xytext=(8, 8), textcoords="offset points", fontsize=9,
                        bbox={"boxstyle": "round", "fc": "white", "alpha": 0.8})  # fmt: skip
    ax_map.autoscale()
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    ax_map.set_title("Road network and charging stations")

    hours = np.asarray(times_s) / 3600.0
    top = max([1, *(int(np.max(waiting[s.id], initial=0)) for s in stations)])
    top = max(top, *(s.points for s in stations))
    for i, (st, c) in enumerate(zip(stations, colors, strict=True)):
        ax = fig.add_subplot(grid[i, 1])
        ax.fill_between(hours, waiting[st.id], step="post", color=c, alpha=0.6, label="waiting")
        ax.step(hours, charging[st.id], where="post", color="k", lw=0.8, label="charging")
        ax.set_xlim(0, 24)
        ax.set_ylim(0, top + 0.5)
        ax.set_xticks(range(0, 25, 3))
        ax.tick_params(labelbottom=i == m - 1, labelsize=8)
        ax.grid(alpha=0.3)
        ax.set_ylabel(st.id, rotation=0, ha="right", va="center")
        if i == 0:
            ax.set_title("EVs waiting (filled) and charging (line) per station")
            ax.legend(loc="upper left", fontsize=8, ncols=2)
        if i == m - 1:
            ax.set_xlabel("time of day (h)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return atomic_write_bytes(path, buf.getvalue())


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
) -> Path:
    """Save a PNG of travel time per training episode (top) and station switches (bottom).

    Args:
        runs: label -> the run's training rows (:class:`~evcd.env.runner.EpisodeRow`) in the order
            they were played (the x axis is that order: the batched engine finishes episodes in
            another order than their indices).
        path: PNG to write (atomically).
        window: episodes in the rolling mean drawn over the per-episode points.
        references: label -> a travel time drawn as a horizontal line (e.g. a rule's mean).
        title: figure title.
    """
    fig = Figure(figsize=(11, 7))
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
    ax_t.set_ylabel("travel time to charge start (s, log)")
    ax_t.grid(alpha=0.3, which="both")
    ax_t.legend(fontsize=8, loc="upper right")
    ax_s.set_ylabel(f"switches per episode\n(mean of the last {window})")
    ax_s.set_xlabel("training episodes played")
    ax_s.grid(alpha=0.3)
    if title:
        ax_t.set_title(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return atomic_write_bytes(Path(path), buf.getvalue())
