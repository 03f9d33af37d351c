"""Small real networks for the scenario tests, generated with netgenerate."""

from __future__ import annotations

from pathlib import Path

import pytest
import sumolib

from tests.conftest import make_grid


@pytest.fixture(scope="session")
def grid_net_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 x 8 grid, 250 m blocks (1.75 km across)."""
    return make_grid(tmp_path_factory.mktemp("grid") / "grid.net.xml")


@pytest.fixture(scope="session")
def grid_net(grid_net_file: Path) -> sumolib.net.Net:
    """The grid read with sumolib."""
    return sumolib.net.readNet(str(grid_net_file))
