"""The herding figure of the fleet: per dispatcher, the vehicles at each station and the guided EVs
heading there over the window (:attr:`evcd.env.fleet.FleetEnv.trace`), where a person sees at a glance
whether the centre sends everybody to the same short queue."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from evcd.utils.atomic import atomic_write_png

Trace = Sequence[tuple[float, Sequence[int], Sequence[int]]]


def plot_fleet_traces(
    traces: Mapping[str, Trace], stations: Sequence[str], path: str | Path, title: str = ""
) -> Path:
    """One panel per dispatcher (same axes): per station, the vehicles there (solid: charging and
    waiting) and the guided EVs sent there and still driving (dashed), against the time of day.

    Args:
        traces: per dispatcher, an episode's trace ``(time, at each station, heading to each)``.
        stations: the stations' ids, in the order of the trace's tuples.
        path: the PNG to write (atomically).
        title: the figure's title (say the day, EVs, guided share).
    """
    if not traces:
        raise ValueError("plot_fleet_traces needs at least one trace")
    n = len(traces)
    from matplotlib import colormaps  # matplotlib where a figure is drawn: not in every script's start
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(11, 2.3 * n + 0.8), layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, sharey=True, squeeze=False)[:, 0]
    colors = colormaps["tab10"](np.arange(len(stations)) % 10)
    for ax, (name, trace) in zip(axes, traces.items(), strict=True):
        t = np.array([row[0] for row in trace]) / 3600.0
        at = np.array([row[1] for row in trace], dtype=float).reshape(len(trace), -1)
        heading = np.array([row[2] for row in trace], dtype=float).reshape(len(trace), -1)
        for i in range(len(stations)):
            ax.step(t, at[:, i], where="post", color=colors[i], lw=1.4)
            ax.step(t, heading[:, i], where="post", color=colors[i], lw=1.0, ls="--")
        ax.set_title(name, loc="left", fontsize=10)
        ax.set_ylabel("vehicles")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time of day (h)")
    handles = [Line2D([], [], color=colors[i], lw=1.4) for i in range(len(stations))]
    handles += [Line2D([], [], color="0.3", lw=1.4), Line2D([], [], color="0.3", lw=1.0, ls="--")]
    labels = [*stations, "at the station (charging + waiting)", "guided EVs heading there"]
    fig.legend(handles, labels, loc="outside upper right", ncol=min(len(labels), 4), fontsize=8)
    if title:
        fig.suptitle(title, x=0.01, ha="left", fontsize=10)
    return atomic_write_png(fig, path)
