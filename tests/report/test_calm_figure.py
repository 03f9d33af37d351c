"""The figure of what a perturbed world costs each dispatcher (:mod:`evcd.report.calm_figure`)."""

from __future__ import annotations

import struct

import pytest

from evcd.report.calm_figure import plot_against_calm
from evcd.report.paired import paired_stat


def _size(path) -> tuple[int, int]:
    """A PNG's width and height (its IHDR chunk)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_a_panel_per_dispatcher_and_a_bar_per_world(tmp_path):
    outages = paired_stat({0: [30.0, 50.0], 1: [120.0, 150.0], 2: [40.0, 60.0]})
    rain = paired_stat({0: [1.0, 3.0], 1: [2.0, 2.5], 2: [-0.5, 4.0]})
    one = plot_against_calm([("fleet +outages sees PTG", "central", outages)], tmp_path / "one.png")
    rows = [(w, a, p) for a in ("central", "queue_aware", "reservation")
            for w, p in (("fleet +outages sees PTG", outages), ("fleet +rain sees PTG", rain))]  # fmt: skip
    three = plot_against_calm(rows, tmp_path / "three.png")
    (w1, h1), (w3, h3) = _size(one), _size(three)
    assert w3 > 2 * w1  # three panels side by side
    assert h3 > h1  # two bars a panel, not one


def test_no_row_is_refused(tmp_path):
    with pytest.raises(ValueError, match="no row to draw"):
        plot_against_calm([], tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()
