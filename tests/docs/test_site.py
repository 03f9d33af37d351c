"""The documentation site (docs/, Sphinx with MyST): it builds with every warning an error, so that a
broken link, a page left out of the navigation or a docstring the API reference cannot read fails the
tests; the environment cards have the sections of Gymnasium's and PettingZoo's."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

DOCS = ROOT / "docs"
#: The sections of an environment card, in order.
CARD_SECTIONS = ["Description", "Action", "Observation", "Reward", "Starting state", "Episode end", "`info`",
                 "Arguments", "Version history"]  # fmt: skip


@pytest.mark.slow
def test_the_site_builds_with_warnings_as_errors(tmp_path):
    out = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html",
                           str(DOCS), str(out)], capture_output=True, text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-5000:]
    for page in ("index", "envs/charging_nav", "envs/fleet", "reference/api", "changelog", "NOTES"):
        assert (out / f"{page}.html").is_file(), page
    api = (out / "reference" / "api.html").read_text()
    assert "evcd.env.ChargingNavEnv" in api and "DQNConfig" in api  # the docstrings were read


@pytest.mark.parametrize("card", ["charging_nav", "fleet", "fleet_slots"])
def test_each_environment_card_has_gymnasiums_sections(card):
    text = (DOCS / "envs" / f"{card}.md").read_text()
    found = re.findall(r"^## (.+)$", text, flags=re.M)
    assert found == CARD_SECTIONS
    assert "RANGE_TABLE" not in text  # the measured range is filled in


def test_each_card_names_todays_version():
    import evcd

    assert f"`{evcd.ENV_ID}`" in (DOCS / "envs" / "charging_nav.md").read_text()
    assert f"`{evcd.FLEET_ENV_ID}`" in (DOCS / "envs" / "fleet.md").read_text()
    from evcd.env.fleet.slots import FleetSlots

    slots = FleetSlots.metadata["name"]
    assert slots.endswith(evcd.FLEET_ENV_ID.rsplit("_", 1)[1])  # the view carries the fleet's version
    assert f"`{slots}`" in (DOCS / "envs" / "fleet_slots.md").read_text()
