"""The fleet's herding figure: a PNG per set of traces, and a clear error for none."""

from __future__ import annotations

import pytest
from matplotlib.image import imread

from evcd.loops.fleet_figure import plot_fleet_traces


def test_one_panel_per_dispatcher_written_as_png(tmp_path) -> None:
    trace = [(25200.0 + 60 * i, (i % 3, 1, 0), (1, 0, i % 2)) for i in range(30)]
    one = plot_fleet_traces({"greedy": trace}, ["cs0", "cs1", "cs2"], tmp_path / "one.png", title="t")
    two = plot_fleet_traces(
        {"greedy": trace, "central": trace[:10]}, ["cs0", "cs1", "cs2"], tmp_path / "two.png"
    )
    h1, h2 = imread(one).shape[0], imread(two).shape[0]
    assert h2 > h1 > 100  # a second panel makes it taller
    with pytest.raises(ValueError, match="at least one trace"):
        plot_fleet_traces({}, ["cs0"], tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()
