"""Sphinx configuration of evcd's documentation site.

    python -m pip install -e ".[docs]"
    sphinx-build -W --keep-going -b html docs docs/_build/html     # warnings are errors, as in the tests

Sphinx with MyST (Markdown pages) and the furo theme, as Gymnasium, stable-baselines3 and sumo-rl build
theirs; autodoc with napoleon reads the package's Google-style docstrings for the API reference.
"""

from __future__ import annotations

import sys
from pathlib import Path

import evcd

# docs/_ext/evcd_reference writes the reference pages' tables from conf/ and the code as Sphinx reads them
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "evcd"
author = "evcd developers"
copyright = "evcd developers; map data (c) OpenStreetMap contributors, ODbL 1.0"
release = evcd.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "evcd_reference"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_ext"]
# MyST: ``[text](page.md)`` links between pages, ``## Heading`` anchors to link to, ``{include}`` et al.
myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 3

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = f"evcd {release}"
