"""Atomic writes: the file appears whole or not at all, with the mode open() would give; JSON is strict."""

from __future__ import annotations

import json
import math
import os
import stat

import pytest
from matplotlib.figure import Figure

from evcd.utils.atomic import FILE_MODE, atomic_write_json, atomic_write_png, atomic_write_text, json_floats


def test_a_write_replaces_the_file_whole_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "a.txt"
    atomic_write_text(path, "old")
    atomic_write_text(path, "new")
    assert path.read_text() == "new" and list(tmp_path.iterdir()) == [path]
    assert stat.S_IMODE(path.stat().st_mode) == FILE_MODE


def test_a_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "a.txt"
    atomic_write_text(path, "old")

    def failing_fsync(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_text(path, "new")
    assert path.read_text() == "old" and list(tmp_path.iterdir()) == [path]


def test_json_floats():
    assert json_floats({"a": [1.0, float("nan"), (float("inf"), 2)], "b": -math.inf, "c": "x"}) == {
        "a": [1.0, None, [None, 2]],
        "b": None,
        "c": "x",
    }


def test_json_is_strict_with_one_space_of_indent_and_a_final_newline(tmp_path):
    path = atomic_write_json(tmp_path / "r.json", {"mean": math.nan, "rows": (1, 2.5)})
    text = path.read_text()
    assert text == '{\n "mean": null,\n "rows": [\n  1,\n  2.5\n ]\n}\n'
    assert json.loads(text) == {"mean": None, "rows": [1, 2.5]}


def test_a_figure_is_written_as_a_png(tmp_path):
    fig = Figure(figsize=(2, 2))
    fig.subplots().plot([0, 1], [1, 0])
    path = atomic_write_png(fig, tmp_path / "f.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and list(tmp_path.iterdir()) == [path]
