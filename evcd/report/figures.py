"""Figures a person looks at: those of a results table over seeds (:mod:`evcd.report.table`), grouped
bars and learning curves, and a scenario's day (the map with its stations, the queues over the day).

Each takes plain values (no file reading here) and writes a PNG atomically.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import sumolib
from matplotlib import colormaps
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import ScalarFormatter

from evcd.env.runners.base import EpisodeRow
from evcd.loops.curves import rolling_mean
from evcd.scenario.stations_file import Station
from evcd.utils.atomic import atomic_write_png

if TYPE_CHECKING:
    from evcd.report.seed_stats import SeedStat

#: Line styles of the reference lines of the learning curves, in order.
REFERENCE_STYLES = (("k", "--"), ("0.45", ":"), ("0.45", "-."))
CURVES_TITLE = "Training travel time: mean over seeds of each seed's rolling mean; band: min-max over seeds"


def agent_colors(agents: Sequence[str]) -> dict[str, Any]:
    """A colour per agent (tab10 in the given order): pass the same list to both figures."""
    palette = colormaps["tab10"](np.arange(max(1, len(agents))) % 10)
    return {a: tuple(palette[i]) for i, a in enumerate(agents)}


def plot_results_bars(
    stats: Mapping[str, Mapping[str, Mapping[Any, SeedStat]]],
    path: str | Path,
    paper: Mapping[str, Mapping[int, float]] | None = None,
    colors: Mapping[str, Any] | None = None,
    title: str = "",
    xlabel: str = "background EVs",
) -> Path:
    """Save a grouped bar chart: per regime a panel, x = EV count, a bar per agent with its interval.

    Args:
        stats: regime -> agent -> x (the EV count, or ``xlabel``'s quantity) -> mean over seeds with its
            95% interval (the bars and error bars; no error bar for a single seed).
        path: PNG to write (atomically).
        paper: agent -> evs -> the paper's value, drawn as a hollow marker on that agent's bar.
        colors: agent -> colour (default: :func:`agent_colors` in the order met).
        title: figure title.
        xlabel: what the x values are.
    """
    regimes = list(stats)
    colors = colors or agent_colors(list(dict.fromkeys(a for r in regimes for a in stats[r])))
    fig = Figure(figsize=(max(8.0, 6.5 * len(regimes)), 5.6))
    axes = fig.subplots(1, max(1, len(regimes)), squeeze=False)[0]
    for ax, regime in zip(axes, regimes, strict=False):
        agents = list(stats[regime])
        evs = sorted({e for a in agents for e in stats[regime][a]})
        width = 0.84 / max(1, len(agents))
        for i, agent in enumerate(agents):
            x = np.arange(len(evs)) + (i - (len(agents) - 1) / 2) * width
            cells = [stats[regime][agent].get(e) for e in evs]
            mean = np.array([c.mean if c else math.nan for c in cells])
            err = np.array([[c.mean - c.low, c.high - c.mean] if c and c.n > 1 else [0, 0] for c in cells]).T
            ax.bar(x, mean, width * 0.92, yerr=err, capsize=3, color=colors[agent], label=agent,
                   error_kw={"elinewidth": 1.2, "ecolor": "0.15"})  # fmt: skip
            if paper and agent in paper:
                ax.scatter(x, [paper[agent].get(e, math.nan) for e in evs], marker="D", s=46, zorder=5,
                           facecolors="white", edgecolors=colors[agent], linewidths=1.8)  # fmt: skip
        ax.set_xticks(np.arange(len(evs)), [f"{e:g}" for e in evs])
        ax.set_xlabel(xlabel)
        ax.set_ylabel("mean travel time (s)")
        ns = sorted({c.n for a in agents for c in stats[regime][a].values()})
        seeds = f"{ns[0]}" if len(ns) == 1 else f"{ns[0]}-{ns[-1]}"
        ax.set_title(f"{'' if ',' in regime else 'regime: '}{regime} ({seeds} seeds per bar)")
        ax.grid(axis="y", alpha=0.3)
        ax.set_axisbelow(True)
        handles, _ = ax.get_legend_handles_labels()
        if paper and any(a in paper for a in agents):
            handles.append(Line2D([], [], ls="", marker="D", mfc="white", mec="0.2", mew=1.8,
                                  label="paper (whole day, training mean)"))  # fmt: skip
        ax.set_ylim(0.0, ax.get_ylim()[1] * 1.18)  # headroom: the legend above the tallest whisker
        ax.legend(handles=handles, fontsize=8, loc="upper left", ncols=min(3, len(handles)))
    default = "Evaluation mean travel time: mean over seeds, 95% interval across seeds (Student t)"
    fig.suptitle(title or default)
    fig.tight_layout()
    return atomic_write_png(fig, path)


def smoothing_window(episodes: int) -> int:
    """Episodes in the rolling mean of a learning curve: 100, or a twentieth of the run if shorter."""
    return max(1, min(100, episodes // 20))


def seed_band(runs: Sequence[Sequence[EpisodeRow]], window: int) -> tuple[np.ndarray, ...]:
    """Each run's rolling mean travel time, averaged over runs: ``(x, mean, min, max)``.

    A run's curve is the rolling mean over its last ``window`` charged episodes, placed at the order
    each episode was played (truncated episodes are skipped) and interpolated between; the mean,
    minimum and maximum are over the runs covering each episode.
    """
    length = max((len(r) for r in runs), default=0)
    grid = np.arange(length, dtype=np.float64)
    curves = []
    for rows in runs:
        travel = np.array([r.travel_time for r in rows], dtype=np.float64)
        x = np.flatnonzero([not r.truncated for r in rows])
        if x.size:
            curves.append(np.interp(grid, x, rolling_mean(travel[x], window), left=np.nan, right=np.nan))
    if not curves:
        return grid, *(np.full(length, np.nan) for _ in range(3))
    stack = np.vstack(curves)
    count = np.isfinite(stack).sum(axis=0)
    mean = np.where(count > 0, np.nansum(stack, axis=0) / np.maximum(count, 1), np.nan)
    return grid, mean, np.fmin.reduce(stack, axis=0), np.fmax.reduce(stack, axis=0)


def _set_log_range(ax: Any, values: np.ndarray) -> None:
    """A log y axis spanning the finite positive ``values`` with a margin, ticks in plain seconds."""
    v = values[np.isfinite(values) & (values > 0)]
    ax.set_yscale("log")
    if v.size:
        ax.set_ylim(v.min() / 1.15, v.max() * 1.15)
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(ScalarFormatter())


def plot_training_curves(
    panels: Mapping[tuple[str, int], Mapping[str, Sequence[Sequence[EpisodeRow]]]],
    path: str | Path,
    references: Mapping[tuple[str, int], Mapping[str, float]] | None = None,
    colors: Mapping[str, Any] | None = None,
) -> Path:
    """Save learning curves: a panel per (regime, evs), a line per agent averaged over its seeds.

    Args:
        panels: (regime, evs) -> agent -> each seed's training rows in the order played.
        path: PNG to write (atomically).
        references: (regime, evs) -> label -> travel time drawn as a horizontal line (e.g. greedy's
            evaluation mean).
        colors: agent -> colour (default: :func:`agent_colors` in the order met).
    """
    regimes = list(dict.fromkeys(r for r, _ in panels))
    per_row = {r: sorted(e for rr, e in panels if rr == r) for r in regimes}
    ncols = max(len(v) for v in per_row.values())
    colors = colors or agent_colors(list(dict.fromkeys(a for p in panels.values() for a in p)))
    fig = Figure(figsize=(max(8.0, 5.4 * ncols), 4.2 * len(regimes) + 0.6))  # room for the title
    axes = fig.subplots(len(regimes), ncols, squeeze=False)
    for row, regime in enumerate(regimes):
        for col in range(ncols):
            ax = axes[row][col]
            if col >= len(per_row[regime]):
                ax.set_visible(False)
                continue
            evs = per_row[regime][col]
            agents = panels[regime, evs]
            window = smoothing_window(max(len(r) for runs in agents.values() for r in runs))
            shown = []  # what the y range must show: the means, and the bands once a window is full
            for agent, runs in agents.items():
                x, mean, lo, hi = seed_band(runs, window)
                ax.fill_between(x, lo, hi, color=colors[agent], alpha=0.2, linewidth=0)
                ax.plot(x, mean, color=colors[agent], lw=1.8, label=f"{agent} ({len(runs)} seeds)")
                shown += [mean, lo[window:], hi[window:]]
            _finish_curve_axes(ax, (references or {}).get((regime, evs), {}), shown,
                               f"regime {regime}, {evs} EVs (rolling mean of {window})",
                               "travel time to charge start (s, log)")  # fmt: skip
    fig.suptitle(CURVES_TITLE)
    fig.tight_layout()
    return atomic_write_png(fig, path)


def _finish_curve_axes(
    ax: Any, references: Mapping[str, float], shown: list[np.ndarray], title: str, ylabel: str
) -> None:
    """Draw ``references`` (label -> travel time) as horizontal lines, fit the log range to what is
    ``shown`` and them, and label a learning-curve panel."""
    for (label, value), (c, ls) in zip(references.items(), REFERENCE_STYLES, strict=False):
        if math.isfinite(value):
            ax.axhline(value, color=c, ls=ls, lw=1.3, label=f"{label}: {value:.0f} s")
            shown.append(np.array([value]))
    _set_log_range(ax, np.concatenate(shown))
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("training episodes played")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right")


def plot_validation_curves(
    panels: Mapping[tuple[str, int], Mapping[str, Sequence[Sequence[tuple[int, float]]]]],
    rules: Mapping[tuple[str, int], Mapping[str, float]],
    path: str | Path,
    colors: Mapping[str, Any] | None = None,
    gaps: Mapping[tuple[str, int], Mapping[str, Sequence[Sequence[tuple[int, float]]]]] | None = None,
    gap_rule: str = "queue_aware",
    titles: Mapping[Any, str] | None = None,
) -> Path:
    """Save the periodic held-out validation: a panel per (regime, evs), a line per learner; with
    ``gaps``, a second row of panels with each seed's paired difference to ``gap_rule``.

    Args:
        panels: (regime, evs) -> agent -> each seed's points ``(training episodes done, mean travel
            time on the validation episodes)``; the line is the mean over seeds at each point, the
            band the min-max over seeds.
        rules: (regime, evs) -> rule -> its validation mean averaged over seeds (horizontal lines).
        path: PNG to write (atomically).
        colors: agent -> colour.
        gaps: (regime, evs) -> agent -> each seed's points ``(training episodes done, learner minus
            gap_rule on the same validation episodes)``: a thin line per seed, a thick one for the
            mean over seeds, on a symmetric log scale around 0 (each seed has its own validation
            episodes, so this is where a reader sees, seed by seed, when the learner stops closing
            in on the rule).
        gap_rule: the rule of ``gaps``, for the labels.
        titles: key -> what its panels are (default ``"regime <regime>, <evs> EVs"`` above and
            ``"<evs> EVs"`` below); the fleet's keys name their guided share this way.
    """
    keys = sorted(panels)
    colors = colors or agent_colors(list(dict.fromkeys(a for p in panels.values() for a in p)))
    rows = 2 if gaps else 1
    fig = Figure(figsize=(max(6.5, 5.4 * len(keys)), 4.8 * rows))
    grid = fig.subplots(rows, len(keys), squeeze=False)
    for ax, key in zip(grid[0], keys, strict=True):
        shown = []
        for agent, runs in panels[key].items():
            steps, values = _seed_matrix(runs)
            with np.errstate(all="ignore"):
                mean = np.nanmean(values, axis=0)
            ax.fill_between(steps, np.nanmin(values, axis=0), np.nanmax(values, axis=0), color=colors[agent],
                            alpha=0.2, linewidth=0)  # fmt: skip
            ax.plot(steps, mean, "o-", color=colors[agent], lw=1.8, label=f"{agent} ({len(runs)} seeds)")
            shown.append(values[np.isfinite(values)])
        title = titles[key] if titles else f"regime {key[0]}, {key[1]} EVs"
        _finish_curve_axes(ax, rules.get(key, {}), shown, title, "validation travel time (s, log)")
    if gaps:
        for ax, key in zip(grid[1], keys, strict=True):
            where = titles[key] if titles else f"{key[1]} EVs"
            _plot_gap_panel(ax, gaps.get(key, {}), colors, gap_rule, where)
    fig.suptitle("Held-out validation during training: the policy without exploration on the same\n"
                 "episodes of the tuning days (band: min-max over seeds)", fontsize=10)  # fmt: skip
    fig.tight_layout()
    return atomic_write_png(fig, path)


def _seed_matrix(runs: Sequence[Sequence[tuple[int, float]]]) -> tuple[list[int], np.ndarray]:
    """The union of the seeds' steps and a ``(seeds, steps)`` array of their values (NaN where a seed
    has no point)."""
    steps = sorted({e for run in runs for e, _ in run})
    return steps, np.array([[dict(run).get(e, math.nan) for e in steps] for run in runs], dtype=float)


def _plot_gap_panel(
    ax: Any,
    gaps: Mapping[str, Sequence[Sequence[tuple[int, float]]]],
    colors: Mapping[str, Any],
    rule: str,
    where: str,
) -> None:
    """One panel of paired validation differences: a thin line per seed, the mean over seeds thick;
    ``where`` (e.g. ``"400 EVs"``) heads its title."""
    for agent, runs in gaps.items():
        steps, values = _seed_matrix(runs)
        for row in values:
            ax.plot(steps, row, "-", color=colors[agent], lw=0.8, alpha=0.45)
        with np.errstate(all="ignore"):
            mean = np.nanmean(values, axis=0)
        ax.plot(steps, mean, "o-", color=colors[agent], lw=2.0,
                label=f"{agent}: mean of {len(runs)} seeds (thin: each seed)")  # fmt: skip
    ax.axhline(0.0, color="0.3", lw=1.0, ls=":", label=f"{rule} (0)")
    ax.set_yscale("symlog", linthresh=10.0)
    ax.set_xlabel("training episodes played")
    ax.set_ylabel(f"learner - {rule} (s, symlog)")
    ax.set_title(f"{where}: learner - {rule}, paired per seed\n"
                 "(each seed on its own validation episodes; < 0: faster)", fontsize=9)  # fmt: skip
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper left")


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
    return atomic_write_png(fig, path)
